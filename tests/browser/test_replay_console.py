"""The console's replay of a finished run: after a completed
run on the built-in emulator the plan's replay panel shows its timeline;
dragging the slider updates the time and moves the scene's replay robot."""

from __future__ import annotations

import time
from pathlib import Path

import httpx
import numpy as np
import pytest

from tests.browser.test_console import browser, screens, signed_in  # noqa: F401
from tests.conftest import make_settings
from tests.support.live import free_port, live_server

pytestmark = pytest.mark.browser


def _run(url: str, token: str) -> tuple[str, str]:
    """An sbg.inspect plan planned, approved and run to completion on the
    climber's emulator (it reports constant joints and changing odometry:
    the replay robot moves with the planned climber it rides on)."""
    h = {"Authorization": f"Bearer {token}"}
    with httpx.Client(base_url=url + "/api/v1", headers=h, timeout=30) as c:
        r = c.post("/plans", json={"kind": "sbg.inspect", "params": {}})
        pid = r.json()["id"]
        deadline = time.monotonic() + 120
        while c.get(f"/plans/{pid}").json()["state"] in ("queued", "planning"):
            assert time.monotonic() < deadline
            time.sleep(0.1)
        assert c.post(f"/plans/{pid}/approve").status_code == 200
        r = c.post(f"/plans/{pid}/dispatch", json={"robot": "sbg_climber"})
        assert r.status_code in (200, 201, 202), r.text
        eid = r.json()["id"]
        while c.get(f"/executions/{eid}").json()["state"] != "completed":
            assert time.monotonic() < deadline, "the run did not complete"
            time.sleep(0.2)
    return pid, eid


def test_a_completed_run_scrubs_and_moves_the_replay_robot(browser, tmp_path: Path) -> None:  # noqa: F811
    settings = make_settings(
        tmp_path / "var",
        port=free_port(),
        scene_port=free_port(),
        emulators=True,
        emulator_time_scale=40.0,
    )
    with live_server(settings) as (url, tokens, app):
        assert app.state.services.dispatch.wait_connected("sbg_climber", 30)
        pid, eid = _run(url, tokens["operator"])
        op = {"Authorization": f"Bearer {tokens['operator']}"}
        r = httpx.post(
            f"{url}/api/v1/scene/replay", headers=op, json={"execution_id": eid, "t_s": 0}
        )
        assert r.status_code == 200, r.text
        scene = app.state.services.scene
        assert r.json()["node"] == "/plan/robot/replay"  # rides on the planned climber
        climber = scene.server.scene.get_handle_by_name("/plan/robot")
        at_start = np.array(climber.position)
        page, errors = signed_in(browser, url, tokens["operator"])
        try:
            page.wait_for_selector(f"#plans tbody tr[data-id='{pid}']")
            page.locator(f"#plans tbody tr[data-id='{pid}']").click()
            page.wait_for_selector("#replay-box:not([hidden]) #replay-slider")
            assert eid in page.inner_text("#replay-execution")
            assert page.locator(".replay-ticks .tick.ack").count() >= 2
            assert page.locator(".replay-ticks .tick.op").count() >= 1
            # A long program's acknowledgements are thinned to readable ticks
            # (571 of them merged into one bar), the last one kept.
            long = page.evaluate(
                """() => {
                    const tl = replay.tl, n = 571;
                    replay.tl = { ...tl, acks: Array.from({ length: n }, (_, i) =>
                        ({ index: i, op: "joints", t_s: (tl.duration_s * (i + 1)) / n })) };
                    replayRender();
                    const ticks = document.querySelectorAll(".replay-ticks .tick.ack");
                    const last = ticks[ticks.length - 1].title;
                    replay.tl = tl;
                    replayRender();
                    return [ticks.length, last];
                }"""
            )
            assert 100 <= long[0] <= 121 and "command 570 " in long[1], long
            assert page.inner_text("#replay-time").startswith("t = 0.0 s")
            dur = float(page.get_attribute("#replay-slider", "max") or 0)
            assert dur > 0

            # Drag the thumb from the start to the middle of the track.
            box = page.locator("#replay-slider").bounding_box()
            assert box is not None
            y = box["y"] + box["height"] / 2
            page.mouse.move(box["x"] + 8, y)
            page.mouse.down()
            page.mouse.move(box["x"] + box["width"] * 0.3, y, steps=5)
            page.mouse.move(box["x"] + box["width"] / 2, y, steps=5)
            page.mouse.up()
            t = float(page.input_value("#replay-slider"))
            assert abs(t - dur / 2) < dur * 0.05, (t, dur)
            assert page.inner_text("#replay-time").startswith(f"t = {t:.1f} s")
            assert page.inner_text("#replay-command") != "–"
            assert page.locator("#replay-joints tr.q td").count() == 5  # the climber's joints

            # The throttled last request reaches the server's scene: the replay
            # robot stands at the recorded joints of that time.
            h = {"Authorization": f"Bearer {tokens['viewer']}"}
            deadline = time.monotonic() + 10
            current: dict = {}
            while time.monotonic() < deadline:
                current = httpx.get(f"{url}/api/v1/scene", headers=h).json()["current"]
                if (current.get("replay") or {}).get("t_s") == t:
                    break
                time.sleep(0.1)
            rep = current["replay"]
            assert rep["t_s"] == t and rep["execution_id"] == eid, current
            handle = scene._replay["handle"]
            np.testing.assert_allclose(np.asarray(handle._urdf.cfg), rep["q_rad"], atol=1e-9)
            assert scene.server.scene.get_handle_by_name("/plan/robot/replay") is not None
            # The planned climber it rides on stands where the plan was at t.
            assert 0.2 < rep["plan_fraction"] < 0.8
            assert np.linalg.norm(np.array(climber.position) - at_start) > 0.05
            screens(page, "console-replay", focus="#replay-box")
            assert errors == []
        finally:
            page.close()

        # A viewer reads the timeline but cannot drive the scene.
        page, errors = signed_in(browser, url, tokens["viewer"])
        try:
            page.wait_for_selector(f"#plans tbody tr[data-id='{pid}']")
            page.locator(f"#plans tbody tr[data-id='{pid}']").click()
            page.wait_for_selector("#replay-box:not([hidden]) #replay-slider")
            assert page.is_disabled("#replay-drive") and page.is_disabled("#replay-clear")
            assert "operator" in (page.get_attribute("#replay-drive", "title") or "")
            page.fill("#replay-slider", str(dur / 4))  # reads on
            assert page.inner_text("#replay-time").startswith("t = ")
            # Play at 4×: the time runs on; Pause holds it.
            page.select_option("#replay-speed", "4")
            t0 = float(page.input_value("#replay-slider"))
            page.click("#replay-play")
            page.wait_for_timeout(1000)
            page.click("#replay-play")
            assert page.inner_text("#replay-play") == "Play"
            t1 = float(page.input_value("#replay-slider"))
            assert 2.0 < t1 - t0 < 6.0, (t0, t1)  # about 4 s of run in 1 s
            page.wait_for_timeout(300)
            assert float(page.input_value("#replay-slider")) == t1
            assert errors == []
        finally:
            page.close()
