"""Reports of plans: stored data → HTML page (→ PDF).

:func:`gather` reads what a report shows, :func:`render_png` draws the
structure picture, :func:`render_html` writes the page, :func:`render_pdf`
prints it with WeasyPrint; :func:`build_html` chains the first three.
"""

from server.reports.data import FindingData, ReportData, gather
from server.reports.figure import render_png
from server.reports.html import render_html
from server.reports.pdf import PdfUnavailableError, render_pdf
from server.reports.report import build_html

__all__ = [
    "FindingData",
    "PdfUnavailableError",
    "ReportData",
    "build_html",
    "gather",
    "render_html",
    "render_pdf",
    "render_png",
]
