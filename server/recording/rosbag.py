"""A run as a ROS 2 bag, so a ROS lab replays it with its own tools.

Written with ``rosbags`` (pure Python, no ROS install) as a rosbag2 of
metadata version 8 with SQLite 3 storage (``.db3``), CDR-serialised with the
ROS 2 Jazzy typestore, and returned zipped (a rosbag2 is a directory: the zip
holds ``<execution id>/metadata.yaml`` and ``<execution id>/<execution id>.db3``).
The same stored data as the MCAP export (:mod:`server.recording.channels`):

* ``/joint_states`` (``sensor_msgs/msg/JointState``): each state report's
  ``q_rad`` with the URDF joint names (``robot_state_publisher`` turns it
  into ``/tf``); a report of a joint count the URDF does not match is left out;
* ``/robot/tool_pose`` (``geometry_msgs/msg/PoseStamped``): per report, the
  pose of the robot model's chain tip in its chain base link (pinocchio FK);
* ``/plan/path`` (``nav_msgs/msg/Path``, frame ``world``): the planned path,
  one message at the run's start (positions, identity orientation);
* ``/plan/cloud`` (``sensor_msgs/msg/PointCloud2``, frame ``world``, float32
  x y z): the plan's stored cloud thinned to ≤ 200 000 points, one message;
* ``/<robot>/camera/points`` (``sensor_msgs/msg/PointCloud2``, frame
  ``<robot>/camera``, float32 x y z and a uint8 ``intensity`` when it has
  one): what the robot's camera saw, one message per capture, and on ``/tf``
  (``tf2_msgs/msg/TFMessage``) at the same stamp ``world → <robot>/base →
  <robot>/camera`` (:mod:`server.recording.captures`).

Every position is in the plan's local ``world`` frame; the bag's
``custom_data`` (``metadata.yaml``) states its origin (``world_origin_x_m``…,
float64 as ``repr``).  A topic with no message (a kind without a path, a plan without a stored cloud)
is not in the bag.  Stamps are the recorded Unix times.
"""

from __future__ import annotations

import io
import tempfile
import zipfile
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from server.recording.captures import (
    ExportCapture,
    ExportCaptures,
    camera_frame,
    camera_topic,
    cloud_fields,
    origin_metadata,
    packed,
    transforms,
)
from server.recording.channels import (
    WORLD_FRAME,
    PlanCloud,
    iso_ns,
    planned_path,
    quaternion,
    robot_frames,
    stamp,
)
from server.store.records import ExecutionRecord, PlanRecord

#: Topic → ROS 2 message type.
ROSBAG_TOPICS: dict[str, str] = {
    "/joint_states": "sensor_msgs/msg/JointState",
    "/robot/tool_pose": "geometry_msgs/msg/PoseStamped",
    "/plan/path": "nav_msgs/msg/Path",
    "/plan/cloud": "sensor_msgs/msg/PointCloud2",
}
#: Types of the capture topics (``/<robot>/camera/points`` and ``/tf``).
POINT_CLOUD2 = "sensor_msgs/msg/PointCloud2"
TF_MESSAGE = "tf2_msgs/msg/TFMessage"

__all__ = ["ROSBAG_TOPICS", "write_rosbag2"]


class _Msgs:
    """Message constructors of one typestore."""

    def __init__(self) -> None:
        from rosbags.typesys import Stores, get_typestore

        self.store = get_typestore(Stores.ROS2_JAZZY)
        self.t = self.store.types

    def header(self, ns: int, frame: str) -> Any:
        sec, nsec = stamp(ns)
        return self.t["std_msgs/msg/Header"](
            stamp=self.t["builtin_interfaces/msg/Time"](sec=sec, nanosec=nsec), frame_id=frame
        )

    def pose(self, T: np.ndarray) -> Any:
        x, y, z, w = quaternion(T[:3, :3])
        p = [float(v) for v in T[:3, 3]]
        return self.t["geometry_msgs/msg/Pose"](
            position=self.t["geometry_msgs/msg/Point"](x=p[0], y=p[1], z=p[2]),
            orientation=self.t["geometry_msgs/msg/Quaternion"](x=x, y=y, z=z, w=w),
        )

    def pose_stamped(self, ns: int, frame: str, T: np.ndarray) -> Any:
        return self.t["geometry_msgs/msg/PoseStamped"](
            header=self.header(ns, frame), pose=self.pose(T)
        )

    def transform(self, ns: int, parent: str, child: str, T: np.ndarray) -> Any:
        x, y, z, w = quaternion(T[:3, :3])
        p = [float(v) for v in T[:3, 3]]
        return self.t["geometry_msgs/msg/TransformStamped"](
            header=self.header(ns, parent),
            child_frame_id=child,
            transform=self.t["geometry_msgs/msg/Transform"](
                translation=self.t["geometry_msgs/msg/Vector3"](x=p[0], y=p[1], z=p[2]),
                rotation=self.t["geometry_msgs/msg/Quaternion"](x=x, y=y, z=z, w=w),
            ),
        )

    def capture(self, ns: int, frame: str, c: ExportCapture) -> Any:
        field = self.t["sensor_msgs/msg/PointField"]
        fields, step = cloud_fields(c.intensity is not None)
        kinds = {"f4": 7, "u1": 2}  # PointField FLOAT32, UINT8
        return self.t[POINT_CLOUD2](
            header=self.header(ns, frame),
            height=1,
            width=len(c.points),
            fields=[field(name=n, offset=o, datatype=kinds[k], count=1) for n, o, k in fields],
            is_bigendian=False,
            point_step=step,
            row_step=step * len(c.points),
            data=np.frombuffer(packed(c), dtype=np.uint8),
            is_dense=True,
        )

    def cloud(self, ns: int, pts: np.ndarray) -> Any:
        field = self.t["sensor_msgs/msg/PointField"]
        data = np.frombuffer(np.ascontiguousarray(pts, dtype="<f4").tobytes(), dtype=np.uint8)
        return self.t["sensor_msgs/msg/PointCloud2"](
            header=self.header(ns, WORLD_FRAME),
            height=1,
            width=len(pts),
            fields=[field(name=n, offset=4 * k, datatype=7, count=1) for k, n in enumerate("xyz")],
            is_bigendian=False,
            point_step=12,
            row_step=12 * len(pts),
            data=data,
            is_dense=True,
        )


