"""What the robot's camera saw, in the recorded run: MCAP read back with the
MCAP reader, the ROS 2 bag with rosbags; a point placed in the world lands
back where it was after the exported transforms world → base → camera."""

from __future__ import annotations

import base64
import io
import json
import tempfile
import zipfile
from collections import defaultdict
from pathlib import Path
from typing import Any

import numpy as np
import yaml  # type: ignore[import-untyped]
from mcap.reader import make_reader
from rosbags.rosbag2 import Reader
from rosbags.typesys import Stores, get_typestore
from scipy.spatial.transform import Rotation

from server.captures.service import record_capture
from server.recording import captures as rec_captures
from server.recording import plan_cloud, write_recording, write_rosbag2
from server.recording.channels import iso_ns
from tests.api.test_captures import make_capture, make_execution

#: A plan's stated origin of its local world frame: a UTM-like position whose
#: digits float32 could not hold.
ORIGIN = [512345.123456789, 5401234.987654321, 187.25]


def _recorded_run(api: Any, *, base_pose: bool) -> tuple[Any, Any, list, Any]:
    """An execution with two captures (one with intensities), its plan stating
    ``world_origin_m`` and, with ``base_pose``, a ``robot_base_pose``."""
    plan, ex = make_execution(api)
    store = api.services.store
    T = np.eye(4)
    T[:3, :3] = Rotation.from_euler("xyz", [0.1, -0.2, 0.7]).as_matrix()
    T[:3, 3] = [3.0, -4.0, 0.5]
    result = dict(plan.result or {}, world_origin_m=ORIGIN)
    if base_pose:
        result["robot_base_pose"] = T.tolist()
    with store.db.transaction() as conn:  # portable SQL: SQLite and PostgreSQL
        conn.execute("UPDATE plans SET result = ? WHERE id = ?", (json.dumps(result), plan.id))
    start = iso_ns(ex.created_at) / 1e9
    caps = [make_capture(1, 400, seed=5), make_capture(2, 250, seed=5, intensity=False)]
    for k, cap in enumerate(caps):
        assert record_capture(store, ex.id, cap, received_at=start + 1.5 + k) is not None
    plan = store.get_plan(plan.id)
    assert rec_captures.world_origin(plan)[0].tolist() == ORIGIN
    exported = rec_captures.load_captures(store, ex.id, ex.robot, plan)
    return plan, store.get_execution(ex.id), caps, exported


def _matrix(translation: dict[str, float], rotation: dict[str, float]) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = Rotation.from_quat([rotation[k] for k in "xyzw"]).as_matrix()
    T[:3, 3] = [translation[k] for k in "xyz"]
    return T


def _chain(parent_of: dict[str, tuple[str, np.ndarray]], frame: str) -> np.ndarray:
    """The pose of ``frame`` in ``world`` by the exported transforms."""
    T = np.eye(4)
    while frame != "world":
        parent, Tp = parent_of[frame]
        T, frame = Tp @ T, parent
    return T


def test_captures_export_to_mcap_in_the_camera_frame_placed_by_tf(api) -> None:
    plan, ex, caps, exported = _recorded_run(api, base_pose=True)
    store = api.services.store
    audit = store.list_audit("execution", ex.id)
    buf = io.BytesIO()
    counts = write_recording(
        buf,
        ex,
        plan,
        store.ack_times(ex.id),
        store.execution_states(ex.id),
        audit,
        cloud=plan_cloud(store, plan),
        captures=exported,
    )
    assert counts["/ara/camera/points"] == 2 and counts["/tf"] == 2

    reader = make_reader(io.BytesIO(buf.getvalue()))
    summary = reader.get_summary()
    assert summary is not None
    schemas = {c.topic: summary.schemas[c.schema_id].name for c in summary.channels.values()}
    assert schemas["/ara/camera/points"] == "foxglove.PointCloud"
    assert schemas["/tf"] == "foxglove.FrameTransforms"
    meta = {m.name: m.metadata for m in reader.iter_metadata()}
    # The stated origin, float64 to the last bit.
    world = meta["world"]
    assert world["frame_id"] == "world"
    assert [float(world[f"origin_{a}_m"]) for a in "xyz"] == ORIGIN
    assert meta["captures"]["captures"] == "2" and meta["captures"]["stride"] == "1"
    assert meta["captures"]["frame_id"] == "ara/camera"
    assert "ara/base" in meta["channels"]["/tf"]

    msgs: dict[str, list[tuple[int, dict]]] = defaultdict(list)
    for _s, channel, message in reader.iter_messages(log_time_order=True):
        msgs[channel.topic].append((message.log_time, json.loads(message.data)))
    tf_at = {t: m for t, m in msgs["/tf"]}
    clouds = msgs["/ara/camera/points"]
    assert len(clouds) == 2
    for cap, (t, pc) in zip(caps, clouds, strict=True):
        rec = store_rec(store, ex.id, cap.capture_id)
        assert t == round(rec.received_at * 1e9)
        assert pc["frame_id"] == "ara/camera"
        assert pc["pose"]["position"] == {"x": 0.0, "y": 0.0, "z": 0.0}
        fields = {f["name"]: (f["offset"], f["type"]) for f in pc["fields"]}
        step = pc["point_stride"]
        raw = np.frombuffer(base64.b64decode(pc["data"]), dtype=np.uint8).reshape(-1, step)
        xyz = np.stack(
            [raw[:, fields[a][0] : fields[a][0] + 4].copy().view("<f4")[:, 0] for a in "xyz"],
            axis=1,
        )
        assert all(fields[a][1] == 7 for a in "xyz")
        if cap.intensity is not None:
            assert step == 13 and fields["intensity"] == (12, 1)
            assert np.array_equal(raw[:, 12], cap.intensity)
        else:
            assert step == 12 and "intensity" not in fields
        # Placed by /tf at the same time: world → ara/base → ara/camera.
        tfs = tf_at[t]["transforms"]
        assert [(x["parent_frame_id"], x["child_frame_id"]) for x in tfs] == [
            ("world", "ara/base"),
            ("ara/base", "ara/camera"),
        ]
        parent_of = {
            x["child_frame_id"]: (x["parent_frame_id"], _matrix(x["translation"], x["rotation"]))
            for x in tfs
        }
        T = _chain(parent_of, "ara/camera")
        placed = xyz.astype(np.float64) @ T[:3, :3].T + T[:3, 3]
        # Each point lands back where it was in the world (to 1 mm; in fact far closer).
        assert np.abs(placed - cap.world_points()).max() < 1e-3
        # The base is the plan's stated base pose.
        assert np.allclose(parent_of["ara/base"][1], np.asarray(plan.result["robot_base_pose"]))


