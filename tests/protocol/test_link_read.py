"""The link's read of a ``socket://`` port takes everything that arrived at once."""

from __future__ import annotations

import socket
import threading
from typing import Any

import pytest
import serial

from robots.adapters.link_types import _raw_socket, _read_some


@pytest.fixture
def connected() -> Any:
    """A pyserial ``socket://`` port and the server end of its connection."""
    lsock = socket.create_server(("127.0.0.1", 0))
    port_no = lsock.getsockname()[1]
    accepted: list[socket.socket] = []
    t = threading.Thread(target=lambda: accepted.append(lsock.accept()[0]))
    t.start()
    port = serial.serial_for_url(f"socket://127.0.0.1:{port_no}", timeout=0.05)
    t.join(5)
    peer = accepted[0]
    try:
        yield port, peer
    finally:
        port.close()
        peer.close()
        lsock.close()


def _drain(port: Any, sock: socket.socket | None, n: int) -> tuple[bytes, int]:
    data, calls = b"", 0
    while len(data) < n and calls < 10_000:
        data += _read_some(port, sock, 0.5)
        calls += 1
    return data, calls


def test_socket_port_reads_a_burst_in_one_call(connected: Any) -> None:
    port, peer = connected
    sock = _raw_socket(port)
    assert sock is not None
    payload = bytes(range(256)) * 4
    peer.sendall(payload)
    data, calls = _drain(port, sock, len(payload))
    assert data == payload
    # 1 KiB sent at once over loopback arrives in one or two segments; the old
    # read(1) + read(in_waiting) took it two bytes a call (512 calls).
    assert calls <= 2


def test_generic_port_path_reads_the_same_bytes(connected: Any) -> None:
    port, peer = connected
    payload = b"\x7e" + bytes(range(1, 200)) + b"\x7e"
    peer.sendall(payload)
    data, _ = _drain(port, None, len(payload))
    assert data == payload


def test_timeout_returns_nothing_and_eof_raises(connected: Any) -> None:
    port, peer = connected
    sock = _raw_socket(port)
    assert _read_some(port, sock, 0.01) == b""
    peer.close()
    with pytest.raises(ConnectionResetError):
        _read_some(port, sock, 1.0)


def test_only_plain_socket_ports_are_read_raw() -> None:
    loop = serial.serial_for_url("loop://", timeout=0.01)
    try:
        assert _raw_socket(loop) is None
        loop.write(b"abc")
        assert _read_some(loop, None, 0.01) == b"abc"
    finally:
        loop.close()
