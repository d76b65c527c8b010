"""What the robot's camera saw: captures fed in where the link service gets
them (the dispatch engine's link-event hook), stored with their execution
within its bounds, listed and served over REST, drawn in the scene and its
replay; and the world file a built-in ARA emulator's camera sees."""

from __future__ import annotations

import dataclasses
import json
import os
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from robots.protocol.capture import SensorCapture
from server.captures import CaptureStore, capture_limits
from server.captures.service import REFUSED_ACTION, CaptureRecorder, record_capture
from server.captures.world import MAX_WORLD_POINTS, plan_scan, world_path
from server.diskspace import DiskGauge
from server.dispatch import DispatchEngine
from server.recording.channels import iso_ns
from server.settings import Settings
from server.store import Store
from tests.api.test_dispatch import approved_demo, wait_execution
from tests.api.test_scene_proposals import free_port

RUN_ID = 424242


class Sink:
    """Where the engine publishes (in the link service: the channel to the web server)."""

    def __init__(self) -> None:
        self.events: list[tuple[str, dict[str, Any]]] = []
        self._lock = threading.Lock()

    def publish(self, type_: str, data: dict[str, Any]) -> None:
        json.dumps(data, allow_nan=False)  # what crosses the channel is plain JSON
        with self._lock:
            self.events.append((type_, data))


try:  # the link's event of a reassembled capture
    from robots.adapters.link import CaptureReceived as _LinkCaptureReceived

    def CaptureReceived(capture: SensorCapture) -> Any:
        return _LinkCaptureReceived(capture, 1)

except ImportError:  # a link without captures: the engine takes any event with one

    @dataclasses.dataclass(frozen=True)
    class _Event:
        capture: SensorCapture
        session: int = 1

    def CaptureReceived(capture: SensorCapture) -> Any:
        return _Event(capture)


def make_capture(
    capture_id: int,
    n: int = 500,
    *,
    seed: int = 0,
    run_id: int = RUN_ID,
    command_index: int = 3,
    intensity: bool = True,
    complete: bool = True,
    position: tuple[float, float, float] | None = None,
) -> SensorCapture:
    rng = np.random.default_rng(seed + capture_id)
    pts = rng.uniform([-1.5, -1.0, 0.5], [1.5, 1.0, 6.0], size=(n, 3)).astype(np.float32)
    pos = np.asarray(position if position is not None else rng.uniform(-20, 20, 3), np.float64)
    rot = Rotation.random(random_state=int(seed + capture_id)).as_matrix()
    inten = rng.integers(0, 256, n).astype(np.uint8) if intensity else None
    return SensorCapture(
        capture_id=capture_id,
        run_id=run_id,
        command_index=command_index,
        t_s=12.5 + capture_id,
        camera_position_m=pos,
        camera_rotation=rot,
        points_m=pts,
        intensity=inten,
        complete=complete,
        meta={"exposure_s": 0.01},
    )


def make_execution(api: Any, robot: str = "ara", run_id: int = RUN_ID) -> tuple[Any, Any]:
    """An approved demo plan and an execution of it on ``robot`` (no robot needed)."""
    plan = approved_demo(api, end="b1")
    store = api.services.store
    ex = store.create_execution(plan["id"], robot, len(plan["program"]), "test", run_id=run_id)
    return store.get_plan(plan["id"]), ex


def link_service_engine(api: Any) -> tuple[DispatchEngine, Sink, Store]:
    """A dispatch engine as the link service runs it: a store of its own on the
    same data directory (another process in production), links not opened."""
    settings: Settings = api.services.settings
    store = Store(settings.data, database_url=settings.database_url)
    sink = Sink()
    return DispatchEngine(store, sink, settings), sink, store


