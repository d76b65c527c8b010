"""Every plan kind through the console's form, no JSON typed: a sample cloud
loaded and picked where the kind takes one, choices picked in the scene
(start and end vertices, blast's surface), plan, review,
approve, dispatch to the kind's robot (the embedded emulators) and watch the
execution to completion; a plan with no robot program (ara.inspect without
its jumps planned) stops at approval, its Dispatch disabled with the reason on
hover.

One server for the module; each kind gets a fresh page.  Emulated motions
run :data:`TIME_SCALE` times faster than real time so the longest default
program (the blasting arm's) finishes in seconds.
"""

from __future__ import annotations

import time
from collections.abc import Iterator
from typing import Any

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from tests.browser.test_console import (  # noqa: F401 (browser: a fixture)
    ARTIFACTS,
    browser,
    screens,
    signed_in,
)
from tests.conftest import make_settings
from tests.support.live import free_port, live_server
from tests.support.waiting import wait_for

TIME_SCALE = 40.0

#: Kinds whose start and end are picked in the scene: after the first plan,
#: two clicks on its vertices in the viser canvas propose a revision, which is
#: accepted in the console and carried through the rest of the flow.
SCENE_PICKS = {"demo.route", "ara.navigate", "ara.inspect"}
#: Kinds planned on a sample cloud loaded through the console and picked in
#: the form's cloud field.  blast then picks its surface in the scene: the
#: plane centres are clickable, and plane 1 (a web patch of the girder) is
#: one the arm reaches (tests/api/test_blast.py).
CLOUDS = {
    "ara.navigate": "cross",
    "ara.switch": "switch_perpendicular",
    "blast": "blast_under_deck",
}
PLANE_PICK = 1

#: Form edits per kind (field → value typed or picked); the rest stay default.
#: ara.inspect: the default sample (Warren seed 2, UPN 200 web members) is one
#: the ARA can drive; seed 0's web members are L 80 angles, narrower than the
#: 0.12 m foot, so its route is honestly rejected.  The form is edited to seed
#: 2 anyway, so that typing into a field is exercised.
EDITS: dict[str, dict[str, str]] = {"ara.inspect": {"sample_seed": "2"}}

KINDS = [
    "ara.inspect",
    "ara.navigate",
    "ara.switch",
    "blast",
    "cmbot.climb",
    "cmbot.manipulate",
    "demo.route",
    "sbg.inspect",
]


@pytest.fixture(scope="module")
def server(tmp_path_factory) -> Iterator[tuple[str, dict[str, str], Any]]:
    settings = make_settings(
        tmp_path_factory.mktemp("every") / "var",
        port=free_port(),
        scene_port=free_port(),
        emulators=True,
        emulator_time_scale=TIME_SCALE,
    )
    with live_server(settings) as (url, tokens, app):
        for name in app.state.services.dispatch.robot_names():
            assert app.state.services.dispatch.wait_connected(name, 30), name
        yield url, tokens, app


@pytest.mark.parametrize("kind", KINDS)
def test_kind_from_the_form_to_a_completed_run(browser, server, kind: str) -> None:  # noqa: F811
    url, tokens, app = server
    page, errors = signed_in(browser, url, tokens["operator"], height=1100)
    try:
        _flow(page, errors, app, kind)
    finally:
        page.close()  # a page left open keeps its WebGL scene drawing


