"""Findings started in the scene: a Ctrl/Cmd-click on a face of
a shown ara.inspect plan proposes a finding at that point; an operator accepts
it with the finding's type and condition state; a click off every face
proposes nothing; ``POST /scene/frame`` points the camera at a finding."""

from __future__ import annotations

import time
import types
from typing import Any

import msgspec
import numpy as np
import pytest

from server.scene.finding_pick import NEAR_FACE_M, FindingPicker, point_view
from tests.api.test_findings import inspect_plan
from tests.api.test_scene_proposals import camera_message, free_port, raw_viser, wait_for


def ctrl_click(origin: Any, direction: Any, modifier: str | None = "cmd/ctrl") -> bytes:
    """The bytes viser's browser client sends for a Ctrl (or Cmd) click in the scene."""
    return msgspec.msgpack.encode(
        {
            "type": "ScenePointerMessage",
            "event_type": "click",
            "ray_origin": [float(v) for v in origin],
            "ray_direction": [float(v) for v in direction],
            "screen_pos": [[0.5, 0.5]],
            "modifier": modifier,
        }
    )


@pytest.fixture
def shown(make_api):
    """A scene with a sample ara.inspect plan shown."""
    sapi = make_api(scene_port=free_port())
    plan = inspect_plan(sapi)
    assert sapi.post("/api/v1/scene/show", json={"plan_id": plan["id"]}).status_code == 200
    return sapi, plan


def _web(plan: dict) -> tuple[int, dict, np.ndarray, np.ndarray]:
    """A face of the first member with every other face of it behind it, and
    its outward normal (a camera on that side sees this face first)."""
    member = plan["result"]["members"][0]
    centres = [np.asarray(f["outline"], float).mean(axis=0) for f in member["faces"]]
    for face, c in zip(member["faces"], centres, strict=True):
        n = np.asarray(face["normal"], float)
        n = n / np.linalg.norm(n)
        ahead = [float((o - c) @ n) for o in centres]
        for s in (1.0, -1.0):
            if all(s * a < 0.01 for a in ahead):
                return member["id"], face, c, s * n
    raise AssertionError("no outer face")


def _pending(sapi) -> list[dict]:
    return sapi.get("/api/v1/scene/proposals?state=pending", "viewer").json()


