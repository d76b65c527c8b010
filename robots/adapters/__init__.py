"""Host-side robot adapters: the protocol link and the program streamer (DESIGN §7).

- :class:`RobotLink` — one connection over any pyserial URL (thread-based; see
  :mod:`robots.adapters.link` for why), with handshake, heartbeat, ACK/NAK and
  bounded retransmission, reconnect with backoff, and a latched E-stop.
- :class:`CaptureReceived` / :meth:`RobotLink.subscribe_captures` — the sensor
  frames (:class:`robots.protocol.capture.SensorCapture`) a robot brings back.
- :class:`Streamer` (= :data:`ExecutionDriver`) — runs a
  :class:`~robots.protocol.program.Program` over a link with per-command
  completion callbacks, pause/resume/abort/E-stop, and exact resume.
"""

from robots.adapters.link import (
    CONNECTED_STATES,
    CaptureReceived,
    Connected,
    EstopLatched,
    FrameAcked,
    FrameRefused,
    LinkConfig,
    LinkDownError,
    LinkEvent,
    LinkState,
    LinkStateChanged,
    LinkStatus,
    ReportReceived,
    RobotLink,
)
from robots.adapters.streamer import (
    TERMINAL_STATES,
    ExecState,
    ExecutionDriver,
    FaultKind,
    Outcome,
    Streamer,
    StreamFault,
)

__all__ = [
    "CONNECTED_STATES",
    "TERMINAL_STATES",
    "CaptureReceived",
    "Connected",
    "EstopLatched",
    "ExecState",
    "ExecutionDriver",
    "FaultKind",
    "FrameAcked",
    "FrameRefused",
    "LinkConfig",
    "LinkDownError",
    "LinkEvent",
    "LinkState",
    "LinkStateChanged",
    "LinkStatus",
    "Outcome",
    "ReportReceived",
    "RobotLink",
    "StreamFault",
    "Streamer",
]
