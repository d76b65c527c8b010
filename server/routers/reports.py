"""``/api/v1/reports``: a plan's report from stored data.

``GET /reports/{plan_id}`` answers a self-contained HTML page — header and
parameters, the structure picture, route and metrics, checks, findings with
their photos and linked maintenance plans, withdrawn findings, executions and
the audit trail — for any plan kind; ``?format=pdf`` the same page printed by
WeasyPrint (503 when WeasyPrint cannot load its libraries here).  Viewer
reads.  The same stored data gives the same bytes of HTML.
"""

from __future__ import annotations

from typing import Annotated, Literal

from fastapi import APIRouter, Depends, HTTPException, Query
from fastapi.responses import HTMLResponse, Response

from server.auth import Viewer
from server.reports import PdfUnavailableError, build_html, render_pdf
from server.routers.responses import errors
from server.services import Services, get_services

router = APIRouter(prefix="/reports", tags=["reports"])

Svc = Annotated[Services, Depends(get_services)]

ReportFormat = Literal["html", "pdf"]


@router.get(
    "/{plan_id}",
    response_class=HTMLResponse,
    responses={
        200: {
            "description": "the report: an HTML page, or a PDF with format=pdf",
            "content": {"text/html": {}, "application/pdf": {}},
        },
        **errors(401, 404, 422, 503),
    },
)
def get_report(
    plan_id: str,
    services: Svc,
    _: Viewer,
    format: Annotated[
        ReportFormat, Query(description="html (default) or pdf (printed by WeasyPrint)")
    ] = "html",
) -> Response:
    """A plan's inspection report, built from stored data only."""
    page = build_html(services, plan_id)  # NotFoundError → 404
    if format == "html":
        return HTMLResponse(page)
    try:
        pdf = render_pdf(page)
    except PdfUnavailableError as exc:
        raise HTTPException(503, detail=str(exc)) from exc
    return Response(
        pdf,
        media_type="application/pdf",
        headers={"Content-Disposition": f'inline; filename="report-{plan_id}.pdf"'},
    )
