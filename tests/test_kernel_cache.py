"""The compiled kernels' cache is keyed on every kernel source (bench.kernel_cache): numba itself
watches only the time stamp of a kernel's own file, so a change to a file whose code a kernel
inlines would otherwise load stale machine code."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

from bench import kernel_cache

ROOT = kernel_cache.ROOT


def _modules_declaring_kernels() -> set[str]:
    found = set()
    for pkg in ("bench", "drivers", "procedures", "simulators"):
        for path in (ROOT / pkg).rglob("*.py"):
            if re.search(r"^@(numba\.)?n?jit\b", path.read_text(encoding="utf-8"), re.M):
                found.add(path.relative_to(ROOT).as_posix())
    return found


def test_every_module_declaring_a_kernel_is_hashed_and_takes_njit_from_the_cache_module():
    declaring = _modules_declaring_kernels()
    assert declaring and declaring <= set(kernel_cache.KERNEL_SOURCES)
    for name in declaring:
        text = (ROOT / name).read_text(encoding="utf-8")
        assert "from bench.kernel_cache import njit" in text and "from numba import" not in text, name


def test_the_hash_changes_with_any_source_and_only_then(tmp_path: Path):
    for name, text in (("a/k.py", "x = 1\n"), ("b/c.py", "TWO_PI = 6.28\n")):
        (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / name).write_text(text)
    sources = ("a/k.py", "b/c.py")
    first = kernel_cache.source_hash(tmp_path, sources)
    assert kernel_cache.source_hash(tmp_path, sources) == first
    (tmp_path / "b/c.py").write_text("TWO_PI = 6.283\n")  # a constant a kernel compiles in
    assert kernel_cache.source_hash(tmp_path, sources) != first


def test_numba_caches_under_the_keyed_directory_and_a_child_keeps_it(tmp_path: Path):
    code = ("import os\nfrom bench import kernel_cache\nimport numba.core.config as c\n"
            "print(c.CACHE_DIR)\nprint(os.environ['NUMBA_CACHE_DIR'])")
    env = dict(os.environ, PYTHONPATH=str(ROOT), NUMBA_CACHE_DIR=str(tmp_path))
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True)
    keyed = str(tmp_path / f"kernels-{kernel_cache.source_hash()}")
    assert out.stdout.split() == [keyed, keyed]
    env["NUMBA_CACHE_DIR"] = keyed  # what a child process inherits: not keyed twice
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True)
    assert out.stdout.split() == [keyed, keyed]


def test_numba_finds_blas_without_scipy_linalg_and_scipy_linalg_still_imports_whole(tmp_path: Path):
    # numba's BLAS check (numba.np.arraymath, loaded with the first kernel) would import all of
    # scipy.linalg; with the extension loaded alone it passes and scipy.linalg stays unimported,
    # and a later `import scipy.linalg` is the complete package with the same extension
    code = ("import sys\nfrom bench import kernel_cache\nimport numba.np.arraymath as a\n"
            "print(a._HAVE_BLAS, 'scipy.linalg' in sys.modules)\n"
            "blas = sys.modules['scipy.linalg.cython_blas']\n"
            "import numpy as np, scipy.linalg, scipy.linalg.cython_blas as again\n"
            "print(again is blas, scipy.linalg.solve(np.diag([2.0, 4.0]), np.array([1.0, 1.0])).tolist())")
    env = dict(os.environ, PYTHONPATH=str(ROOT), NUMBA_CACHE_DIR=str(tmp_path))
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True)
    assert out.stdout.split("\n")[:2] == ["True False", "True [0.5, 0.25]"]