def test_a_ctrl_click_on_a_face_proposes_a_finding_that_the_operator_confirms(shown) -> None:
    sapi, plan = shown
    scene = sapi.services.scene
    assert scene.finding_picker.plan_id == plan["id"]
    member, face, c, n = _web(plan)
    # A point on the web, 0.2 m along it from its centre; the camera 0.5 m in front.
    outline = np.asarray(face["outline"], float)
    along = outline[1] - outline[0]
    target = c + 0.2 * along / np.linalg.norm(along)
    cam = target + 0.5 * n
    with raw_viser(scene.port, scene.issue_ticket()) as ws:
        ws.recv(timeout=10)
        ws.send(camera_message())
        # Off every face (looking up into the sky), and a plain click: nothing.
        ws.send(ctrl_click(cam + [0, 0, 5.0], [0.0, 0.0, 1.0]))
        ws.send(ctrl_click(cam, target - cam, modifier=None))
        time.sleep(1.5)
        assert _pending(sapi) == []
        ws.send(ctrl_click(cam, target - cam))
        (prop,) = wait_for(lambda: _pending(sapi), 10)
    assert prop["action"] == "finding" and prop["plan_id"] == plan["id"]
    assert prop["patch"]["member_id"] == member and prop["patch"]["face_id"] == face["id"]
    assert np.allclose(prop["patch"]["point_m"], target, atol=2e-3)
    marker = f"/findings/proposed/{prop['id']}"
    assert wait_for(lambda: scene.server.scene.get_handle_by_name(marker), 10) is not None

    url = f"/api/v1/scene/proposals/{prop['id']}/accept"
    fields = {"type": "corrosion", "condition_state": 3, "notes": "rust at the web"}
    assert sapi.post(url, "viewer", json=fields).status_code == 403
    r = sapi.post(url, json={**fields, "condition_state": 5})
    assert r.status_code == 422 and "condition_state" in r.text
    r = sapi.post(url)
    assert r.status_code == 422 and "type and condition_state" in r.text
    assert _pending(sapi)[0]["id"] == prop["id"]  # still pending after refusals
    r = sapi.post(url, json=fields)
    assert r.status_code == 201, r.text
    f = r.json()
    assert r.headers["location"] == f"/api/v1/findings/{f['id']}"
    assert (f["plan_id"], f["member_id"], f["face_id"]) == (plan["id"], member, face["id"])
    assert f["type"] == "corrosion" and f["condition_state"] == 3 and f["proposal_id"] == prop["id"]
    assert f["created_by"].startswith("test-operator")
    assert np.allclose(f["point_m"], prop["patch"]["point_m"])
    listed = sapi.get(f"/api/v1/findings?plan_id={plan['id']}", "viewer").json()
    assert [x["id"] for x in listed] == [f["id"]]
    decided = sapi.get(f"/api/v1/scene/proposals/{prop['id']}", "viewer").json()
    assert decided["state"] == "accepted" and decided["result_finding_id"] == f["id"]
    assert sapi.post(url, json=fields).status_code == 409
    # The scene redrew the plan's findings: one marker, the proposal's gone.
    assert scene.current["findings"] == 1
    assert scene.server.scene.get_handle_by_name(f"/findings/proposed/{prop['id']}") is None

    # Framing on it: the viewers' camera looks at the finding, from in front of its face.
    assert (
        sapi.post("/api/v1/scene/frame", "viewer", json={"finding_id": f["id"]}).status_code == 403
    )
    r = sapi.post("/api/v1/scene/frame", json={"finding_id": f["id"]})
    assert r.status_code == 200, r.text
    view = r.json()["view"]
    np.testing.assert_allclose(view["look_at"], f["point_m"], atol=1e-3)
    cam_now = scene.server.initial_camera
    np.testing.assert_allclose(cam_now.look_at, f["point_m"], atol=1e-3)
    off = np.asarray(cam_now.position) - np.asarray(f["point_m"])
    assert 0.8 < np.linalg.norm(off) < 6.0
    assert abs(off @ n) / np.linalg.norm(off) > 0.7  # in front of the face, not along it
    assert sapi.get("/api/v1/scene", "viewer").json()["current"]["view"] == view
    p = [float(v) for v in c]
    r = sapi.post("/api/v1/scene/frame", json={"point_m": p})
    assert r.status_code == 200
    np.testing.assert_allclose(scene.server.initial_camera.look_at, p, atol=1e-3)
    for body, code in (({}, 422), ({"point_m": p, "finding_id": f["id"]}, 422),
                       ({"finding_id": "fd_nope"}, 404), ({"point_m": [0, 0, "x"]}, 422)):  # fmt: skip
        assert sapi.post("/api/v1/scene/frame", json=body).status_code == code, body

    # A dismissed finding proposal's marker goes too (after the book's rate limits).
    time.sleep(scene.proposals.min_interval_s + 0.1)
    with raw_viser(scene.port, scene.issue_ticket()) as ws:
        ws.recv(timeout=10)
        ws.send(camera_message())
        ws.send(ctrl_click(cam, target - cam))
        (again,) = wait_for(lambda: _pending(sapi), 10)
    marker = f"/findings/proposed/{again['id']}"
    # the API lists a proposal as soon as it is recorded; its marker follows
    assert wait_for(lambda: scene.server.scene.get_handle_by_name(marker), 10) is not None
    assert sapi.post(f"/api/v1/scene/proposals/{again['id']}/dismiss").status_code == 200
    assert scene.server.scene.get_handle_by_name(marker) is None


def test_other_kinds_shown_pick_nothing(shown) -> None:
    sapi, plan = shown
    scene = sapi.services.scene
    pid = sapi.wait(sapi.submit("demo.route")["id"])["id"]
    sapi.post("/api/v1/scene/show", json={"plan_id": pid})
    assert not scene.finding_picker.active
    _, _, c, n = _web(plan)
    assert scene.finding_picker.pick(c + n, -n) is None