def test_a_capture_fed_at_the_link_service_is_stored_listed_and_served(api) -> None:
    plan, ex = make_execution(api)
    engine, sink, lstore = link_service_engine(api)
    start = iso_ns(ex.created_at) / 1e9
    caps = [make_capture(7, 1200), make_capture(8, 300, intensity=False, complete=False)]
    try:
        engine._on_link_event("ara", CaptureReceived(caps[0]))  # the one-line hook
        engine._on_link_event("ara", caps[1])  # or the capture itself as the event
        # A capture of a run no execution has is dropped, nothing stored.
        engine._on_link_event("ara", CaptureReceived(make_capture(9, run_id=RUN_ID + 1)))
        assert engine.captures.drain()
    finally:
        engine.captures.close()
        lstore.close()
    assert engine.captures.recorded == 2 and engine.captures.dropped == 1
    # Only a small event crossed to the web server; the points went to the store.
    assert [(t, d["capture_id"], d["n_points"]) for t, d in sink.events] == [
        ("capture", 7, 1200),
        ("capture", 8, 300),
    ]
    assert all(d["execution_id"] == ex.id and d["plan_id"] == plan.id for _, d in sink.events)

    r = api.get(f"/api/v1/executions/{ex.id}/captures", "viewer")
    assert r.status_code == 200, r.text
    listed = r.json()
    assert listed["execution_id"] == ex.id and listed["frame_id"] == "world"
    assert listed["totals"] == {"captures": 2, "points": 1500}
    assert listed["limits"]["captures"] == capture_limits().capture_max_per_execution
    got = {c["capture_id"]: c for c in listed["captures"]}
    assert list(got) == [7, 8]
    for cap in caps:
        c = got[cap.capture_id]
        assert c["command_index"] == cap.command_index and c["t_robot_s"] == cap.t_s
        assert c["n_points"] == len(cap.points_m) and c["complete"] is cap.complete
        assert c["has_intensity"] is (cap.intensity is not None)
        # The pose reads back bit for bit (float64 through JSON).
        assert c["pose"]["position_m"] == cap.camera_position_m.tolist()
        assert c["pose"]["rotation"] == cap.camera_rotation.tolist()
        assert c["t_s"] == pytest.approx(c["received_at"] - start)
        assert c["t_s"] >= 0 and c["url"].endswith(f"/captures/{cap.capture_id}")

    one = api.get(f"/api/v1/executions/{ex.id}/captures/7", "viewer").json()
    assert one["frame_id"] == "world" and one["stride"] == 1 and one["returned_points"] == 1200
    world = caps[0].world_points()
    assert np.abs(np.asarray(one["points_m"]) - world).max() < 1e-5
    assert caps[0].intensity is not None and one["intensity"] == caps[0].intensity.tolist()
    assert api.get(f"/api/v1/executions/{ex.id}/captures/8").json()["intensity"] is None
    thin = api.get(f"/api/v1/executions/{ex.id}/captures/7?max_points=500").json()
    assert thin["stride"] == 3 and thin["returned_points"] == 400
    assert np.abs(np.asarray(thin["points_m"]) - world[::3]).max() < 1e-5
    assert api.get(f"/api/v1/executions/{ex.id}/captures/7?max_points=0").status_code == 422
    assert api.get(f"/api/v1/executions/{ex.id}/captures/7?max_points=10**9").status_code == 422

    # Not found, unauthenticated.
    assert api.get(f"/api/v1/executions/{ex.id}/captures/99").status_code == 404
    assert api.get("/api/v1/executions/ex_nope/captures").status_code == 404
    assert api.get("/api/v1/executions/ex_nope/captures/7").status_code == 404
    assert api.client.get(f"/api/v1/executions/{ex.id}/captures").status_code == 401

    # The same capture resent changes nothing; the incomplete one is replaced
    # by its complete resend.
    store = api.services.store
    rec = record_capture(store, ex.id, make_capture(7, 10))
    assert rec is not None and rec.n_points == 1200
    full = dataclasses.replace(caps[1], complete=True, points_m=caps[1].points_m[:250])
    rec = record_capture(store, ex.id, full)
    assert rec is not None and rec.complete and rec.n_points == 250
    assert CaptureStore(store).totals(ex.id) == (2, 1450)


def test_past_its_bounds_a_capture_is_refused_and_the_execution_says_why(api) -> None:
    _plan, ex = make_execution(api)
    store = api.services.store
    sink = Sink()
    limits = capture_limits(capture_max_per_execution=2, capture_max_points_per_execution=900)
    recorder = CaptureRecorder(store, sink, limits=limits)
    try:
        for cid, n in ((1, 400), (2, 400), (3, 10), (4, 10)):
            recorder.submit("ara", make_capture(cid, n))
        assert recorder.drain()
    finally:
        recorder.close()
    assert CaptureStore(store).totals(ex.id) == (2, 800)
    refused = [d for _, d in sink.events if d.get("refused")]
    assert [(d["capture_id"], d["refused"]) for d in refused] == [(3, "limit"), (4, "limit")]
    assert "already holds 2 captures" in refused[0]["reason"]
    # Recorded on the execution once, with the reason and the setting to change.
    audit = api.get(f"/api/v1/executions/{ex.id}").json()["audit"]
    notes = [a for a in audit if a["action"] == REFUSED_ACTION]
    assert len(notes) == 1 and "STEELPATH_CAPTURE_MAX_PER_EXECUTION" in notes[0]["reason"]
    # Nothing else changed: the execution is as it was.
    assert api.get(f"/api/v1/executions/{ex.id}").json()["state"] == ex.state

    # The points bound, and a capture larger than one capture may be.
    big = capture_limits(capture_max_points_per_execution=900, capture_max_points=600)
    assert record_capture(store, ex.id, make_capture(5, 200), limits=big) is None
    assert record_capture(store, ex.id, make_capture(6, 700), limits=big) is None
    reasons = [
        a["reason"]
        for a in api.get(f"/api/v1/executions/{ex.id}").json()["audit"]
        if a["action"] == REFUSED_ACTION
    ]
    assert len(reasons) == 1  # the same reason ("limit") is recorded once
    assert CaptureStore(store).totals(ex.id) == (2, 800)


