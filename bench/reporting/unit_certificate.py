"""The run report with a unit's calibration certificate (bench.line.certificate) as its first page."""

from __future__ import annotations

from typing import Any

from bench.line.certificate import TEMPLATES as CERTIFICATE_TEMPLATES
from bench.line.certificate import certificate_section
from bench.line.compensation import Compensation

from . import TEMPLATES, context


def report_with_certificate(data: Any, record: dict[str, Any], row: dict[str, Any] | None = None,
                            compensation: Compensation | None = None) -> str:
    """The run report (bench.reporting) with the unit's certificate as its first page: the report's
    `certificate` block filled by templates/report_certificate.html.j2."""
    import jinja2
    from markupsafe import Markup

    loader = jinja2.ChoiceLoader([jinja2.FileSystemLoader(CERTIFICATE_TEMPLATES), jinja2.FileSystemLoader(TEMPLATES)])
    env = jinja2.Environment(loader=loader, autoescape=True, trim_blocks=True, lstrip_blocks=True,
                             undefined=jinja2.StrictUndefined)
    section = Markup(certificate_section(record, compensation))  # rendered (and escaped) by its own template
    return env.get_template("report_certificate.html.j2").render(**context(data, row),
                                                                 certificate_html=section)
