"""The scene's measuring tool: two shift-clicks → the distance in mm, in the console.

The pick is checked against a brute-force reading of its rule; the whole path
(a viser client's shift-clicks on its websocket → the published event and
``GET /scene``) against the distance between the cloud points aimed at.
"""

from __future__ import annotations

from typing import Any

import msgspec
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import server.scene.measure as measure
from server.scene.measure import Measurer, pick_on_ray, thin
from tests.api.test_scene_proposals import camera_message, free_port, raw_viser, wait_for


def brute_pick(P: np.ndarray, o: np.ndarray, d: np.ndarray, tol: float, floor: float) -> int | None:
    """The rule read literally, one point at a time."""
    d = d / np.linalg.norm(d)
    cands = []
    for i, p in enumerate(P):
        v = p - o
        t = float(v @ d)
        perp = float(np.linalg.norm(v - t * d))
        if t > 0 and perp <= max(floor, t * np.tan(tol)) + 1e-12:
            cands.append((perp, t, i))
    if not cands:
        return None
    t0 = min(t for _, t, _ in cands)
    front = [c for c in cands if c[1] <= t0 + 3 * max(floor, t0 * np.tan(tol))]
    return min(front)[2]


coord = st.floats(-2.0, 2.0, allow_nan=False)


@settings(max_examples=150, deadline=None)
@given(
    pts=st.lists(st.tuples(coord, coord, coord), min_size=0, max_size=40),
    origin=st.tuples(coord, coord, coord),
    direction=st.tuples(coord, coord, coord).filter(lambda v: np.linalg.norm(v) > 0.1),
    tol=st.sampled_from([0.01, 0.05, 0.3]),
    floor=st.sampled_from([0.0, 0.01, 0.2]),
    chunk=st.sampled_from([3, 7, 65536]),
)
def test_pick_matches_brute_force(pts, origin, direction, tol, floor, chunk) -> None:
    P = np.array(pts, dtype=float).reshape(-1, 3)
    o, d = np.array(origin), np.array(direction)
    old = measure._CHUNK
    measure._CHUNK = chunk  # the chunked scan must not depend on the chunk size
    try:
        got = pick_on_ray(P, o, d, tol_rad=tol, min_tol_m=floor)
    finally:
        measure._CHUNK = old
    want = brute_pick(P, o, d, tol, floor)
    if got != want:
        # Only a tie within rounding may differ: the same offset from the ray.
        assert got is not None and want is not None
        dn = d / np.linalg.norm(d)

        def off(i: int) -> float:
            v = P[i] - o
            return float(np.linalg.norm(v - (v @ dn) * dn))

        assert abs(off(got) - off(want)) < 1e-9


def test_pick_takes_the_front_surface_and_misses_off_the_ray() -> None:
    # Two parallel sheets 1 m apart, seen from above: the upper one is picked.
    g = np.stack(np.meshgrid(np.arange(10) * 0.1, np.arange(10) * 0.1), axis=-1).reshape(-1, 2)
    lower = np.column_stack([g, np.zeros(len(g))])
    upper = np.column_stack([g, np.ones(len(g))])
    P = np.vstack([lower, upper])
    k = pick_on_ray(P, np.array([0.3, 0.4, 5.0]), np.array([0.0, 0.0, -1.0]))
    assert k is not None and np.allclose(P[k], [0.3, 0.4, 1.0])
    # Looking away, or beside the sheets: nothing.
    assert pick_on_ray(P, np.array([0.3, 0.4, 5.0]), np.array([0.0, 0.0, 1.0])) is None
    assert pick_on_ray(P, np.array([5.0, 5.0, 5.0]), np.array([0.0, 0.0, -1.0])) is None


def test_pick_refuses_a_degenerate_ray() -> None:
    with pytest.raises(ValueError, match="non-zero direction"):
        pick_on_ray(np.zeros((3, 3)), np.zeros(3), np.zeros(3))
    with pytest.raises(ValueError, match="finite origin"):
        pick_on_ray(np.zeros((3, 3)), np.array([np.nan, 0, 0]), np.array([0, 0, 1.0]))


def test_thin_bounds_the_points_and_drops_non_finite() -> None:
    P = np.arange(30.0).reshape(10, 3)
    P[2, 1] = np.inf
    out = thin([P, P], limit=5)
    assert len(out) <= 5 and np.all(np.isfinite(out))
    assert thin([]).shape == (0, 3)


def test_measurer_pairs_picks_per_client_and_a_new_picture_drops_first_picks() -> None:
    m = Measurer()
    m.set_points([np.array([[0.0, 0.0, 0.0], [3.0, 4.0, 0.0], [0.0, 0.0, 2.0]])])
    down = np.array([0.0, 0.0, -1.0])
    assert m.click(1, np.array([0.0, 0.0, 1.0]), down)["state"] == "first"  # (0,0,0)
    assert m.click(2, np.array([3.0, 4.0, 9.0]), down)["state"] == "first"  # another client
    r = m.click(1, np.array([3.0, 4.0, 1.0]), down)
    assert r["state"] == "measured" and r["distance_mm"] == 5000.0
    assert r["a_m"] == [0.0, 0.0, 0.0] and r["b_m"] == [3.0, 4.0, 0.0]
    assert m.public() is not None and m.public()["distance_mm"] == 5000.0
    assert m.click(1, np.array([9.0, 9.0, 1.0]), down) == {"state": "missed", "client": 1}
    # Client 2's first pick belonged to the old picture.
    m.set_points([np.array([[0.0, 0.0, 0.0], [0.0, 1.0, 0.0]])])
    assert m.click(2, np.array([0.0, 1.0, 1.0]), down)["state"] == "first"
    assert m.public()["distance_mm"] == 5000.0  # the finished one is kept
    m.clear()
    assert m.public() is None


