"""The scene follows the console: with a console already open, showing a plan
frames the browser's own camera on it, without a reload."""

from __future__ import annotations

import time
from pathlib import Path

import httpx
import numpy as np
import pytest

from tests.browser.test_console import ARTIFACTS, browser, signed_in  # noqa: F401
from tests.conftest import make_settings
from tests.support.live import free_port, live_server

KINDS = ("blast", "demo.route", "ara.navigate", "sbg.inspect")


def _browser_camera(app) -> tuple[np.ndarray, np.ndarray] | None:
    """The camera the browser reports (viser keeps each client's last report)."""
    clients = list(app.state.services.scene.server.get_clients().values())
    if len(clients) != 1:
        return None
    cam = clients[0].camera
    try:
        return np.asarray(cam.position, float), np.asarray(cam.look_at, float)
    except AssertionError:  # the client has not reported a camera yet
        return None


@pytest.mark.slow
def test_each_plan_is_framed_in_an_open_console(browser, tmp_path: Path) -> None:  # noqa: F811
    settings = make_settings(tmp_path / "var", port=free_port(), scene_port=free_port())
    with live_server(settings) as (url, tokens, app):
        page, errors = signed_in(browser, url, tokens["operator"])
        page.wait_for_function("document.querySelector('#scene').src.endsWith('/scene/')")
        deadline = time.monotonic() + 60
        while _browser_camera(app) is None:  # the console's scene is open and connected
            assert time.monotonic() < deadline, "the scene's browser client never connected"
            time.sleep(0.2)
        auth = {"Authorization": f"Bearer {tokens['operator']}"}
        for kind in KINDS:
            r = httpx.post(f"{url}/api/v1/plans", json={"kind": kind, "params": {}}, headers=auth)
            pid = r.json()["id"]
            row = f"#plans tbody tr[data-id='{pid}']"
            page.wait_for_selector(f"{row}[data-state='planned']", timeout=120_000)
            page.locator(row).click()
            page.click("#show")
            page.wait_for_function(
                f"document.querySelector('#scene-msg').textContent.includes('{pid}')"
            )
            scene = app.state.services.scene
            assert scene.current.get("plan_id") == pid
            view = scene.current["view"]
            want_pos, want_at = np.asarray(view["position"]), np.asarray(view["look_at"])
            deadline = time.monotonic() + 15
            while True:  # the browser moved its camera and reported it back
                got = _browser_camera(app)
                if got is not None:
                    pos, at = got
                    if np.abs(pos - want_pos).max() < 0.01 and np.abs(at - want_at).max() < 0.01:
                        break
                assert time.monotonic() < deadline, (kind, got, view)
                time.sleep(0.1)
            ARTIFACTS.mkdir(exist_ok=True)
            page.locator("#scene").screenshot(path=str(ARTIFACTS / f"scene-follows-{kind}.png"))
        assert not errors, errors
