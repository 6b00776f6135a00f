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


cache_dir()
from numba import njit  # noqa: E402  (after NUMBA_CACHE_DIR is set: what the kernel modules import)

__all__ = ["KERNEL_SOURCES", "cache_dir", "is_filled", "mark_filled", "njit", "source_hash"]
