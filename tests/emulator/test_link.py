"""RobotLink: handshake, state machine, reconnect with backoff, URL handlers."""

from __future__ import annotations

import socket

import pytest

from robots.adapters import (
    Connected,
    LinkConfig,
    LinkDownError,
    LinkState,
    LinkStateChanged,
    RobotLink,
)
from robots.emulator import Emulator
from robots.protocol import FaultFlag, JointMove, Mode, generate_secret

from .helpers import link_config


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_handshake_and_ready_over_tcp() -> None:
    events: list = []
    with Emulator("generic") as emu, RobotLink(emu.url, link_config(emu), name="gen") as link:
        link.subscribe(events.append)
        assert link.wait_connected(5)
        info = link.robot_info
        assert info is not None and info.name == "generic" and info.n_joints == 6
        assert link.state == LinkState.READY and link.last_report is not None
        status = link.status()
        assert status.last_rx_wall is not None and status.session == 1
        # Idle link: heartbeats keep both sides alive well past the timeouts.
        assert not link.wait_for(lambda lk: lk.state != LinkState.READY, 1.5)
        assert emu.snapshot().faults == 0
    assert any(isinstance(e, LinkStateChanged) and e.new == LinkState.DISCONNECTED for e in events)


def test_state_machine_through_streaming_and_fault() -> None:
    seen: list[LinkState] = []
    with Emulator("generic", time_scale=5) as emu, RobotLink(emu.url, link_config(emu)) as link:
        assert link.wait_connected(5)
        link.subscribe(lambda e: isinstance(e, LinkStateChanged) and seen.append(e.new))
        link.send_command(JointMove((0.1,) * 6, 1.0), run_id=3, index=0)
        assert link.wait_for(lambda lk: lk.state == LinkState.STREAMING, 5)
        assert link.wait_for(lambda lk: lk.state == LinkState.READY, 5)
        assert link.last_report.last_done == 0 and link.last_report.run_id == 3
        emu.raise_fault(code=4)
        assert link.wait_for(lambda lk: lk.state == LinkState.FAULT, 5)
        assert "DRIVE" in link.status().reason
        link.clear_faults(FaultFlag.DRIVE)
        assert link.wait_for(lambda lk: lk.state == LinkState.READY, 5)
    assert seen[:4] == [LinkState.STREAMING, LinkState.READY, LinkState.FAULT, LinkState.READY]


def test_reconnects_with_backoff_until_the_robot_appears() -> None:
    port = free_port()
    secret = generate_secret()
    cfg = LinkConfig(backoff_initial_s=0.05, backoff_max_s=0.2, secret=secret)
    with RobotLink(f"socket://127.0.0.1:{port}", cfg) as link:
        assert link.wait_for(lambda lk: "cannot open" in lk.status().reason, 5)
        assert link.state == LinkState.DISCONNECTED
        with pytest.raises(LinkDownError):
            link.pause()
        with Emulator("generic", listen=f"tcp://127.0.0.1:{port}", secret=secret):
            assert link.wait_connected(5)
        # The emulator went away: the link notices and goes back to reconnecting.
        assert link.wait_for(lambda lk: lk.state == LinkState.DISCONNECTED, 5)


def test_reconnect_after_drop_opens_a_new_session() -> None:
    events: list = []
    with Emulator("generic") as emu:
        link = RobotLink(emu.url, link_config(emu))
        link.subscribe(events.append)
        with link:
            assert link.wait_connected(5)
            emu.drop_link()
            assert link.wait_for(lambda lk: lk.session == 2 and lk.connected, 5)
    assert [e.session for e in events if isinstance(e, Connected)] == [1, 2]
    assert emu.stats["connections"] == 2


def test_loop_url_never_completes_a_handshake() -> None:
    # loop:// echoes our own HELLO back; the link must not mistake it for a robot.
    cfg = LinkConfig(handshake_timeout_s=0.3, backoff_initial_s=0.05, backoff_max_s=0.1)
    with RobotLink("loop://", cfg) as link:
        assert link.wait_for(lambda lk: "no handshake answer" in lk.status().reason, 5)
        link.estop()  # E-stop while handshaking: latched, no exception
        assert link.estop_latched and not link.connected


def test_wrong_robot_is_refused() -> None:
    with (
        Emulator("generic") as emu,
        RobotLink(
            emu.url, link_config(emu, expected_robot="cmbot", backoff_initial_s=0.05)
        ) as link,
    ):
        assert link.wait_for(lambda lk: "expected 'cmbot'" in lk.status().reason, 5)
        assert not link.connected


def test_pty_serial_device() -> None:
    with (
        Emulator("generic", listen=None, pty=True) as emu,
        RobotLink(emu.pty_path, link_config(emu)) as link,
    ):
        assert emu.pty_path.startswith("/dev/pts/")
        assert link.wait_connected(5)
        link.send_command(JointMove((0.2,) * 6, 0.0), run_id=1, index=0)
        assert link.wait_for(lambda lk: lk.last_report.last_done == 0, 5)
        assert link.last_report.mode == Mode.IDLE
