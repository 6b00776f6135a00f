"""HTML pages to PDF through WeasyPrint (the `pdf` extra): the run report, the unit certificate and
the lot report all print this way."""

from __future__ import annotations

from pathlib import Path
from typing import Any


class PdfUnavailable(RuntimeError):
    """WeasyPrint (the `pdf` extra) is not installed."""


def require_weasyprint() -> Any:
    """WeasyPrint, or PdfUnavailable naming the extra to install."""
    try:
        import weasyprint
    except (ImportError, OSError) as exc:  # not installed, or its system libraries (Pango) missing
        raise PdfUnavailable(f"a PDF report needs WeasyPrint: pip install 'gyrobench[pdf]' ({exc})") from None
    return weasyprint


def write_pdf(html: str, path: str | Path) -> Path:
    """An HTML page (a run report, a certificate, a lot report) as a PDF: WeasyPrint renders the
    inline SVG figures as vectors."""
    weasyprint = require_weasyprint()
    import logging

    logging.getLogger("fontTools").setLevel(logging.WARNING)
    weasyprint.HTML(string=html).write_pdf(str(path))
    return Path(path)
