"""Recorded runs: an execution exported as MCAP and read back with the MCAP
reader, and as a zipped ROS 2 bag read back with rosbags."""

from __future__ import annotations

import base64
import io
import json
import math
import tempfile
import time
import zipfile
from collections import Counter, defaultdict
from pathlib import Path

import numpy as np
from mcap.reader import make_reader
from rosbags.rosbag2 import Reader
from rosbags.typesys import Stores, get_typestore
from scipy.spatial.transform import Rotation

from robots import load_robot
from server.recording import channels
from tests.api.test_dispatch import approved_demo, wait_execution


def test_a_real_run_exports_as_mcap_with_every_channel(make_api, monkeypatch) -> None:
    api = make_api(emulators=True, emulator_time_scale=10.0)
    assert api.services.dispatch.wait_connected("ara", 20)
    plan = approved_demo(api, end="c2")
    eid = api.post(f"/api/v1/plans/{plan['id']}/dispatch", json={"robot": "ara"}).json()["id"]
    wait_execution(api, eid, ("running",), timeout=30)
    time.sleep(1.0)
    assert api.post(f"/api/v1/executions/{eid}/pause").status_code == 200
    time.sleep(0.5)
    assert api.post(f"/api/v1/executions/{eid}/resume").status_code == 200
    ex = wait_execution(api, eid, ("completed",), timeout=120)

    r = api.get(f"/api/v1/executions/{eid}/recording.mcap", "viewer")
    assert r.status_code == 200, r.text
    assert r.headers["content-type"] == "application/octet-stream"
    assert f"{eid}.mcap" in r.headers["content-disposition"]

    reader = make_reader(io.BytesIO(r.content))
    summary = reader.get_summary()
    assert summary is not None
    topics = {c.id: c.topic for c in summary.channels.values()}
    # demo.route names no stored cloud: no /plan/cloud (the metadata says why).
    assert set(topics.values()) == {
        "/plan/program",
        "/commands/acknowledged",
        "/robot/state",
        "/operator",
        "/tf",
        "/robot/tool_pose",
        "/plan/path",
    }
    schemas = {summary.channels[i].topic: summary.schemas[summary.channels[i].schema_id].name
               for i in summary.channels}  # fmt: skip
    assert schemas["/operator"] == "foxglove.Log"
    assert schemas["/tf"] == "foxglove.FrameTransforms"
    assert schemas["/robot/tool_pose"] == "foxglove.PoseInFrame"
    assert schemas["/plan/path"] == "foxglove.PosesInFrame"
    meta = {m.name: m.metadata for m in reader.iter_metadata()}
    assert meta["channels"]["/plan/cloud"].startswith("absent:")
    assert "path_xyz" in meta["channels"]["/plan/path"]
    assert all(c.message_encoding == "json" for c in summary.channels.values())

    msgs: dict[str, list[tuple[int, dict]]] = defaultdict(list)
    for _schema, channel, message in reader.iter_messages():
        msgs[channel.topic].append((message.log_time, json.loads(message.data)))
    counts = Counter({t: len(v) for t, v in msgs.items()})
    # The summary's statistics say the same.
    stats = summary.statistics
    assert stats is not None
    assert {topics[i]: n for i, n in stats.channel_message_counts.items()} == dict(counts)

    program = api.get(f"/api/v1/plans/{plan['id']}").json()["program"]
    assert [m["command"] for _, m in msgs["/plan/program"]] == program
    acked = msgs["/commands/acknowledged"]
    assert [m["index"] for _, m in acked] == list(range(ex["total"]))
    assert [m["op"] for _, m in acked] == [c["op"] for c in program]
    times = [t for t, _ in acked]
    assert times == sorted(times)
    # State reports (2 Hz) while it ran, between the first and last ack roughly.
    states = msgs["/robot/state"]
    assert len(states) >= 2
    assert all(m["robot"] == "ara" and len(m["q_rad"]) == 6 for _, m in states)
    recorded = api.services.store.execution_states(eid)
    assert states == [(round(t * 1e9), {"robot": "ara", **st}) for t, st in recorded]
    # The operator's actions, as Foxglove log lines.
    lines = [m["message"] for _, m in msgs["/operator"]]
    for word in ("approve", "pause", "resume", "complete"):
        assert any(f" {word}" in line for line in lines), (word, lines)
    assert all(m["level"] in (2, 3) and "sec" in m["timestamp"] for _, m in msgs["/operator"])

    check_frames(msgs, states)
    check_path(api, plan["id"], msgs["/plan/path"])
    check_rosbag(api, eid, states, cloud=None)

    # The plan names a stored cloud (demo.route cannot: its params are fixed, so
    # the stored row is edited), thinned to a bound lowered for the test.
    cid = api.post("/api/v1/clouds", json={"sample": "demo_plane", "seed": 3}).json()["id"]
    store = api.services.store
    with store.db.transaction() as conn:
        conn.execute(
            "UPDATE plans SET params = json_set(params, '$.cloud_id', ?) WHERE id = ?",
            (cid, plan["id"]),
        )
    monkeypatch.setattr(channels, "MAX_CLOUD_POINTS", 1000)
    stored = store.cloud_points(cid)
    thinned = stored[:: math.ceil(len(stored) / 1000)].astype(np.float32)
    r = api.get(f"/api/v1/executions/{eid}/recording.mcap", "viewer")
    reader = make_reader(io.BytesIO(r.content))
    clouds = [
        (s.name, json.loads(m.data)) for s, c, m in reader.iter_messages(topics=["/plan/cloud"])
    ]
    assert len(clouds) == 1 and clouds[0][0] == "foxglove.PointCloud"
    pc = clouds[0][1]
    assert pc["frame_id"] == "world" and pc["point_stride"] == 12
    assert [(f["name"], f["offset"], f["type"]) for f in pc["fields"]] == [
        ("x", 0, 7), ("y", 4, 7), ("z", 8, 7)
    ]  # fmt: skip
    got = np.frombuffer(base64.b64decode(pc["data"]), dtype="<f4").reshape(-1, 3)
    assert len(thinned) == 1000 and np.array_equal(got, thinned)
    meta = {m.name: m.metadata for m in make_reader(io.BytesIO(r.content)).iter_metadata()}
    assert meta["cloud"] == {
        "cloud_id": cid, "stored_points": str(len(stored)), "stride": "5", "written_points": "1000"
    }  # fmt: skip
    check_rosbag(api, eid, states, cloud=thinned)

    r = api.get(f"/api/v1/executions/{eid}/recording.mcap?format=bag", "viewer")
    assert r.status_code == 422
    assert "rosbag2" in json.dumps(r.json()["detail"])
    assert api.get("/api/v1/executions/ex_nope/recording.mcap").status_code == 404
    assert api.get("/api/v1/executions/ex_nope/recording.mcap?format=rosbag2").status_code == 404


