"""Light commands stay light: building the CLI's parser (what `gyrobench --help` does) imports
neither numba nor numpy, so help and argument errors answer at once (issue 36)."""

from __future__ import annotations

import os
import subprocess
import sys

_ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def _heavy_after(code: str) -> list[str]:
    """The heavy libraries imported by running `code` in a fresh interpreter."""
    probe = code + "\nimport sys\nprint(' '.join(m for m in ('numba', 'numpy', 'bench.engine') if m in sys.modules))"
    env = dict(os.environ, PYTHONPATH=_ROOT)
    out = subprocess.run([sys.executable, "-c", probe], env=env, capture_output=True, text=True, check=True)
    return out.stdout.split()


def test_import_bench_gui_imports_neither_the_engine_nor_numba():
    assert _heavy_after("import bench.gui") == []


def test_building_the_cli_parser_imports_neither_the_engine_nor_numba():
    assert _heavy_after("from bench.cli import build_parser\nbuild_parser()") == []


def test_the_gui_package_still_gives_its_names():
    assert _heavy_after("from bench.gui import run_gui, make_backend") != []  # .app, on first use