def test_a_full_disk_refuses_a_capture_and_leaves_no_file(api) -> None:
    _plan, ex = make_execution(api)
    store = api.services.store
    full = DiskGauge(store.data_dir, reserve_bytes=2**62)  # no volume has that much free
    sink = Sink()
    assert record_capture(store, ex.id, make_capture(1), gauge=full, events=sink) is None
    assert sink.events[0][1]["refused"] == "disk"
    assert "disk is full" in sink.events[0][1]["reason"]
    audit = api.get(f"/api/v1/executions/{ex.id}").json()["audit"]
    assert any(a["action"] == REFUSED_ACTION and "[disk]" in a["reason"] for a in audit)
    files = list((store.data_dir / "captures").rglob("*"))
    assert [f for f in files if f.is_file()] == []
    assert api.get(f"/api/v1/executions/{ex.id}/captures").json()["captures"] == []


def test_malformed_captures_are_refused(api) -> None:
    _plan, ex = make_execution(api)
    store = api.services.store
    cap = make_capture(1)
    bad_rot = dataclasses.replace(cap, camera_rotation=np.eye(3) * 2)
    bad_pts = dataclasses.replace(cap, points_m=np.zeros((5, 2), np.float32))
    for bad in (bad_rot, bad_pts):
        assert record_capture(store, ex.id, bad) is None
    # Non-finite points are dropped, the rest kept; an intensity of the wrong
    # length is dropped, the points kept.
    pts = cap.points_m.copy()
    pts[3] = np.nan
    odd = dataclasses.replace(cap, points_m=pts, intensity=np.zeros(3, np.uint8))
    rec = record_capture(store, ex.id, odd)
    assert rec is not None and rec.n_points == len(pts) - 1 and rec.intensity_file is None


def test_captures_are_drawn_live_and_scrubbed_in_the_replay(make_api) -> None:
    api = make_api(scene_port=free_port())
    plan, ex = make_execution(api)
    store = api.services.store
    start = iso_ns(ex.created_at) / 1e9
    record_capture(store, ex.id, make_capture(1, 200), received_at=start + 1.0)
    record_capture(store, ex.id, make_capture(2, 200, intensity=False), received_at=start + 3.0)
    for k in range(6):  # recorded state reports, so that the replay has joints
        store.record_execution_state(ex.id, start + k, {"q_rad": [0.1 * k] * 6})

    r = api.post("/api/v1/scene/captures", json={"execution_id": ex.id})
    assert r.status_code == 200, r.text
    scene = api.services.scene
    assert scene.current["plan_id"] == plan.id
    assert [s["capture_id"] for s in r.json()["shown"]] == [1, 2]
    node = scene.server.scene.get_handle_by_name("/plan/captures/c2")
    assert node is not None
    pose = store_pose(store, ex.id, 2)
    np.testing.assert_allclose(node.position, pose[:3, 3], atol=1e-5)
    pc = scene.server.scene.get_handle_by_name("/plan/captures/c2/points")
    assert pc is not None and len(pc.points) == 200
    shown = api.get("/api/v1/scene", "viewer").json()["current"]["captures"]
    assert shown["execution_id"] == ex.id
    before = api.post("/api/v1/scene/captures", json={"execution_id": ex.id, "up_to_s": 2.0})
    assert [s["capture_id"] for s in before.json()["shown"]] == [1]
    assert scene.server.scene.get_handle_by_name("/plan/captures/c2") is None

    # A new capture of the run is drawn when its event arrives (the link
    # service's "capture" event, published on the web server's bus).
    rec = record_capture(store, ex.id, make_capture(3, 50), received_at=start + 4.0)
    assert rec is not None
    api.services.events.publish(
        "capture", {"execution_id": ex.id, "plan_id": plan.id, "capture_id": 3}
    )
    scene._capture_follower.drain()
    assert scene.server.scene.get_handle_by_name("/plan/captures/c3") is not None

    # The replay's timeline lists them; scrubbing shows the latest by then.
    tl = api.get(f"/api/v1/executions/{ex.id}/replay", "viewer").json()
    assert [(c["capture_id"], round(c["t_s"], 6)) for c in tl["captures"]] == [
        (1, 1.0),
        (2, 3.0),
        (3, 4.0),
    ]
    for t, want in ((0.5, None), (1.0, 1), (2.9, 1), (3.5, 2), (99.0, 3)):
        out = api.post("/api/v1/scene/replay", json={"execution_id": ex.id, "t_s": t}).json()
        got = out["capture"]["capture_id"] if out["capture"] else None
        assert got == want, (t, out["capture"])
        drawn = [f"/plan/captures/c{i}" for i in (1, 2, 3)]
        present = [n for n in drawn if scene.server.scene.get_handle_by_name(n) is not None]
        assert present == ([] if want is None else [f"/plan/captures/c{want}"])
    # While a replay scrubs, a live capture is not drawn over it.
    api.services.events.publish(
        "capture", {"execution_id": ex.id, "plan_id": plan.id, "capture_id": 1}
    )
    scene._capture_follower.drain()
    assert scene.server.scene.get_handle_by_name("/plan/captures/c1") is None
    assert api.delete("/api/v1/scene/replay").status_code == 204
    assert scene.server.scene.get_handle_by_name("/plan/captures/c3") is None

    assert api.delete("/api/v1/scene/captures").status_code == 204
    assert api.post("/api/v1/scene/captures", "viewer", json={"execution_id": ex.id}
                    ).status_code == 403  # fmt: skip
    assert api.post("/api/v1/scene/captures", json={"execution_id": "ex_nope"}).status_code == 404