def check_frames(msgs: dict[str, list[tuple[int, dict]]], states: list) -> None:
    """/tf and /robot/tool_pose: one message per state report, at its time, the
    ARA URDF's joints at the reported q_rad (pinocchio FK of robots/)."""
    model = load_robot("ara")
    tfs, tool = msgs["/tf"], msgs["/robot/tool_pose"]
    assert [t for t, _ in tfs] == [t for t, _ in states] == [t for t, _ in tool]
    for (_, st), (_, tf), (_, tp) in zip(states, tfs, tool, strict=True):
        q = np.asarray(st["q_rad"])
        pairs = [(x["parent_frame_id"], x["child_frame_id"]) for x in tf["transforms"]]
        assert pairs[0] == ("base_link", "link1") and len(pairs) == 8
        T = model.fk(q)
        p = tp["pose"]["position"]
        assert tp["frame_id"] == "base_link"
        assert np.allclose([p["x"], p["y"], p["z"]], T[:3, 3], atol=1e-9)
        o = tp["pose"]["orientation"]
        R = Rotation.from_quat([o["x"], o["y"], o["z"], o["w"]]).as_matrix()
        assert np.allclose(R, T[:3, :3], atol=1e-9)
        # Chaining the per-joint transforms from base_link to the tip gives the same pose.
        parent = {x["child_frame_id"]: x for x in tf["transforms"]}
        chain, link = np.eye(4), "foot1_sole"
        while link != "base_link":
            x = parent[link]
            Tj = np.eye(4)
            r = x["rotation"]
            Tj[:3, :3] = Rotation.from_quat([r["x"], r["y"], r["z"], r["w"]]).as_matrix()
            Tj[:3, 3] = [x["translation"][k] for k in "xyz"]
            chain, link = Tj @ chain, x["parent_frame_id"]
        assert np.allclose(chain, T, atol=1e-9)


