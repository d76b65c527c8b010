"""A plan's report in a real browser: Debian's Chromium shows
the report of a sample inspection with its findings; with
STEELPATH_DOCS_SCREENSHOTS=1 it is the docs' report-1280/1920.png."""

from __future__ import annotations

import io
import time
from pathlib import Path

import httpx
import numpy as np
import pytest
from PIL import Image

from tests.browser.test_console import browser, screens  # noqa: F401 - the fixture
from tests.conftest import make_settings
from tests.support.live import free_port, live_server

pytestmark = pytest.mark.browser


def _photo() -> bytes:
    im = Image.new("RGB", (400, 300), (150, 80, 40))
    for x in range(0, 400, 25):
        for y in range(300):
            im.putpixel((x, y), (60, 40, 30))
    buf = io.BytesIO()
    im.save(buf, format="PNG")
    return buf.getvalue()


def _planned(client: httpx.Client, kind: str, params: dict) -> dict:
    pid = client.post("/api/v1/plans", json={"kind": kind, "params": params}).json()["id"]
    deadline = time.monotonic() + 120
    while True:
        plan = client.get(f"/api/v1/plans/{pid}").json()
        if plan["state"] not in ("queued", "planning"):
            return plan
        assert time.monotonic() < deadline, plan
        time.sleep(0.2)


def test_report_of_a_sample_inspection(browser, tmp_path: Path) -> None:  # noqa: F811
    settings = make_settings(tmp_path / "var", port=free_port(), scene_port=free_port())
    with live_server(settings) as (url, tokens, _app):
        auth = {"Authorization": f"Bearer {tokens['operator']}"}
        with httpx.Client(base_url=url, headers=auth, timeout=30) as client:
            plan = _planned(client, "ara.inspect", {"sample_seed": 2})
            assert plan["state"] in ("planned", "rejected"), plan.get("error")
            members = plan["result"]["members"]
            for i, (kind, state, notes) in enumerate(
                (
                    ("corrosion", 3, "rust bloom at the bearing, flange edge pitted"),
                    ("coating_loss", 2, "paint flaking over 0.2 m²"),
                    ("crack", 4, "crack at the weld toe of the gusset"),
                )
            ):
                member = members[(i * 5) % len(members)]
                face = member["faces"][0]
                centre = np.asarray(face["outline"]).mean(axis=0)
                r = client.post(
                    "/api/v1/findings",
                    json={
                        "plan_id": plan["id"],
                        "member_id": member["id"],
                        "face_id": face["id"],
                        "point_m": list(centre),
                        "type": kind,
                        "condition_state": state,
                        "notes": notes,
                    },
                )
                assert r.status_code == 201, r.text
                if i == 0:
                    r = client.post(
                        f"/api/v1/findings/{r.json()['id']}/photos",
                        files={"file": ("bearing.png", _photo(), "image/png")},
                    )
                    assert r.status_code == 201, r.text

        page = browser.new_page(
            viewport={"width": 1400, "height": 1000},
            extra_http_headers={"Authorization": f"Bearer {tokens['viewer']}"},
        )
        errors: list[str] = []
        page.on("pageerror", lambda e: errors.append(str(e)))
        page.goto(f"{url}/api/v1/reports/{plan['id']}")
        page.wait_for_selector("#structure-picture")
        loaded = page.evaluate(
            "() => { const i = document.querySelector('#structure-picture');"
            " return i.complete && i.naturalWidth > 0 ? i.naturalWidth : 0 }"
        )
        assert loaded > 600
        assert page.locator("table.findings tbody tr").count() == 3
        assert page.evaluate(
            "() => [...document.querySelectorAll('img.photo')]"
            ".every(i => i.complete && i.naturalWidth > 0)"
        )
        assert "rust bloom at the bearing" in page.inner_text("#findings")
        assert plan["id"] in page.title()
        assert errors == []
        screens(page, "report")
        page.close()
