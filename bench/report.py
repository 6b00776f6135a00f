"""The run report (kept for its callers): `bench.reporting` draws the figures with matplotlib and
lays the page out with a Jinja2 template."""

from __future__ import annotations

from typing import Any

from bench.reporting import render_html, write_pdf, write_report

__all__ = ["render_report", "render_html", "write_pdf", "write_report"]


def render_report(data: Any, run_row: dict[str, Any] | None = None) -> str:
    """HTML for one run from its raw file (a RunData) and, when known, its results-store row."""
    return render_html(data, run_row)