def test_no_scene_is_a_409(api) -> None:
    r = api.post("/api/v1/scene/captures", json={"execution_id": "ex_x"})
    assert r.status_code == 409 and "not running" in r.json()["detail"]


def store_pose(store: Store, execution_id: str, capture_id: int) -> np.ndarray:
    return CaptureStore(store).get(execution_id, capture_id).camera_pose


def test_dispatch_to_the_built_in_ara_emulator_writes_its_world(make_api) -> None:
    api = make_api(emulators=True, emulator_time_scale=40.0)
    assert api.services.dispatch.wait_connected("ara", 20)
    data = Path(api.services.settings.data)
    path = world_path(data, "ara")
    from server.linkservice.emulators import emulator_takes_world

    if emulator_takes_world():  # the ARA emulator was started with it
        cmdline = Path(f"/proc/{api.services.emulators['ara'].pid}/cmdline").read_bytes()
        assert cmdline.split(b"\0")[-3:-1] == [b"--world", os.fsencode(path)]
        assert path.exists()

    # The plan names a stored cloud (demo.route's params cannot: the row is edited).
    cid = api.post("/api/v1/clouds", json={"sample": "demo_plane", "seed": 3}).json()["id"]
    plan = approved_demo(api, end="b1")
    store = api.services.store
    with store.db.transaction() as conn:
        conn.execute(
            "UPDATE plans SET params = json_set(params, '$.cloud_id', ?) WHERE id = ?",
            (cid, plan["id"]),
        )
    r = api.post(f"/api/v1/plans/{plan['id']}/dispatch", json={"robot": "ara"})
    assert r.status_code == 201, r.text
    with np.load(path) as world:
        assert set(world.files) == {"points"}
        pts = world["points"]
    assert pts.dtype == np.float32 and pts.shape[1] == 3
    assert np.array_equal(pts, store.cloud_points(cid).astype(np.float32))
    wait_execution(api, r.json()["id"], ("completed",), timeout=120)

    # A plan without a scan leaves the emulator nothing to see (not the last plan's).
    plan = approved_demo(api, end="b1")
    r = api.post(f"/api/v1/plans/{plan['id']}/dispatch", json={"robot": "ara"})
    assert r.status_code == 201, r.text
    with np.load(path) as world:
        assert world["points"].shape == (0, 3)
    wait_execution(api, r.json()["id"], ("completed",), timeout=120)
    # Other robots' emulators take no world.
    assert not world_path(data, "cmbot").exists()


