"""Length-prefixed JSON messages over a local stream socket.

The web server and the robot-link service talk over a ``socketpair`` that the
server creates and hands to the child (no name on disk, so no other local
process can connect).  Each message is ``u32 length ‖ UTF-8 JSON``; a writer
holds a lock per message so threads never interleave bytes.  Receivers read
with no timeout and treat EOF as "the other side is gone".
"""

from __future__ import annotations

import contextlib
import json
import socket
import struct
import threading
from typing import Any

_LEN = struct.Struct("<I")
#: Messages are small (requests, status dicts, events); a corrupt length must
#: not make a receiver allocate gigabytes.
MAX_MESSAGE = 16 * 1024 * 1024


#: The web server's last message on the RPC channel when it stops in order
#: (no reply): the service then releases this server's robot leases.
STOP_OP = "stop"


class ChannelClosed(ConnectionError):
    """The other end closed the channel (or the bytes stopped making sense)."""


class Channel:
    """One end of a message channel; thread-safe for senders, one reader."""

    def __init__(self, sock: socket.socket) -> None:
        self.sock = sock
        self._wlock = threading.Lock()
        self._rbuf = bytearray()

    def send(self, obj: Any) -> None:
        data = json.dumps(obj, separators=(",", ":"), allow_nan=False).encode()
        if len(data) > MAX_MESSAGE:
            raise ValueError(f"message of {len(data)} bytes exceeds {MAX_MESSAGE}")
        with self._wlock:
            try:
                self.sock.sendall(_LEN.pack(len(data)) + data)
            except OSError as exc:
                raise ChannelClosed(str(exc)) from exc

    def _read_exact(self, n: int) -> bytes:
        while len(self._rbuf) < n:
            try:
                chunk = self.sock.recv(max(65536, n - len(self._rbuf)))
            except OSError as exc:
                raise ChannelClosed(str(exc)) from exc
            if not chunk:
                raise ChannelClosed("peer closed the channel")
            self._rbuf += chunk
        out = bytes(self._rbuf[:n])
        del self._rbuf[:n]
        return out

    def recv(self) -> Any:
        (n,) = _LEN.unpack(self._read_exact(_LEN.size))
        if n > MAX_MESSAGE:
            raise ChannelClosed(f"message length {n} exceeds {MAX_MESSAGE}")
        try:
            return json.loads(self._read_exact(n))
        except ValueError as exc:
            raise ChannelClosed(f"undecodable message: {exc}") from exc

    def close(self) -> None:
        with contextlib.suppress(OSError):
            self.sock.shutdown(socket.SHUT_RDWR)
        self.sock.close()
