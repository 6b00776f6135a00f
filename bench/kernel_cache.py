"""Where the compiled (numba) kernels are cached: a directory keyed on a hash of their sources.

numba's `cache=True` keys a kernel on its own file's time stamp only: a change to a file whose code
or constants it compiles in (the firmware kernels the fused kernel inlines, `put_stream_frame`,
`params.TWO_PI`) is not noticed and stale machine code loads.  Every kernel module therefore takes
`njit` from here: before the first kernel is declared, NUMBA_CACHE_DIR is set to
`<base>/kernels-<hash of every file in KERNEL_SOURCES>`, so any change to any of them starts a fresh
cache (tests/test_kernel_cache.py checks that every module declaring a kernel is listed).  <base>
is the NUMBA_CACHE_DIR the user set, else `.kernel_cache` at the top of the checkout, else
`~/.cache/gyrobench` when the checkout is read-only.  Child processes inherit the keyed directory."""

from __future__ import annotations

import hashlib
import os
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
#: every file whose code numba compiles into a cached kernel, or whose constants a kernel reads
KERNEL_SOURCES = (
    "bench/analysis/free_decay_rk.py",
    "drivers/fpga/protocol.py",
    "drivers/fpga/stream.py",
    "simulators/fpga/kernels.py",
    "simulators/frontend/kernels.py",
    "simulators/fused_kernel.py",
    "simulators/physics/dop853.py",
    "simulators/physics/errors_kernel.py",
    "simulators/physics/kernels.py",
    "simulators/physics/params.py",
    "simulators/rate_table/kernels.py",
)
_PREFIX = "kernels-"
_FILLED = "filled"  # written in the keyed directory once every kernel is compiled (simulators.warm)


def source_hash(root: Path = ROOT, sources: tuple[str, ...] = KERNEL_SOURCES) -> str:
    """16 hex digits of SHA-256 over the kernel sources' names and bytes (a missing file counts as empty)."""
    digest = hashlib.sha256()
    for name in sources:
        path = root / name
        digest.update(name.encode() + b"\0" + (path.read_bytes() if path.is_file() else b"") + b"\0")
    return digest.hexdigest()[:16]


def _default_base() -> Path:
    """`.kernel_cache` in the checkout when it is writable, else the user's cache directory."""
    local = ROOT / ".kernel_cache"
    if os.access(local if local.exists() else ROOT, os.W_OK):
        return local
    return Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "gyrobench"


def cache_dir() -> Path:
    """The keyed directory; sets NUMBA_CACHE_DIR to it (once; a child process finds it set)."""
    key = _PREFIX + source_hash()
    current = os.environ.get("NUMBA_CACHE_DIR", "")
    if current and Path(current).name == key:
        return Path(current)
    keyed = Path(current or _default_base()) / key
    os.environ["NUMBA_CACHE_DIR"] = str(keyed)
    import numba.core.config

    numba.core.config.reload_config()  # numba read its environment when it was first imported
    return keyed


def is_filled() -> bool:
    """Whether every kernel of this source hash has been compiled into the cache (simulators.warm)."""
    return (cache_dir() / _FILLED).is_file()


def mark_filled() -> None:
    """Record that the keyed directory holds every kernel."""
    path = cache_dir()
    path.mkdir(parents=True, exist_ok=True)
    (path / _FILLED).write_text("every kernel compiled by simulators.warm\n", encoding="utf-8")


def load_blas_bindings_alone() -> None:
    """Load scipy's `cython_blas` extension without the rest of scipy.linalg, so numba's BLAS check
    finds it loaded (issue 36: ~0.18 s CPU of every process that loads a kernel).

    Why: the first cached kernel a process loads makes numba import `numba.np.arraymath`, which
    checks that BLAS exists by `import scipy.linalg.cython_blas`; that import runs scipy.linalg's
    package `__init__` (decompositions, matrix functions, ~200 modules) that no kernel of ours calls.
    An import finds a module already in `sys.modules` without importing its parent, so the check
    (and numba's LP64/ILP64 width check after it) passes as before, with the same extension module
    numba's BLAS wrappers would bind.  Nothing is done if scipy.linalg is already imported or the
    extension is not where scipy keeps it (numba then imports it its own way)."""
    import importlib.machinery
    import importlib.util
    import sys

    name = "scipy.linalg.cython_blas"
    if name in sys.modules or "scipy.linalg" in sys.modules:
        return
    try:
        import scipy
    except ImportError:
        return
    folder = Path(scipy.__path__[0]) / "linalg"
    finder = importlib.machinery.FileFinder(
        str(folder), (importlib.machinery.ExtensionFileLoader, importlib.machinery.EXTENSION_SUFFIXES))
    spec = finder.find_spec(name)
    if spec is None or spec.loader is None:
        return
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    try:
        spec.loader.exec_module(module)
    except Exception:
        del sys.modules[name]  # numba's own import then reports what is wrong


cache_dir()
load_blas_bindings_alone()
from numba import njit  # noqa: E402  (after NUMBA_CACHE_DIR is set: what the kernel modules import)

__all__ = ["KERNEL_SOURCES", "cache_dir", "is_filled", "mark_filled", "njit", "source_hash"]