# ----------------------------------------------------------- through the API
def shift_click(origin: list[float], direction: list[float]) -> bytes:
    """The bytes viser's browser client sends for a shift-click in the scene."""
    return msgspec.msgpack.encode(
        {
            "type": "ScenePointerMessage",
            "event_type": "click",
            "ray_origin": origin,
            "ray_direction": direction,
            "screen_pos": [[0.5, 0.5]],
            "modifier": "shift",
        }
    )


def _first_pick_seen(sapi) -> bool:
    return any(e.data.get("state") == "first" for e in sapi.services.events.recent(500))


@pytest.fixture
def sapi(make_api):
    return make_api(scene_port=free_port())


def test_two_shift_clicks_measure_between_the_cloud_points_aimed_at(sapi) -> None:
    # A flat 2 m × 1 m grid at z = 1.5 m, 5 cm spacing.
    xs, ys = np.meshgrid(np.arange(41) * 0.05, np.arange(21) * 0.05)
    pts = np.column_stack([xs.ravel(), ys.ravel(), np.full(xs.size, 1.5)])
    body = "\n".join(f"{x:.3f} {y:.3f} {z:.3f}" for x, y, z in pts).encode()
    cloud = sapi.post("/api/v1/clouds", files={"file": ("grid.xyz", body)})
    assert cloud.status_code in (200, 201), cloud.text
    cid = cloud.json()["id"]
    assert sapi.post("/api/v1/scene/show", json={"cloud_id": cid}).status_code == 200
    scene = sapi.services.scene
    assert scene.measurer.pickable == len(pts)
    events_before = sapi.services.events.recent(500)
    a, b = pts[22], pts[41 * 17 + 33]  # (1.10, 0, 1.5) and (1.65, 0.85, 1.5)
    with raw_viser(scene.port, scene.issue_ticket()) as ws:
        ws.recv(timeout=10)
        ws.send(camera_message())
        # Rays from a camera up and to the side, through each point.
        cam = np.array([0.5, -2.0, 4.0])
        ws.send(shift_click(cam.tolist(), (a - cam).tolist()))
        wait_for(lambda: _first_pick_seen(sapi), 10)
        ws.send(shift_click(cam.tolist(), (b - cam).tolist()))
        got = wait_for(lambda: sapi.get("/api/v1/scene", "viewer").json()["measurement"], 10)
    want = float(np.linalg.norm(b - a)) * 1000.0
    assert got["distance_mm"] == pytest.approx(want, abs=0.1)
    assert np.allclose(got["a_m"], a, atol=1e-4) and np.allclose(got["b_m"], b, atol=1e-4)
    published = [e.data for e in sapi.services.events.recent(500) if e not in events_before]
    states = [d["state"] for d in published if "distance_mm" in d or "point_m" in d]
    assert states == ["first", "measured"]
    handle = scene.server.scene.get_handle_by_name("/measure/label")
    assert handle is not None and handle.text == f"{want:.0f} mm"

    # A viewer may read it, not clear it; an operator clears it (markers too).
    assert sapi.delete("/api/v1/scene/measurement", "viewer").status_code == 403
    assert sapi.delete("/api/v1/scene/measurement", "operator").status_code == 204
    assert sapi.get("/api/v1/scene", "viewer").json()["measurement"] is None
    assert scene.server.scene.get_handle_by_name("/measure/label") is None


def test_a_plain_click_does_not_measure(sapi) -> None:
    xs, ys = np.meshgrid(np.arange(5) * 0.1, np.arange(5) * 0.1)
    pts = np.column_stack([xs.ravel(), ys.ravel(), np.zeros(xs.size)])
    body = "\n".join(f"{x:.3f} {y:.3f} {z:.3f}" for x, y, z in pts).encode()
    cid = sapi.post("/api/v1/clouds", files={"file": ("g.xyz", body)}).json()["id"]
    sapi.post("/api/v1/scene/show", json={"cloud_id": cid})
    scene = sapi.services.scene
    down = [0.0, 0.0, -1.0]
    plain: Any = msgspec.msgpack.decode(shift_click([0.2, 0.2, 3.0], down))
    plain["modifier"] = None
    with raw_viser(scene.port, scene.issue_ticket()) as ws:
        ws.recv(timeout=10)
        ws.send(camera_message())
        # Two plain clicks, then two shift-clicks: only the latter pair measures.
        # viser runs click callbacks on a thread pool, so the second shift-click
        # goes only once the first is seen, as a person's would.
        for _ in range(2):
            ws.send(msgspec.msgpack.encode(plain))
        ws.send(shift_click([0.0, 0.0, 3.0], down))
        wait_for(lambda: _first_pick_seen(sapi), 10)
        ws.send(shift_click([0.4, 0.3, 3.0], down))
        got = wait_for(lambda: sapi.get("/api/v1/scene", "viewer").json()["measurement"], 10)
    assert got["a_m"] == [0.0, 0.0, 0.0] and got["b_m"] == [0.4, 0.3, 0.0]
    assert got["distance_mm"] == pytest.approx(500.0, abs=0.1)
