"""What the robot's camera saw: captures stored with their execution, listed
and served over REST (:mod:`server.captures.router`), drawn in the scene
(:mod:`server.scene.captures`) and exported (:mod:`server.recording`)."""

from server.captures.limits import CaptureLimits, capture_limits
from server.captures.store import CaptureRecord, CaptureRefused, CaptureStore

__all__ = [
    "CaptureLimits",
    "CaptureRecord",
    "CaptureRefused",
    "CaptureStore",
    "capture_limits",
]
