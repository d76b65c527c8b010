"""Findings tied to the structure through REST: placed on an
ara.inspect member's face or an ara.navigate cluster, checked against the
plan's model, edited and withdrawn with an audit trail, photos checked by
content; a serious new finding reaches a webhook."""

from __future__ import annotations

import io
import json
import time

import numpy as np
import pytest
from PIL import Image

from tests.api.test_webhooks import receiver, register
from tests.support.waiting import wait_for


def _image(fmt: str) -> bytes:
    """A real 4 × 3 image: an upload must be one Pillow can read."""
    buf = io.BytesIO()
    Image.new("RGB", (4, 3), (180, 90, 40)).save(buf, format=fmt)
    return buf.getvalue()


PNG = _image("PNG")
JPEG = _image("JPEG")


@pytest.fixture
def fapi(make_api):
    return make_api(webhook_backoff_s=0.2)


def inspect_plan(api) -> dict:
    plan = api.wait(api.submit("ara.inspect", {"sample_seed": 2})["id"], timeout=120)
    assert plan["state"] == "planned", plan.get("error")
    return plan


def on_face(plan: dict) -> tuple[int, dict, list[float], list[list[float]]]:
    """A member, one of its faces, a point on it and a small region around it."""
    member = plan["result"]["members"][0]
    face = member["faces"][0]
    outline = np.asarray(face["outline"])
    c = outline.mean(axis=0)
    region = [list(c + 0.3 * (p - c)) for p in outline]
    return member["id"], face, list(c), region


def test_a_finding_on_a_face_is_checked_listed_edited_and_withdrawn(fapi) -> None:
    plan = inspect_plan(fapi)
    member, face, point, region = on_face(plan)
    body = {
        "plan_id": plan["id"],
        "member_id": member,
        "face_id": face["id"],
        "point_m": point,
        "region_m": region,
        "type": "corrosion",
        "condition_state": 3,
        "notes": "rust bloom at the bearing",
    }
    assert fapi.post("/api/v1/findings", "viewer", json=body).status_code == 403
    r = fapi.post("/api/v1/findings", json=body)
    assert r.status_code == 201, r.text
    f = r.json()
    assert f["condition"] == "poor" and f["created_by"].startswith("test-operator")
    assert f["point_m"] == pytest.approx(point) and not f["deleted"]

    # Bad places are refused, naming what is wrong.
    n = np.asarray(face["normal"]) / np.linalg.norm(face["normal"])
    off = list(np.asarray(point) + 0.2 * n)
    for patch, field, words in (
        ({"plan_id": "pl_nope"}, "plan_id", "no plan"),
        ({"member_id": 999}, "member_id", "no member 999"),
        ({"face_id": 99}, "face_id", "no face 99"),
        ({"point_m": off, "region_m": None}, "point_m", "off face"),
        ({"point_m": None, "region_m": None}, "point_m", "give point_m or region_m"),
        ({"cluster_id": 1}, "cluster_id", "members, not clusters"),
        ({"member_id": None}, "member_id", "names its member"),
        ({"condition_state": 5}, "condition_state", ""),
        ({"type": "rust"}, "type", ""),
        ({"colour": "red"}, "colour", ""),
    ):
        r = fapi.post("/api/v1/findings", json={**body, **patch})
        assert r.status_code == 422, (patch, r.text)
        locs = [d["loc"][-1] for d in r.json()["detail"]]
        assert field in locs and words in r.text, (patch, r.text)

    # Listed and filtered.
    other = fapi.post(
        "/api/v1/findings", json={**body, "type": "crack", "condition_state": 1, "region_m": None}
    ).json()
    ids = lambda q: [x["id"] for x in fapi.get(f"/api/v1/findings{q}", "viewer").json()]  # noqa: E731
    assert set(ids(f"?plan_id={plan['id']}")) == {f["id"], other["id"]}
    assert ids("?type=crack") == [other["id"]]
    assert ids("?min_condition_state=3") == [f["id"]]
    assert ids(f"?member_id={member + 1}") == []

    # Edited: audited old → new; a point moved off the face is refused.
    r = fapi.patch(f"/api/v1/findings/{f['id']}", json={"condition_state": 4, "notes": "worse"})
    assert r.status_code == 200 and r.json()["condition"] == "severe"
    assert fapi.patch(f"/api/v1/findings/{f['id']}", json={"point_m": off}).status_code == 422
    assert (
        fapi.patch(f"/api/v1/findings/{f['id']}", "viewer", json={"notes": "x"}).status_code == 403
    )
    got = fapi.get(f"/api/v1/findings/{f['id']}", "viewer").json()
    edits = [a for a in got["audit"] if a["action"] == "edit"]
    assert len(edits) == 1 and "condition_state: 3 → 4" in edits[0]["reason"]

    # Withdrawn, never removed: who and why, still readable, no more edits.
    assert fapi.delete(f"/api/v1/findings/{f['id']}").status_code == 422  # no reason
    r = fapi.delete(f"/api/v1/findings/{f['id']}?reason=duplicate of another finding")
    assert r.status_code == 200 and r.json()["deleted"]
    assert ids(f"?plan_id={plan['id']}") == [other["id"]]
    assert f["id"] in ids(f"?plan_id={plan['id']}&include_deleted=true")
    gone = fapi.get(f"/api/v1/findings/{f['id']}", "viewer").json()
    assert gone["deleted_reason"] == "duplicate of another finding" and gone["deleted_by"]
    assert fapi.patch(f"/api/v1/findings/{f['id']}", json={"notes": "x"}).status_code == 409
    assert fapi.get("/api/v1/findings/fd_nope", "viewer").status_code == 404


