"""Recorded runs: an execution exported as MCAP
(:mod:`server.recording.mcap`, for Foxglove / Lichtblick) or as a ROS 2 bag
(:mod:`server.recording.rosbag`), both from what the service stored
(:mod:`server.recording.channels`)."""

from server.recording.channels import PlanCloud, plan_cloud
from server.recording.mcap import CHANNELS, write_recording
from server.recording.rosbag import ROSBAG_TOPICS, write_rosbag2

__all__ = [
    "CHANNELS",
    "ROSBAG_TOPICS",
    "PlanCloud",
    "plan_cloud",
    "write_recording",
    "write_rosbag2",
]