def check_path(api, plan_id: str, path_msgs: list[tuple[int, dict]]) -> None:
    """/plan/path: the plan's stored path_xyz, once, in the world frame."""
    raw = api.get(f"/api/v1/plans/{plan_id}/arrays/path_xyz", "viewer").content
    stored = np.load(io.BytesIO(raw))
    assert len(path_msgs) == 1
    msg = path_msgs[0][1]
    assert msg["frame_id"] == "world"
    got = [[p["position"][k] for k in "xyz"] for p in msg["poses"]]
    assert np.array_equal(np.asarray(got), stored)
    assert all(p["orientation"] == {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0} for p in msg["poses"])


def check_rosbag(api, eid: str, states: list, cloud: np.ndarray | None) -> None:
    """The same run as a zipped ROS 2 bag, read back with rosbags."""
    r = api.get(f"/api/v1/executions/{eid}/recording.mcap?format=rosbag2", "viewer")
    assert r.status_code == 200, r.text
    assert r.headers["content-type"] == "application/zip"
    assert f"{eid}.rosbag2.zip" in r.headers["content-disposition"]
    typestore = get_typestore(Stores.ROS2_JAZZY)
    with tempfile.TemporaryDirectory() as tmp:
        with zipfile.ZipFile(io.BytesIO(r.content)) as z:
            assert {Path(n).parent.name for n in z.namelist()} == {eid}
            assert f"{eid}/metadata.yaml" in z.namelist()
            z.extractall(tmp)
        with Reader(Path(tmp) / eid) as reader:
            types = {c.topic: c.msgtype for c in reader.connections}
            got: dict[str, list] = defaultdict(list)
            for conn, t, data in reader.messages():
                got[conn.topic].append((t, typestore.deserialize_cdr(data, conn.msgtype)))
    expected = {
        "/joint_states": "sensor_msgs/msg/JointState",
        "/robot/tool_pose": "geometry_msgs/msg/PoseStamped",
        "/plan/path": "nav_msgs/msg/Path",
    }
    if cloud is not None:
        expected["/plan/cloud"] = "sensor_msgs/msg/PointCloud2"
    assert types == expected
    js = got["/joint_states"]
    assert [t for t, _ in js] == [t for t, _ in states]
    for (_, st), (t, m) in zip(states, js, strict=True):
        assert m.name == [f"joint{i}" for i in range(1, 7)]
        assert np.array_equal(m.position, st["q_rad"])
        assert m.header.stamp.sec * 10**9 + m.header.stamp.nanosec == t
    assert len(got["/robot/tool_pose"]) == len(states)
    ((_, path),) = got["/plan/path"]
    assert path.header.frame_id == "world" and len(path.poses) >= 2
    if cloud is not None:
        ((_, pc),) = got["/plan/cloud"]
        assert pc.width == len(cloud) and pc.height == 1 and pc.point_step == 12
        assert [(f.name, f.offset, f.datatype) for f in pc.fields] == [
            ("x", 0, 7), ("y", 4, 7), ("z", 8, 7)
        ]  # fmt: skip
        assert np.array_equal(np.frombuffer(pc.data.tobytes(), "<f4").reshape(-1, 3), cloud)


def test_clouds_are_thinned_to_the_bound() -> None:
    pts = np.random.default_rng(0).normal(size=(450_001, 3))
    pts[7] = np.nan
    c = channels.thin_cloud(pts, "cl_x")
    assert c.stored_points == 450_000 and c.stride == 3
    assert c.points is not None and len(c.points) == 150_000 <= channels.MAX_CLOUD_POINTS
    assert np.array_equal(c.points, np.delete(pts, 7, axis=0)[::3].astype(np.float32))


def test_robot_frames_place_only_the_reported_joints() -> None:
    """CMBOT may report its 7 arm joints of the URDF's 12: the arm's joints and
    every fixed joint are placed, the unreported climbing joints are left out."""
    model = load_robot("cmbot")
    frames = channels.RobotFrames("cmbot")
    q = np.linspace(-0.3, 0.3, model.dof)
    arm = frames.at(list(q))
    every = frames.at([0.1] * 12)
    assert arm is not None and every is not None
    assert len(every.transforms) == len(frames.joints) == len(arm.transforms) + 5
    assert frames.base == "arm_base" and frames.tip == "tool"
    assert np.allclose(arm.tip_pose, model.fk(q), atol=1e-9)
    assert frames.at([0.0] * 3) is None and frames.at([float("nan")] * 7) is None
    assert channels.robot_frames("nope")[0] is None