def _messages(
    execution: ExecutionRecord,
    plan: PlanRecord,
    states: Sequence[tuple[float, dict[str, Any]]],
    cloud: PlanCloud | None,
    m: _Msgs,
    captures: ExportCaptures | None = None,
) -> list[tuple[str, int, Any]]:
    """(topic, Unix ns, message) of the run, in time order per topic."""
    out: list[tuple[str, int, Any]] = []
    start_ns = iso_ns(execution.created_at)
    path, _ = planned_path(plan)
    if path is not None:
        poses = []
        for p in path:
            T = np.eye(4)
            T[:3, 3] = p
            poses.append(m.pose_stamped(start_ns, WORLD_FRAME, T))
        msg = m.t["nav_msgs/msg/Path"](header=m.header(start_ns, WORLD_FRAME), poses=poses)
        out.append(("/plan/path", start_ns, msg))
    if cloud is not None and cloud.points is not None:
        out.append(("/plan/cloud", start_ns, m.cloud(start_ns, cloud.points)))
    frames, _ = robot_frames(execution.robot)
    for t_s, st in states:
        ns = round(t_s * 1e9)
        q = [float(v) for v in st.get("q_rad") or []]
        names = frames.joint_names(len(q)) if frames else None
        if frames is None or names is None:
            continue
        js = m.t["sensor_msgs/msg/JointState"](
            header=m.header(ns, ""),
            name=names,
            position=np.asarray(q, dtype=np.float64),
            velocity=np.zeros(0),
            effort=np.zeros(0),
        )
        out.append(("/joint_states", ns, js))
        fs = frames.at(q)
        if fs is not None and np.isfinite(fs.tip_pose).all():
            out.append(("/robot/tool_pose", ns, m.pose_stamped(ns, frames.base, fs.tip_pose)))
    robot = execution.robot
    for c in captures.captures if captures is not None else []:
        tfs = [m.transform(c.t_ns, p, ch, T) for p, ch, T in transforms(robot, c)]
        out.append(("/tf", c.t_ns, m.t[TF_MESSAGE](transforms=tfs)))
        out.append((camera_topic(robot), c.t_ns, m.capture(c.t_ns, camera_frame(robot), c)))
    return out


def write_rosbag2(
    execution: ExecutionRecord,
    plan: PlanRecord,
    states: Sequence[tuple[float, dict[str, Any]]],
    *,
    cloud: PlanCloud | None = None,
    captures: ExportCaptures | None = None,
) -> tuple[bytes, dict[str, int]]:
    """The run as a zipped rosbag2 directory, and the message count per topic;
    ``captures``: what the robot's camera saw
    (:func:`server.recording.captures.load_captures`)."""
    from rosbags.rosbag2 import StoragePlugin, Writer

    m = _Msgs()
    msgs = _messages(execution, plan, states, cloud, m, captures)
    types = {**ROSBAG_TOPICS, "/tf": TF_MESSAGE, camera_topic(execution.robot): POINT_CLOUD2}
    counts: dict[str, int] = {}
    buf = io.BytesIO()
    with tempfile.TemporaryDirectory(prefix="steelpath-bag-") as tmp:
        bag = Path(tmp) / execution.id
        with Writer(bag, version=8, storage_plugin=StoragePlugin.SQLITE3) as writer:
            origin = origin_metadata(plan)
            for axis in "xyz":
                writer.set_custom_data(f"world_origin_{axis}_m", origin[f"origin_{axis}_m"])
            writer.set_custom_data("world_frame", WORLD_FRAME)
            conns: dict[str, Any] = {}
            for topic, ns, msg in msgs:
                if topic not in conns:
                    conns[topic] = writer.add_connection(topic, types[topic], typestore=m.store)
                writer.write(conns[topic], ns, m.store.serialize_cdr(msg, types[topic]))
                counts[topic] = counts.get(topic, 0) + 1
        with zipfile.ZipFile(buf, "w", compression=zipfile.ZIP_DEFLATED) as z:
            for f in sorted(bag.iterdir()):
                z.write(f, f"{execution.id}/{f.name}")
    return buf.getvalue(), counts