def _flow(page: Any, errors: list[str], app: Any, kind: str) -> None:
    page.wait_for_selector(f"#kind option[value='{kind}']", state="attached")
    if kind not in SCENE_PICKS and kind != "blast":
        # This run does not look at the scene: software WebGL drawing it
        # would only slow the machine the emulators run on.
        page.evaluate("document.querySelector('#scene').src = 'about:blank'")
    page.select_option("#kind", kind)
    page.wait_for_selector("#params-form .field")
    if kind in CLOUDS:
        page.select_option("#sample", CLOUDS[kind])
        page.click("#load-sample")
        page.wait_for_function(
            "document.querySelector('#cloud-msg').textContent.startsWith('stored')"
        )
        cloud_id = page.inner_text("#cloud-msg").split()[1].rstrip(":")
        page.wait_for_selector(f"#pf-cloud_id option[value='{cloud_id}']", state="attached")
        page.select_option("#pf-cloud_id", cloud_id)
    for field, value in EDITS.get(kind, {}).items():
        sel = f"#pf-{field}"
        if not page.is_visible(sel):
            page.click("#params-form details summary")
        page.fill(sel, value)
    # The form sends only what differs from the defaults: nothing typed as JSON.
    page.click("#tab-json")
    sent = page.input_value("#params").strip()
    page.click("#tab-form")
    before = set(
        page.eval_on_selector_all("#plans tbody tr", "rows => rows.map(r => r.dataset.id)")
    )
    page.click("#submit-plan")
    plan_id = page.wait_for_function(
        "ids => [...document.querySelectorAll('#plans tbody tr')]"
        ".filter(r => !['queued', 'planning'].includes(r.dataset.state))"
        ".map(r => r.dataset.id).find(i => !ids.includes(i)) || null",
        arg=list(before),
        timeout=120_000,
    ).json_value()
    assert isinstance(plan_id, str), plan_id
    plan = app.state.services.store.get_plan(plan_id)
    assert plan.kind == kind
    failed = [c.get("message") for c in plan.checks if not c.get("passed")]
    assert plan.state == "planned", (plan.state, plan.error, failed, sent)

    if kind in CLOUDS:
        assert plan.params["cloud_id"] == cloud_id
    if kind in SCENE_PICKS or kind == "blast":
        plan_id = _pick_in_the_scene(page, app, plan_id, kind)
        plan = app.state.services.store.get_plan(plan_id)
        failed = [c.get("message") for c in plan.checks if not c.get("passed")]
        assert plan.state == "planned", (plan.state, plan.error, failed, plan.params)

    # Review: the detail shows every check passing; approve it.
    page.locator(f"#plans tbody tr[data-id='{plan_id}']").click()
    page.wait_for_function(
        f"document.querySelector('#d-title').textContent.startsWith('{plan_id}')"
    )
    from server.kinds import registry

    spec = registry()[kind]
    first = plan.checks[0]["name"]
    page.wait_for_selector(f"#d-checks tr[data-check='{first}']")
    assert "FAIL" not in page.inner_text("#d-checks")
    page.click("#approve")
    page.wait_for_function("document.querySelector('#d-state').textContent === 'approved'")
    if not plan.program:
        # ara.inspect without its jumps planned has no robot program: nothing
        # to dispatch, and the greyed button says why.
        assert page.is_disabled("#dispatch")
        note = (plan.result or {}).get("program_note")
        assert note and page.get_attribute("#dispatch", "title") == note
        assert not errors, errors
        return

    # Dispatch to the kind's robot (preselected) and watch it complete.
    page.wait_for_selector("#d-checks tr[data-check='command_program']")
    robot = spec.robot
    page.click("#dispatch")
    chosen = page.input_value("#dispatch-robot")
    assert chosen == robot, (chosen, robot)
    page.click("#dispatch-confirm")
    page.wait_for_function(
        "['completed', 'faulted', 'aborted', 'interrupted']"
        ".includes(document.querySelector('#x-state').textContent)",
        timeout=240_000,
    )
    state = page.inner_text("#x-state")
    progress = page.inner_text("#x-progress")
    ARTIFACTS.mkdir(exist_ok=True)
    page.screenshot(path=str(ARTIFACTS / f"every-kind-{kind}.png"))
    if kind == "cmbot.climb":  # the execution view, for the README
        screens(page, "console-execution", focus="#x-state")
    assert state == "completed", (state, progress)
    # Progress by command and by planned time, both full.
    total_s = sum(max(float(c.get("duration_s", 0.0) or 0.0), 0.0) for c in plan.program or [])
    n = len(plan.program or [])
    assert progress.startswith(f"{n}/{n} commands · {total_s:.1f} of {total_s:.1f} s planned"), (
        progress
    )
    (ex,) = app.state.services.store.list_executions(plan_id=plan_id)
    assert ex.state == "completed" and ex.acked == ex.total and ex.robot == chosen
    assert not errors, errors


