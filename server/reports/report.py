"""The report of one plan as an HTML page: gathered, drawn, written."""

from __future__ import annotations

from server.reports.data import gather
from server.reports.figure import render_png
from server.reports.html import render_html
from server.services import Services


def build_html(services: Services, plan_id: str) -> str:
    """Plan ``plan_id``'s report page (``NotFoundError`` when there is no such plan)."""
    data = gather(services, plan_id)
    png = render_png(data.plan, data.findings + data.withdrawn)
    return render_html(data, png)
