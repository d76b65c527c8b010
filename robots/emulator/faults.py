"""Fault injection settings of the emulator (``steelpath emulate`` flags)."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class FaultConfig:
    """Which faults to inject; the defaults inject none.

    Link faults (applied by the transport):

    - ``drop_after_frames``: after this many valid frames received on a
      connection, drop the link — close the TCP connection (``drop_mode``
      ``"close"``), or go silent for ``drop_for_s`` seconds (``"silence"``:
      nothing read or written, as if the cable were pulled; the only kind a pty
      can do).  ``"auto"`` closes TCP and silences a pty.  Repeats on the next
      ``drop_times - 1`` connections.
    - ``corrupt_rate``: probability that each byte is replaced by a random one,
      on received (``"rx"``), sent (``"tx"``) or ``"both"`` directions.
    - ``delay_s``: hold every frame this long (``delay_direction`` as above).

    Robot faults (applied by :class:`robots.emulator.robot.SimRobot`):

    - ``nak_index``: NAK command index ``nak_index`` the first ``nak_times``
      times it arrives: ``BUSY`` (transient, the host retransmits) or, with
      ``nak_permanent``, ``INVALID`` (refused).
    - ``fault_at_index``: halfway through command ``fault_at_index`` raise a
      latched ``DRIVE`` fault with ``fault_code`` (``fault_times`` times).
    """

    drop_after_frames: int | None = None
    drop_times: int = 1
    drop_mode: str = "auto"
    drop_for_s: float = 1.0
    corrupt_rate: float = 0.0
    corrupt_direction: str = "both"
    delay_s: float = 0.0
    delay_direction: str = "both"
    nak_index: int | None = None
    nak_times: int = 1
    nak_permanent: bool = False
    fault_at_index: int | None = None
    fault_times: int = 1
    fault_code: int = 1
    seed: int = 0

    def __post_init__(self) -> None:
        if self.drop_mode not in ("auto", "close", "silence"):
            raise ValueError(f"drop_mode={self.drop_mode!r}: auto, close or silence")
        for name in ("corrupt_direction", "delay_direction"):
            if getattr(self, name) not in ("rx", "tx", "both"):
                raise ValueError(f"{name}={getattr(self, name)!r}: rx, tx or both")
        if not 0.0 <= self.corrupt_rate <= 1.0:
            raise ValueError(f"corrupt_rate={self.corrupt_rate}: must be 0…1")
        if self.delay_s < 0 or self.drop_for_s < 0:
            raise ValueError("delay_s and drop_for_s must be ≥ 0")
        if self.drop_after_frames is not None and self.drop_after_frames < 1:
            raise ValueError(f"drop_after_frames={self.drop_after_frames}: must be ≥ 1")