def test_every_kind_is_covered() -> None:
    from server.kinds import registry

    shipped = {k for k in registry() if not k.startswith("test.")}
    assert shipped == set(KINDS), shipped ^ set(KINDS)


def _world(scene: Any, name: str, points: np.ndarray) -> np.ndarray:
    """``points`` of node ``name`` in the world frame (its own and its
    parents' poses)."""
    T = np.eye(4)
    parts = name.strip("/").split("/")
    for k in range(1, len(parts) + 1):
        h = scene.get_handle_by_name("/" + "/".join(parts[:k]))
        if h is None:
            continue
        w, x, y, z = (float(v) for v in h.wxyz)
        M = np.eye(4)
        M[:3, :3] = Rotation.from_quat([x, y, z, w]).as_matrix()
        M[:3, 3] = np.asarray(h.position, dtype=float)
        T = T @ M
    return points @ T[:3, :3].T + T[:3, 3]


def _pixel(cam: Any, p: np.ndarray) -> tuple[float, float, float]:
    """Where the client's camera sees world point ``p``: (u, v) in its image
    pixels (viser's camera frame: x right, y down, z forward) and the depth."""
    w, x, y, z = (float(v) for v in cam.wxyz)
    R = Rotation.from_quat([x, y, z, w]).as_matrix()
    c = R.T @ (np.asarray(p, dtype=float) - np.asarray(cam.position, dtype=float))
    f = (cam.image_height / 2) / np.tan(cam.fov / 2)
    return cam.image_width / 2 + f * c[0] / c[2], cam.image_height / 2 + f * c[1] / c[2], c[2]


def _pick_in_the_scene(page: Any, app: Any, plan_id: str, kind: str) -> str:
    """Show the plan, click in the viser canvas (real pointer clicks) two of
    its vertices (start, end) or, for blast, a plane centre; accept the
    proposal in the console; the revision's id."""
    page.click("#show")
    frame = page.wait_for_selector("#scene").content_frame()
    canvas = frame.locator("canvas[data-engine^='three']").first
    canvas.wait_for(timeout=60_000)
    page.locator("#scene").scroll_into_view_if_needed()
    service = app.state.services.scene
    scene = service.server.scene
    # the show runs on the server while the page loads: wait until it is drawn and framed
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:
        now = dict(service.current)
        if now.get("plan_id") == plan_id and "view" in now:
            break
        time.sleep(0.1)
    suffix = "/planes" if kind == "blast" else "/vertices"
    name = next(n for n in scene._handle_from_node_name if n.endswith(suffix))
    handle = scene.get_handle_by_name(name)
    pts = _world(scene, name, np.asarray(handle.batched_positions, dtype=float))
    # The framing reaches the browser's camera; wait until the client reports it.
    view = service.current["view"]
    cam = _settled_camera(service, view)
    time.sleep(1.0)  # the last frame drawn at that view
    box = canvas.bounding_box()
    assert box is not None
    width, height = box["width"], box["height"]

    def on_screen() -> tuple[np.ndarray, np.ndarray]:
        px = np.array([_pixel(cam, p) for p in pts])
        inside = np.nonzero(
            (px[:, 2] > 0)
            & (px[:, 0] > 20)
            & (px[:, 0] < cam.image_width - 20)
            & (px[:, 1] > 20)
            & (px[:, 1] < cam.image_height - 20)
        )[0]
        return px, inside

    def click(px: np.ndarray, i: int) -> None:
        canvas.click(
            position={
                "x": px[i, 0] * width / cam.image_width,
                "y": px[i, 1] * height / cam.image_height,
            }
        )
        page.wait_for_timeout(1200)  # proposals are rate-limited per client

    px, inside = on_screen()
    if kind == "blast":
        assert PLANE_PICK in inside, "the plane to pick is off screen"
        keys = {"plane_index"}
        # One click proposes.  Once in CI a click here made no proposal, for a
        # reason never established (it did not recur here, loaded or not); an
        # operator clicks again, and so does this test (at most three times),
        # each time at the marker seen by the camera the client reports then.
        tries: list[str] = []
        for attempt in range(3):
            if attempt:
                cam = _settled_camera(service, view)
                px, inside = on_screen()
            click(px, PLANE_PICK)
            if _pending(service, 10.0):
                break
            tries.append(_diagnosis(service, cam, px[PLANE_PICK]))
        assert service.proposals.list("pending"), "no proposal after 3 clicks: " + "; ".join(tries)
    else:
        assert len(inside) >= 2, "fewer than two vertices on screen"
        # Two vertices far apart on screen: the first, and the farthest from it.
        a = int(inside[0])
        b = int(inside[np.argmax(np.linalg.norm(px[inside, :2] - px[a, :2], axis=1))])
        keys = {"start", "end"}
        for i in (a, b):
            click(px, i)
        assert _pending(service, 30.0), "no proposal: " + _diagnosis(service, cam, px[b])
    page.wait_for_selector("#proposals tr[data-proposal]", timeout=30_000)
    (prop,) = service.proposals.list("pending")
    assert set(prop.patch) == keys, prop.patch
    if kind == "blast":
        assert prop.patch["plane_index"] == PLANE_PICK
    else:
        assert prop.patch["start"] != prop.patch["end"]
    store = app.state.services.store
    page.click("#proposals tr[data-proposal] button.accept")
    page.wait_for_function(
        f"document.querySelector('#d-title').textContent.includes('revision of {plan_id}')",
        timeout=60_000,
    )
    (child,) = store.list_plans(parent_id=plan_id)
    deadline = time.monotonic() + 120
    while store.get_plan(child.id).state in ("queued", "planning"):
        assert time.monotonic() < deadline, "the revision never finished planning"
        time.sleep(0.2)
    done = store.get_plan(child.id)
    assert {k: done.params[k] for k in keys} == prop.patch
    page.locator(f"#plans tbody tr[data-id='{child.id}']").click()
    page.evaluate("document.querySelector('#scene').src = 'about:blank'")  # done with it
    return child.id