def test_photos_are_checked_by_content_and_served(fapi) -> None:
    plan = inspect_plan(fapi)
    member, _face, point, _ = on_face(plan)
    f = fapi.post(
        "/api/v1/findings",
        json={
            "plan_id": plan["id"],
            "member_id": member,
            "point_m": point,
            "type": "coating_loss",
            "condition_state": 2,
        },
    ).json()
    url = f"/api/v1/findings/{f['id']}/photos"
    r = fapi.post(url, files={"file": ("bearing.png", PNG, "image/png")})
    assert r.status_code == 201, r.text
    photo = r.json()
    assert photo["content_type"] == "image/png" and photo["size"] == len(PNG)
    # A JPEG named .png is a JPEG; a text file named .jpg is refused.
    r = fapi.post(url, files={"file": ("wrong.png", JPEG, "image/png")})
    assert r.status_code == 201 and r.json()["content_type"] == "image/jpeg"
    r = fapi.post(url, files={"file": ("notes.jpg", b"hello, not an image", "image/jpeg")})
    assert r.status_code == 415 and "JPEG, PNG or WebP" in r.text
    big = b"\xff\xd8\xff" + b"\x00" * (10 * 1024 * 1024)
    assert fapi.post(url, files={"file": ("big.jpg", big, "image/jpeg")}).status_code == 413
    assert fapi.post(url, "viewer", files={"file": ("a.png", PNG, "image/png")}).status_code == 403
    got = fapi.get(photo["url"], "viewer")
    assert got.status_code == 200 and got.content == PNG
    assert got.headers["content-type"] == "image/png"
    listed = fapi.get(f"/api/v1/findings/{f['id']}", "viewer").json()["photos"]
    assert [p["content_type"] for p in listed] == ["image/png", "image/jpeg"]
    assert fapi.get(f"/api/v1/findings/{f['id']}/photos/ph_nope", "viewer").status_code == 404


