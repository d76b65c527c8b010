"""Show in scene frames the content: the recorder's world
points, the view's geometry, and the scene service applying it."""

from __future__ import annotations

import socket

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import server.scene.framing as framing_module
from server.scene.framing import BoundsRecorder, framing


class _FakeScene:
    def __init__(self) -> None:
        self.calls: list[str] = []

    def add_frame(self, name: str, **kw):
        self.calls.append(name)
        return name

    def add_point_cloud(self, name: str, points, **kw):
        self.calls.append(name)
        return name

    def add_line_segments(self, name: str, points, **kw):
        self.calls.append(name)
        return name

    def add_label(self, name: str, **kw):
        raise RuntimeError("viser refused")  # the drawer sees the error, framing ignores it

    def remove_by_name(self, name: str) -> None:
        self.calls.append("rm " + name)


def test_recorder_notes_world_points_through_parent_frames() -> None:
    fake = _FakeScene()
    rec = BoundsRecorder(fake)
    c, s = np.cos(np.pi / 4), np.sin(np.pi / 4)  # 90° about z as wxyz
    rec.add_frame("/plan/base", position=(10.0, 0.0, 0.0), wxyz=(c, 0.0, 0.0, s))
    rec.add_point_cloud("/plan/base/pts", points=np.array([[1.0, 0.0, 0.0]]), colors=None)
    rec.add_line_segments("/plan/seg", np.array([[[0, 0, 0], [0, 0, 2.0]]]), position=(0, 5, 0))
    rec.add_point_cloud("/plan/far", points=np.array([[np.nan, 0, 0], [1.0, 2.0, 3.0]]))
    rec.remove_by_name("/plan")  # other calls pass through untouched
    with pytest.raises(RuntimeError):
        rec.add_label("/plan/l", text="x", position=(0, 0, 0))
    assert fake.calls == ["/plan/base", "/plan/base/pts", "/plan/seg", "/plan/far", "rm /plan"]
    pts = np.vstack(rec.points)
    np.testing.assert_allclose(pts[0], [10.0, 0.0, 0.0])  # the frame's origin
    np.testing.assert_allclose(pts[1], [10.0, 1.0, 0.0], atol=1e-12)  # rotated, then moved
    np.testing.assert_allclose(pts[2:4], [[0, 5, 0], [0, 5, 2.0]])
    np.testing.assert_allclose(pts[4:], [[1.0, 2.0, 3.0]])  # the NaN row is left out


@settings(max_examples=60, deadline=None)
@given(
    centre=st.tuples(*[st.floats(-1e5, 1e5)] * 3),
    half=st.tuples(*[st.floats(0.0, 50.0)] * 3),
    fov_deg=st.floats(20.0, 120.0),
    seed=st.integers(0, 2**16),
)
def test_the_view_holds_the_bulk_of_the_points(centre, half, fov_deg, seed) -> None:
    """Every point inside the 2–98 % box lies within the camera's cone."""
    rng = np.random.default_rng(seed)
    P = np.asarray(centre) + rng.uniform(-1, 1, (300, 3)) * np.asarray(half)
    fov = np.radians(fov_deg)
    view = framing([P], fov)
    assert view is not None
    lo, hi = np.percentile(P, 2, axis=0), np.percentile(P, 98, axis=0)
    np.testing.assert_allclose(view.look_at, (lo + hi) / 2, atol=1e-6 * (1 + np.abs(centre).max()))
    inside = P[np.all((lo <= P) & (hi >= P), axis=1)]
    axis = view.look_at - view.position
    axis /= np.linalg.norm(axis)
    d = inside - view.position
    ang = np.arccos(np.clip((d @ axis) / np.linalg.norm(d, axis=1), -1, 1))
    assert np.all(ang <= fov / 2 + 1e-9)
    assert framing([], fov) is None


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_show_plan_and_cloud_frame_the_camera(make_api) -> None:
    sapi = make_api(scene_port=_free_port())
    pid = sapi.wait(sapi.submit("demo.route")["id"])["id"]
    assert sapi.post("/api/v1/scene/show", json={"plan_id": pid}).status_code == 200
    view = sapi.get("/api/v1/scene", "viewer").json()["current"]["view"]
    nodes = np.array(list(sapi.services.store.get_plan(pid).result["nodes"].values()), float)
    lo, hi = nodes.min(axis=0), nodes.max(axis=0)
    assert np.all(np.asarray(view["look_at"]) >= lo - 0.5)
    assert np.all(np.asarray(view["look_at"]) <= hi + 0.5)
    cam = sapi.services.scene.server.initial_camera
    np.testing.assert_allclose(cam.look_at, view["look_at"], atol=1e-3)
    # A cloud far from the origin (survey-like, y ≈ 18 m) is framed where it is.
    rng = np.random.default_rng(0)
    pts = rng.uniform([4.0, 17.0, 0.0], [6.0, 19.0, 1.0], (2000, 3))
    text = "\n".join(" ".join(f"{v:.4f}" for v in p) for p in pts)
    r = sapi.post("/api/v1/clouds", files={"file": ("far.xyz", text.encode())})
    assert r.status_code in (200, 201), r.text
    cid = r.json()["id"]
    assert sapi.post("/api/v1/scene/show", json={"cloud_id": cid}).status_code == 200
    look = np.asarray(sapi.get("/api/v1/scene", "viewer").json()["current"]["view"]["look_at"])
    np.testing.assert_allclose(look, [5.0, 18.0, 0.5], atol=0.1)
    np.testing.assert_allclose(cam.look_at, look, atol=1e-3)


@settings(max_examples=40, deadline=None)
@given(angle=st.floats(0.0, np.pi), length=st.floats(3.0, 100.0), seed=st.integers(0, 2**16))
def test_a_long_structure_is_seen_broadside(angle, length, seed) -> None:
    """A girder along any horizontal direction is seen from its side (the
    camera's horizontal offset within 30° of perpendicular to it), from above."""
    rng = np.random.default_rng(seed)
    axis = np.array([np.cos(angle), np.sin(angle), 0.0])
    t = rng.uniform(-length / 2, length / 2, 2000)
    P = t[:, None] * axis + rng.normal(0, 0.1, (2000, 3))
    view = framing([P], np.radians(60))
    assert view is not None
    off = view.position - view.look_at
    horiz = off[:2] / np.linalg.norm(off[:2])
    assert abs(horiz @ axis[:2]) <= np.sin(np.radians(30)) + 1e-9
    assert off[2] > 0


def test_content_without_a_long_axis_keeps_the_usual_view() -> None:
    rng = np.random.default_rng(0)
    P = rng.uniform(-1, 1, (2000, 3))
    view = framing([P], np.radians(60))
    assert view is not None
    off = (view.position - view.look_at) / np.linalg.norm(view.position - view.look_at)
    np.testing.assert_allclose(off, framing_module._VIEW_DIR, atol=1e-9)