def _settled_camera(service: Any, view: dict[str, Any], timeout: float = 30.0) -> Any:
    """The scene client's camera once it shows ``view`` (look-at *and*
    position: the server sets them as two messages, and a report can fall
    between them) and two reports half a second apart agree."""
    look = np.asarray(view["look_at"], dtype=float)
    where = np.asarray(view["position"], dtype=float)
    deadline = time.monotonic() + timeout
    last = None
    while time.monotonic() < deadline:
        for client in list(service.server.get_clients().values()):
            cam = client.camera
            if np.allclose(cam.look_at, look, atol=2e-3) and np.allclose(
                cam.position, where, atol=2e-3
            ):
                state = (
                    tuple(np.round(cam.wxyz, 6)),
                    tuple(np.round(cam.position, 6)),
                    cam.image_width,
                    cam.image_height,
                )
                if state == last:
                    return cam
                last = state
                break
        time.sleep(0.5)
    raise AssertionError(f"the scene's camera never settled on the framed view {view}")


def _pending(service: Any, timeout: float) -> bool:
    """Whether a proposal is pending within ``timeout`` seconds."""
    try:
        wait_for(lambda: service.proposals.list("pending"), timeout, "a proposal", poll_s=0.2)
    except AssertionError:
        return False
    return True


def _diagnosis(service: Any, cam: Any, clicked: np.ndarray) -> str:
    """What a failed pick saw: where it clicked, the camera the client
    reports now, the clients, and proposals dropped by the rate limits."""
    clients = list(service.server.get_clients().values())
    return (
        f"clicked px {np.round(clicked, 1).tolist()}, camera now at "
        f"{np.round(cam.position, 4).tolist()} looking at {np.round(cam.look_at, 4).tolist()} "
        f"({cam.image_width}x{cam.image_height}), {len(clients)} client(s), "
        f"{service.proposals.dropped} proposal(s) dropped"
    )
