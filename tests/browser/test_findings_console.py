"""The console's findings list beside an inspection plan, in
Debian's Chromium: both findings with their condition colours, the filters,
framing the scene on a finding, a blast plan made and selected from one, and
a viewer's read-only list."""

from __future__ import annotations

import time
from pathlib import Path

import httpx
import numpy as np
import pytest

from tests.api.test_finding_plans import _patch
from tests.api.test_scene_findings import _web, ctrl_click
from tests.api.test_scene_proposals import camera_message, raw_viser, wait_for
from tests.browser.test_console import browser, screens, signed_in  # noqa: F401 (fixture)
from tests.conftest import make_settings
from tests.support.live import free_port, live_server

pytestmark = pytest.mark.browser


def _inspection_with_two_findings(url: str, token: str) -> tuple[dict, dict, dict]:
    h = {"Authorization": f"Bearer {token}"}
    r = httpx.post(
        f"{url}/api/v1/plans", json={"kind": "ara.inspect", "params": {"sample_seed": 2}}, headers=h
    )
    pid = r.json()["id"]
    deadline = time.monotonic() + 120
    while True:
        plan = httpx.get(f"{url}/api/v1/plans/{pid}", headers=h).json()
        if plan["state"] not in ("queued", "planning") or time.monotonic() > deadline:
            break
        time.sleep(0.3)
    assert plan["state"] == "planned", plan.get("error")
    member = plan["result"]["members"][0]
    face = member["faces"][0]
    centre = np.asarray(face["outline"], float).mean(axis=0)
    base = {"plan_id": pid, "member_id": member["id"], "point_m": list(centre)}
    rust = httpx.post(
        f"{url}/api/v1/findings",
        json={**base, "face_id": face["id"], "region_m": _patch(face, centre, 0.15),
              "type": "corrosion", "condition_state": 3, "notes": "rust bloom by the gusset"},
        headers=h,
    )  # fmt: skip
    crack = httpx.post(
        f"{url}/api/v1/findings",
        json={**base, "type": "crack", "condition_state": 1, "notes": "hairline, to watch"},
        headers=h,
    )
    assert rust.status_code == 201 and crack.status_code == 201, (rust.text, crack.text)
    shown = httpx.post(f"{url}/api/v1/scene/show", json={"plan_id": pid}, headers=h)
    assert shown.status_code == 200, shown.text
    return plan, rust.json(), crack.json()


def _findings(url: str, h: dict, plan_id: str) -> list[dict]:
    return httpx.get(f"{url}/api/v1/findings?plan_id={plan_id}", headers=h).json()


def _pending_in(url: str, h: dict) -> dict | None:
    got = httpx.get(f"{url}/api/v1/scene/proposals?state=pending", headers=h).json()
    return got[0] if got else None


def _rows(page) -> list[str]:
    return page.eval_on_selector_all(
        "#findings-box tr[data-finding]", "rs => rs.map(r => r.dataset.finding)"
    )


