"""The project's own files a newcomer reads first (issue 39): the MIT license, a changelog, a
contributing page; the license given as setuptools wants it (no deprecation warning on install)."""

from __future__ import annotations

import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def test_license_changelog_and_contributing_exist():
    text = (ROOT / "LICENSE").read_text()
    assert text.startswith("MIT License") and "Copyright (c) 2026 the gyrobench authors" in text
    assert "## Wave 3" in (ROOT / "CHANGELOG.md").read_text()
    contributing = (ROOT / "CONTRIBUTING.md").read_text()
    assert all(w in contributing for w in ("docs/architecture.md", "ruff", "## Tests", "## Commits"))


def test_the_license_is_an_spdx_string_with_a_setuptools_that_takes_it():
    """A TOML table (`license = { text = "MIT" }`) makes setuptools >= 75 warn on every install; the SPDX
    string needs setuptools >= 77 (PEP 639)."""
    py = tomllib.loads((ROOT / "pyproject.toml").read_text())
    assert py["project"]["license"] == "MIT" and py["project"]["license-files"] == ["LICENSE"]
    setuptools = [r for r in py["build-system"]["requires"] if r.startswith("setuptools")]
    assert setuptools == ["setuptools>=77"]
    assert not any(c.startswith("License ::") for c in py["project"].get("classifiers", []))


def test_line_report_figures_of_a_measurement_without_limits_or_spread_warn_nothing():
    import warnings

    from bench.line.report import _figures

    measure = {"name": "q", "unit": "", "low": None, "high": None, "mean": 1.0, "sigma": 0.0,
               "procedure": "p", "sequence": "s", "final": [{"value": 1.0}], "rows": [{"value": 1.0}],
               "chart": {"center": 1.0, "sigma_within": 0.0, "ucl": 1.0, "lcl": 1.0, "outside": []}}
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # matplotlib's "No artists with labels found to put in legend"
        hist, chart = _figures(measure)
    assert "<svg" in hist and "<svg" in chart


QT_SIZE_HINTS = """
from bench.gui.app import _app
app = _app()
from PySide6.QtCore import qWarning
from PySide6.QtWidgets import QMainWindow
w = QMainWindow(); w.show(); app.processEvents()
w.setMinimumSize(300, 200); app.processEvents(); w.close()  # the offscreen plugin's propagateSizeHints()
qWarning("a message that is kept")
"""


def test_headless_windows_print_no_propagate_size_hints_lines(tmp_path):
    import os
    import subprocess
    import sys

    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY", "QT_QPA_PLATFORM")}
    r = subprocess.run([sys.executable, "-c", QT_SIZE_HINTS], cwd=tmp_path, env={**env, "PYTHONPATH": str(ROOT)},
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    assert "propagateSizeHints" not in r.stderr and "a message that is kept" in r.stderr