def test_a_proposal_decided_before_its_marker_is_drawn_leaves_no_marker(shown) -> None:
    """The API lists a proposal as soon as it is recorded, so an operator may
    dismiss it before the click's thread draws its marker: the marker must
    not stay behind (proposal_decided found nothing to remove)."""
    sapi, plan = shown
    scene = sapi.services.scene
    _, _, c, n = _web(plan)
    record = scene._on_propose

    def record_then_dismiss(plan_id, patch, action="revise"):
        pid = record(plan_id, patch, action=action)
        assert sapi.post(f"/api/v1/scene/proposals/{pid}/dismiss").status_code == 200
        return pid

    scene._on_propose = record_then_dismiss
    click = types.SimpleNamespace(client_id=1, ray_origin=c + n, ray_direction=-n)
    scene._on_finding_click(click)
    (done,) = sapi.get("/api/v1/scene/proposals", "viewer").json()
    assert done["state"] == "dismissed"
    assert scene.server.scene.get_handle_by_name(f"/findings/proposed/{done['id']}") is None


# ---------------------------------------------------------- the picker alone
def _plate_plan() -> Any:
    """A 2 m × 1 m plate at z = 0 (member 4, face 7) and its cloud: the
    plate's points and a few beyond its edge, 3 cm above its plane."""
    outline = [[0, 0, 0], [2, 0, 0], [2, 1, 0], [0, 1, 0]]
    result = {"members": [{"id": 4, "faces": [{"id": 7, "outline": outline, "normal": [0, 0, 2]}]}]}
    xs, ys = np.meshgrid(np.linspace(0, 2, 21), np.linspace(0, 1, 11))
    plate = np.column_stack([xs.ravel(), ys.ravel(), np.zeros(xs.size)])
    beyond = np.array([[2.05, 0.5, 0.03], [5.0, 5.0, 0.0]])
    arrays = {
        "points": np.vstack([plate, beyond]),
        "labels": np.r_[np.full(len(plate), 4), 4, -1],
    }
    return types.SimpleNamespace(
        id="pl_plate", kind="ara.inspect", result=result, array=lambda name: arrays[name]
    )


def test_the_picker_snaps_onto_the_face_hit_or_the_member_cloud_near_one() -> None:
    picker = FindingPicker()
    assert picker.pick([0, 0, 1], [0, 0, -1]) is None  # nothing shown
    picker.set_plan(_plate_plan())
    down = [0.0, 0.0, -1.0]
    got = picker.pick([0.5, 0.25, 3.0], [0.2, 0.1, -3.0])  # slanted ray to (0.7, 0.35, 0)
    assert got is not None and (got["member_id"], got["face_id"], got["via"]) == (4, 7, "face")
    np.testing.assert_allclose(got["point_m"], [0.7, 0.35, 0.0], atol=1e-4)
    # From below the plate too (a face has two sides).
    assert picker.pick([1.0, 0.5, -2.0], [0, 0, 1])["face_id"] == 7
    # Just beyond the outline, the member's cloud point there: snapped onto the plane.
    got = picker.pick([2.05, 0.5, 3.0], down)
    assert got is not None and got["via"] == "cloud"
    np.testing.assert_allclose(got["point_m"], [2.05, 0.5, 0.0], atol=1e-4)
    assert NEAR_FACE_M > 0.03
    # Unlabelled points and empty space: nothing.
    assert picker.pick([5.0, 5.0, 3.0], down) is None
    assert picker.pick([1.0, 0.5, 3.0], [0, 0, 1]) is None
    assert picker.pick([1.0, 0.5, 3.0], [0, 0, 0]) is None
    picker.set_plan(types.SimpleNamespace(id="x", kind="demo.route", result={"nodes": {}}))
    assert not picker.active and picker.pick([1.0, 0.5, 3.0], down) is None


def test_point_view_looks_at_the_point_from_in_front_of_the_face() -> None:
    fov = np.radians(60)
    v = point_view([1.0, 2.0, 3.0], fov)
    np.testing.assert_allclose(v.look_at, [1, 2, 3])
    d = np.linalg.norm(v.position - v.look_at)
    assert d == pytest.approx(1.15 * 0.8 / np.sin(fov / 2))
    for normal in ([0, 1, 0], [0, -1, 0]):
        w = point_view([0, 0, 0], fov, normal)
        off = w.position / np.linalg.norm(w.position)
        assert abs(off[1]) > 0.85  # mostly along the normal, on the usual view's side
        assert off[1] < 0 and off[2] > 0