def test_a_plans_points_array_comes_before_its_cloud(api, monkeypatch) -> None:
    plan, _ex = make_execution(api)
    rng = np.random.default_rng(1)
    pts = rng.normal(size=(50, 3))
    pts[4] = np.nan
    inten = np.arange(50, dtype=np.uint8)
    arrays = {"points": pts, "intensity": inten}
    with_points = dataclasses.replace(
        plan,
        arrays={"points": "p.npy", "intensity": "i.npy"},
        params={**plan.params, "cloud_id": "cl_unused"},
        _loader=lambda rel: arrays["points" if rel == "p.npy" else "intensity"],
    )
    got, got_i, source = plan_scan(api.services.store, with_points)
    assert "stored array 'points'" in source
    assert np.array_equal(got, np.delete(pts, 4, axis=0).astype(np.float32))
    assert got_i is not None and np.array_equal(got_i, np.delete(inten, 4))
    # Thinned above the bound.
    monkeypatch.setattr("server.captures.world.MAX_WORLD_POINTS", 10)
    got, got_i, source = plan_scan(api.services.store, with_points)
    assert len(got) == 10 and "every 5. point" in source and MAX_WORLD_POINTS > 10
    # A cloud no longer stored: no scan, said so.
    gone = dataclasses.replace(plan, params={**plan.params, "cloud_id": "cl_gone"})
    got, got_i, source = plan_scan(api.services.store, gone)
    assert got.shape == (0, 3) and "no longer stored" in source


def test_a_capture_command_run_on_the_ara_emulator_comes_back_stored(make_api) -> None:
    """End to end: a program with ``capture`` commands dispatched to the built-in
    ARA emulator, whose camera sees the plan's scan (the world file written at
    dispatch); each capture comes back through the link service into the store."""
    api = make_api(emulators=True, emulator_time_scale=40.0)
    assert api.services.dispatch.wait_connected("ara", 20)
    from server.linkservice.emulators import emulator_takes_world

    if not emulator_takes_world():
        pytest.skip("the ARA emulator takes no --world")
    # The scan: a sphere of points 1.5 m around the base, whichever way the camera looks.
    rng = np.random.default_rng(3)
    d = rng.normal(size=(200_000, 3))
    sphere = 1.5 * d / np.linalg.norm(d, axis=1, keepdims=True)
    store = api.services.store
    cloud = store.add_cloud("sphere", "test", sphere, 0, "test")
    plan = approved_demo(api, end="b1")
    program = [
        {"op": "base_pose", "position_m": [0.0, 0.0, 0.0], "rpy_rad": [0.0, 0.0, 0.0]},
        {"op": "capture"},
        {"op": "base_pose", "position_m": [0.0, 0.0, 0.0], "rpy_rad": [0.0, 0.0, 1.5]},
        {"op": "capture"},
    ] + plan["program"]
    with store.db.transaction() as conn:
        conn.execute(
            "UPDATE plans SET params = json_set(params, '$.cloud_id', ?), program = ? WHERE id = ?",
            (cloud.id, json.dumps(program), plan["id"]),
        )
    r = api.post(f"/api/v1/plans/{plan['id']}/dispatch", json={"robot": "ara"})
    assert r.status_code == 201, r.text
    ex = wait_execution(api, r.json()["id"], ("completed",), timeout=120)
    # Stored by the link service's capture recorder (its own thread): soon after.
    deadline = time.monotonic() + 10
    while True:
        listed = api.get(f"/api/v1/executions/{ex['id']}/captures", "viewer").json()
        if len(listed["captures"]) >= 2 or time.monotonic() > deadline:
            break
        time.sleep(0.05)
    caps = listed["captures"]
    assert [c["command_index"] for c in caps] == [1, 3]
    assert all(c["run_id"] == ex["run_id"] for c in caps)
    assert all(c["n_points"] > 0 and c["complete"] for c in caps), caps
    # The two views differ by the base's yaw; each lands on the sphere in the world.
    for c in caps:
        one = api.get(f"/api/v1/executions/{ex['id']}/captures/{c['capture_id']}").json()
        radius = np.linalg.norm(np.asarray(one["points_m"]), axis=1)
        assert abs(float(np.median(radius)) - 1.5) < 0.02, np.median(radius)
    r0, r1 = (np.asarray(c["pose"]["rotation"]) for c in caps)
    assert not np.allclose(r0, r1, atol=1e-3)
    # The link service announced them to the web server (the console's event stream).
    seen = [e.data for e in api.services.events.recent(500) if e.type == "capture"]
    assert sorted(d["capture_id"] for d in seen if d["execution_id"] == ex["id"]) == [
        c["capture_id"] for c in caps
    ]