def test_findings_list_filters_frames_and_makes_a_blast_plan(browser, tmp_path: Path) -> None:  # noqa: F811
    settings = make_settings(tmp_path / "var", port=free_port(), scene_port=free_port())
    with live_server(settings) as (url, tokens, app):
        plan, rust, crack = _inspection_with_two_findings(url, tokens["operator"])
        page, errors = signed_in(browser, url, tokens["operator"])
        page.wait_for_selector(f"#plans tbody tr[data-id='{plan['id']}']", timeout=60_000)
        page.locator(f"#plans tbody tr[data-id='{plan['id']}']").click()
        page.wait_for_selector("#findings-box:not([hidden]) tr[data-finding]")
        page.wait_for_function(
            "document.querySelectorAll('#findings-box tr[data-finding]').length == 2"
        )
        assert set(_rows(page)) == {rust["id"], crack["id"]}
        colour = lambda fid: page.eval_on_selector(  # noqa: E731
            f"tr[data-finding='{fid}'] .f-cs", "e => getComputedStyle(e).backgroundColor"
        )
        assert colour(rust["id"]) == "rgb(240, 130, 30)"  # 3 poor: orange
        assert colour(crack["id"]) == "rgb(60, 170, 80)"  # 1 good: green
        text = page.inner_text(f"tr[data-finding='{rust['id']}']")
        assert "corrosion" in text and "3 poor" in text and "rust bloom" in text
        assert f"member {rust['member_id']} / face {rust['face_id']}" in text
        assert "0 photos" in text
        # The crack has no face: no blast plan from it (the reason on hover).
        blast_crack = page.locator(f"tr[data-finding='{crack['id']}'] button.f-blast")
        assert blast_crack.is_disabled() and "corrosion" in (
            blast_crack.get_attribute("title") or ""
        )

        # Filters: minimum condition state 3 hides the crack; type crack hides the rust.
        page.select_option("#f-min", "3")
        assert _rows(page) == [rust["id"]]
        assert page.inner_text("#f-count") == "1 of 2"
        page.select_option("#f-min", "1")
        page.select_option("#f-type", "crack")
        assert _rows(page) == [crack["id"]]
        page.select_option("#f-type", "")
        assert len(_rows(page)) == 2

        # Clicking a finding frames the scene on it.
        page.locator(f"tr[data-finding='{rust['id']}'] td").nth(1).click()
        scene = app.state.services.scene  # type: ignore[attr-defined]
        deadline = time.monotonic() + 10
        while time.monotonic() < deadline:
            if np.allclose(scene.server.initial_camera.look_at, rust["point_m"], atol=1e-3):
                break
            time.sleep(0.1)
        np.testing.assert_allclose(scene.server.initial_camera.look_at, rust["point_m"], atol=1e-3)
        assert (
            page.locator(f"tr[data-finding='{rust['id']}']").get_attribute("class").count("framed")
        )
        screens(page, "console-findings", focus="#findings-box")

        # Blast plan: made from the finding, then selected.
        page.locator(f"tr[data-finding='{rust['id']}'] button.f-blast").click()
        page.wait_for_function(
            f"state.selected && state.selected !== '{plan['id']}'"
            " && (state.plans.get(state.selected) || {}).kind === 'blast'",
            timeout=30_000,
        )
        blast_id = page.evaluate("state.selected")
        # select() sets state.selected before the detail is drawn: wait for it
        page.wait_for_function(
            "document.querySelector('#d-title').textContent"
            f".includes('{blast_id} · blast (from finding {rust['id']})')"
        )
        # The scene shows the new blast plan too, not the inspection it came from.
        page.wait_for_function(
            f"document.querySelector('#scene-msg').textContent.includes('{blast_id}')",
            timeout=30_000,
        )
        # Back on the inspection, the finding lists its blast plan.
        page.locator(f"#plans tbody tr[data-id='{plan['id']}']").click()
        page.wait_for_selector(f"tr[data-finding='{rust['id']}'] a.f-plan[data-plan='{blast_id}']")

        # A Ctrl-click on a face in the scene proposes a finding; the console's
        # Accept… asks what it is and creates it on the plan.
        h = {"Authorization": f"Bearer {tokens['operator']}"}
        httpx.post(f"{url}/api/v1/scene/show", json={"plan_id": plan["id"]}, headers=h)
        member, face, c, n = _web(plan)
        with raw_viser(scene.port, scene.issue_ticket()) as ws:
            ws.recv(timeout=10)
            ws.send(camera_message())
            ws.send(ctrl_click(c + 0.5 * n, -n))
            prop = wait_for(lambda: _pending_in(url, h), 10)
        assert prop is not None and prop["action"] == "finding"
        page.wait_for_selector(f"tr[data-proposal='{prop['id']}'] button.accept")
        page.locator(f"tr[data-proposal='{prop['id']}'] button.accept").click()
        page.wait_for_selector("#finding-form form")
        page.select_option("#finding-form select[name=type]", "section_loss")
        page.select_option("#finding-form select[name=condition_state]", "4")
        page.fill("#finding-form textarea[name=notes]", "flange thinned at the bolt row")
        page.locator("#finding-form button[type=submit]").click()
        page.wait_for_selector("#finding-form", state="detached")
        page.wait_for_function(
            "document.querySelectorAll('#findings-box tr[data-finding]').length == 3"
        )
        made = [f for f in _findings(url, h, plan["id"]) if f["type"] == "section_loss"]
        assert len(made) == 1 and made[0]["condition_state"] == 4
        assert (made[0]["member_id"], made[0]["face_id"]) == (member, face["id"])
        new_row = f"tr[data-finding='{made[0]['id']}']"
        assert "4 severe" in page.inner_text(new_row)

        # Close inspection of that member: an ara.inspect plan made and selected.
        page.locator(f"{new_row} button.f-inspect").click()
        page.wait_for_function(
            f"state.selected && state.selected !== '{plan['id']}'"
            " && (state.plans.get(state.selected) || {}).kind === 'ara.inspect'",
            timeout=30_000,
        )
        close_id = page.evaluate("state.selected")
        close = httpx.get(f"{url}/api/v1/plans/{close_id}", headers=h).json()
        assert close["params"]["close_member"] == member

        # A withdrawn finding shows only with the "withdrawn" toggle, marked.
        httpx.delete(f"{url}/api/v1/findings/{crack['id']}?reason=duplicate", headers=h)
        page.locator(f"#plans tbody tr[data-id='{plan['id']}']").click()
        page.wait_for_function(
            "document.querySelectorAll('#findings-box tr[data-finding]').length == 2"
        )
        page.check("#f-withdrawn")
        page.wait_for_selector(f"tr.withdrawn[data-finding='{crack['id']}']")
        assert "withdrawn by" in page.inner_text(f"tr[data-finding='{crack['id']}']")
        page.uncheck("#f-withdrawn")
        assert not errors, errors

        # A viewer reads the list; every finding button is disabled, with why.
        view, verrors = signed_in(browser, url, tokens["viewer"])
        view.wait_for_selector(f"#plans tbody tr[data-id='{plan['id']}']", timeout=60_000)
        view.locator(f"#plans tbody tr[data-id='{plan['id']}']").click()
        view.wait_for_function(
            "document.querySelectorAll('#findings-box tr[data-finding]').length == 2"
        )
        buttons = view.locator("#findings-box button")
        assert buttons.count() >= 4
        for i in range(buttons.count()):
            assert buttons.nth(i).is_disabled()
            assert "operator role" in (buttons.nth(i).get_attribute("title") or "")
        assert not verrors, verrors
