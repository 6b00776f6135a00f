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
               "final": [{"value": 1.0}], "rows": [{"value": 1.0}]}
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # matplotlib's "No artists with labels found to put in legend"
        hist, chart = _figures(measure)
    assert "<svg" in hist and "<svg" in chart