def test_on_a_navigate_plan_a_finding_names_a_cluster(fapi) -> None:
    plan = fapi.wait(fapi.submit("ara.navigate")["id"], timeout=120)
    cluster = plan["result"]["clusters"][0]
    body = {
        "plan_id": plan["id"],
        "cluster_id": cluster["id"],
        "point_m": cluster["centre"],
        "type": "loose_fastener",
        "condition_state": 2,
    }
    assert fapi.post("/api/v1/findings", json=body).status_code == 201
    r = fapi.post("/api/v1/findings", json={**body, "cluster_id": 9999})
    assert r.status_code == 422 and "no cluster 9999" in r.text
    r = fapi.post("/api/v1/findings", json={**body, "member_id": 0})
    assert r.status_code == 422 and "clusters, not members" in r.text
    demo = fapi.wait(fapi.submit("demo.route")["id"])
    r = fapi.post("/api/v1/findings", json={**body, "plan_id": demo["id"]})
    assert r.status_code == 422 and "not demo.route" in r.text


def test_a_serious_new_finding_reaches_a_webhook(fapi) -> None:
    plan = inspect_plan(fapi)
    member, _, point, _ = on_face(plan)
    body = {"plan_id": plan["id"], "member_id": member, "point_m": point, "type": "crack"}
    with receiver() as rx:
        register(fapi, rx.url, ["finding.created"])
        mild = fapi.post("/api/v1/findings", json={**body, "condition_state": 2}).json()
        severe = fapi.post("/api/v1/findings", json={**body, "condition_state": 4}).json()
        fapi.patch(f"/api/v1/findings/{mild['id']}", json={"condition_state": 3})  # an edit
        wait_for(lambda: rx.got, what="the webhook")
        time.sleep(0.5)
    assert len(rx.got) == 1
    msg = json.loads(rx.got[0][1])
    assert msg["event"] == "finding.created" and msg["data"]["id"] == severe["id"]
    assert msg["data"]["condition_state"] == 4 and msg["data"]["type"] == "crack"


def test_findings_are_drawn_on_their_plan_in_the_scene(make_api) -> None:
    """Markers coloured by condition state at each finding, labelled; a new
    finding on the plan shown appears at once, a withdrawn one goes."""
    from server.scene.service import CONDITION_RGB
    from tests.api.test_scene_proposals import free_port

    sapi = make_api(scene_port=free_port())
    plan = inspect_plan(sapi)
    member, _face, point, region = on_face(plan)
    body = {"plan_id": plan["id"], "member_id": member, "type": "corrosion"}
    a = sapi.post("/api/v1/findings", json={**body, "point_m": point, "condition_state": 4}).json()
    sapi.post("/api/v1/scene/show", json={"plan_id": plan["id"]})
    scene = sapi.services.scene
    markers = scene.server.scene.get_handle_by_name("/findings/markers")
    assert markers is not None and scene.current["findings"] == 1
    np.testing.assert_allclose(markers.batched_positions[0], point, atol=1e-3)
    assert tuple(markers.batched_colors[0]) == CONDITION_RGB[4]
    label = scene.server.scene.get_handle_by_name(f"/findings/labels/{a['id']}")
    assert label is not None and label.text == "corrosion (severe)"
    # A second one (a region elsewhere on the face: at its centroid), drawn
    # without showing the plan again.
    shift = 0.5 * (np.asarray(region[1]) - np.asarray(point))
    moved = [list(np.asarray(p) + shift) for p in region]
    sapi.post(
        "/api/v1/findings",
        json={**body, "region_m": moved, "type": "crack", "condition_state": 1},
    )
    assert scene.current["findings"] == 2
    markers = scene.server.scene.get_handle_by_name("/findings/markers")
    got = sorted(map(tuple, np.round(markers.batched_positions, 3)))
    want = sorted(map(tuple, np.round([point, np.mean(moved, axis=0)], 3)))
    np.testing.assert_allclose(got, want, atol=2e-3)
    assert np.linalg.norm(shift) > 0.05
    sapi.delete(f"/api/v1/findings/{a['id']}?reason=measured again")
    assert scene.current["findings"] == 1
    assert scene.server.scene.get_handle_by_name(f"/findings/labels/{a['id']}") is None