def store_rec(store: Any, execution_id: str, capture_id: int) -> Any:
    from server.captures import CaptureStore

    return CaptureStore(store).get(execution_id, capture_id)


def test_captures_export_to_a_ros2_bag_with_their_tf(api) -> None:
    plan, ex, caps, exported = _recorded_run(api, base_pose=False)
    store = api.services.store
    data, counts = write_rosbag2(
        ex, plan, store.execution_states(ex.id), cloud=plan_cloud(store, plan), captures=exported
    )
    assert counts["/ara/camera/points"] == 2 and counts["/tf"] == 2
    typestore = get_typestore(Stores.ROS2_JAZZY)
    with tempfile.TemporaryDirectory() as tmp:
        with zipfile.ZipFile(io.BytesIO(data)) as z:
            z.extractall(tmp)
        bag = Path(tmp) / ex.id
        info = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
        custom = info["custom_data"]
        assert [float(custom[f"world_origin_{a}_m"]) for a in "xyz"] == ORIGIN
        assert custom["world_frame"] == "world"
        with Reader(bag) as reader:
            types = {c.topic: c.msgtype for c in reader.connections}
            got: dict[str, list] = defaultdict(list)
            for conn, t, blob in reader.messages():
                got[conn.topic].append((t, typestore.deserialize_cdr(blob, conn.msgtype)))
    assert types["/ara/camera/points"] == "sensor_msgs/msg/PointCloud2"
    assert types["/tf"] == "tf2_msgs/msg/TFMessage"
    tf_at = {t: m for t, m in got["/tf"]}
    for cap, (t, pc) in zip(caps, got["/ara/camera/points"], strict=True):
        assert pc.header.frame_id == "ara/camera"
        assert pc.header.stamp.sec * 10**9 + pc.header.stamp.nanosec == t
        fields = {f.name: (f.offset, f.datatype) for f in pc.fields}
        raw = np.frombuffer(pc.data.tobytes(), np.uint8).reshape(pc.height * pc.width, -1)
        assert raw.shape[1] == pc.point_step == (13 if cap.intensity is not None else 12)
        xyz = np.stack(
            [raw[:, fields[a][0] : fields[a][0] + 4].copy().view("<f4")[:, 0] for a in "xyz"],
            axis=1,
        )
        if cap.intensity is not None:
            assert fields["intensity"] == (12, 2) and np.array_equal(raw[:, 12], cap.intensity)
        parent_of = {}
        for x in tf_at[t].transforms:
            tr, ro = x.transform.translation, x.transform.rotation
            parent_of[x.child_frame_id] = (
                x.header.frame_id,
                _matrix({"x": tr.x, "y": tr.y, "z": tr.z}, {"x": ro.x, "y": ro.y, "z": ro.z,
                                                           "w": ro.w}),
            )  # fmt: skip
        assert set(parent_of) == {"ara/base", "ara/camera"}
        assert np.allclose(parent_of["ara/base"][1], np.eye(4))  # no base pose stated
        T = _chain(parent_of, "ara/camera")
        placed = xyz.astype(np.float64) @ T[:3, :3].T + T[:3, 3]
        assert np.abs(placed - cap.world_points()).max() < 1e-3


def test_an_export_without_captures_is_unchanged_but_states_the_origin(api) -> None:
    plan, ex = make_execution(api)
    store = api.services.store
    buf = io.BytesIO()
    none = rec_captures.load_captures(store, ex.id, ex.robot, plan)
    counts = write_recording(buf, ex, plan, [], [], [], captures=none)
    assert "/ara/camera/points" not in counts and "/tf" not in counts
    meta = {m.name: m.metadata for m in make_reader(io.BytesIO(buf.getvalue())).iter_metadata()}
    assert [float(meta["world"][f"origin_{a}_m"]) for a in "xyz"] == [0.0, 0.0, 0.0]
    assert "states no world_origin_m" in meta["world"]["note"]
    assert "captures" not in meta
    _data, counts = write_rosbag2(ex, plan, [], captures=none)
    assert "/tf" not in counts


def test_exported_capture_points_are_bounded(api, monkeypatch) -> None:
    plan, ex, caps, _ = _recorded_run(api, base_pose=False)
    monkeypatch.setattr(rec_captures, "MAX_EXPORT_POINTS", 100)
    exported = rec_captures.load_captures(api.services.store, ex.id, ex.robot, plan)
    assert exported.stride == 7 and exported.stored_points == 650
    assert [len(c.points) for c in exported.captures] == [58, 36]
    assert np.array_equal(exported.captures[0].points, caps[0].points_m[::7])
    assert "every 7. point" in exported.metadata()["note"]
