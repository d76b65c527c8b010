"""A report page as PDF, by WeasyPrint.

WeasyPrint is imported on first use: it loads Pango, HarfBuzz and
fontconfig through cffi, and a host without them (a slim container) must
still serve the HTML report.  When it cannot be imported or cannot load its
libraries, :func:`render_pdf` raises :class:`PdfUnavailableError` with the
reason, which the route answers as 503.  The PDF's identifier is derived
from the page, so the same page gives the same document identity.
"""

from __future__ import annotations

import hashlib
import importlib
from typing import Any


class PdfUnavailableError(RuntimeError):
    """WeasyPrint (or a library it loads at run time) is not usable here."""


def _import_weasyprint() -> Any:
    """The ``weasyprint`` module (raises ``ImportError`` / ``OSError`` as it does)."""
    return importlib.import_module("weasyprint")


def render_pdf(page: str) -> bytes:
    """``page`` (a self-contained HTML document) as PDF bytes."""
    try:
        weasyprint = _import_weasyprint()
    except (ImportError, OSError) as exc:
        raise PdfUnavailableError(
            "PDF reports need WeasyPrint and the Pango libraries it loads "
            f"(pip install weasyprint; apt-get install libpango-1.0-0): {exc}"
        ) from exc
    ident = hashlib.sha256(page.encode("utf-8")).hexdigest()[:32].encode("ascii")
    pdf: bytes = weasyprint.HTML(string=page).write_pdf(pdf_identifier=ident)
    return pdf
