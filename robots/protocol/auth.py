"""Authentication of the SteelPath robot protocol v2 (docs/protocol.md §5, §12).

A per-robot **secret** ``K`` (32 random bytes) is known to the robot and to the
one server that may command it.  Nothing else is ever derived from a password;
the secret is stored as 64 hex characters in a file of mode 0600
(:func:`load_or_create_secret`) or typed into real hardware
(:func:`parse_secret`).

Handshake (mutual challenge–response, one and a half round trips)::

    host  → robot  HELLO      major minor heartbeat_ms watchdog_ms flags host_nonce     (plain)
    robot → host   CHALLENGE  major minor status robot_nonce proof                       (plain)
    host  → robot  AUTH       (empty message, MAC'd under the new session key)
    robot → host   HELLO_ACK, STATE …                                                    (MAC'd)

- ``proof = HMAC(K, "SteelPath v2 robot proof" ‖ HELLO ‖ CHALLENGE[0:19])[:16]``
  — the robot proves it knows ``K`` for this fresh ``host_nonce``, so a host
  never streams to an impostor.
- ``session_key = HMAC(K, "SteelPath v2 session key" ‖ HELLO ‖ CHALLENGE)``
  (32 bytes).  ``HELLO`` and ``CHALLENGE`` are the exact payload bytes, so the
  key also authenticates every handshake field (watchdog, takeover flag…): a
  changed byte gives another key and the ``AUTH`` fails.  The robot's fresh
  nonce makes every session's key new, so frames of an old session never
  verify again.  Different labels keep the proof (which anybody may ask for)
  useless as a session key.

Every frame of a session, both directions, carries a **trailer** at the end of
its payload region (the ``len`` field counts it)::

    message payload ‖ counter (u32 LE) ‖ MAC (16 bytes)
    MAC = HMAC(session_key, direction ‖ ver type seq len ‖ message payload ‖ counter)[:16]

``direction`` is ``'H'`` (0x48) host → robot or ``'R'`` (0x52) robot → host, so
a frame cannot be reflected back to its sender.  Each side numbers its frames
0, 1, 2, … and the receiver accepts a counter only if it is greater than the
last one it accepted (gaps are fine: a lost frame is the reliability layer's
business), so a replayed frame is dropped.  A sender must open a new session
before its counter would pass 2³²−1.

:class:`SessionMac` holds one side's state (key, counters); :class:`HostHandshake`
and :func:`robot_challenge`/:func:`robot_session` are the two ends of the
handshake.  Only the standard library is used (``hmac``, ``hashlib``,
``secrets``): a microcontroller needs SHA-256 (≈1 kB of code) and HMAC on top.
"""

from __future__ import annotations

import contextlib
import enum
import hashlib
import hmac
import logging
import os
import secrets
import stat
import struct
from pathlib import Path

from robots.protocol.framing import (
    AUTH_TRAILER_SIZE,
    MAX_MESSAGE_PAYLOAD,
    PROTOCOL_MAJOR,
    Frame,
    ProtocolError,
    encode_frame,
    frame_header,
)
from robots.protocol.messages import (
    NONCE_FIELD_SIZE,
    Auth,
    Challenge,
    Hello,
    HelloFlag,
    HelloStatus,
    Message,
    decode_message,
)

log = logging.getLogger(__name__)

SECRET_SIZE = 32
NONCE_SIZE = NONCE_FIELD_SIZE
MAC_SIZE = 16
COUNTER_SIZE = 4
TRAILER_SIZE = AUTH_TRAILER_SIZE
assert TRAILER_SIZE == COUNTER_SIZE + MAC_SIZE
MAX_COUNTER = 0xFFFFFFFF

PROOF_LABEL = b"SteelPath v2 robot proof"
SESSION_LABEL = b"SteelPath v2 session key"
#: Bytes of a CHALLENGE payload that the robot's proof covers (everything before the proof).
CHALLENGE_PROOF_OFFSET = 3 + NONCE_SIZE


class Direction(enum.IntEnum):
    """First byte of every MAC input: who sent the frame."""

    HOST_TO_ROBOT = 0x48  # 'H'
    ROBOT_TO_HOST = 0x52  # 'R'


# --- errors ---------------------------------------------------------------------------


class AuthError(ProtocolError):
    """A frame or handshake that fails authentication (dropped, never acted on)."""


class MacError(AuthError):
    """Missing trailer or a MAC that does not verify (wrong key, altered bytes)."""


class ReplayError(AuthError):
    """A correctly MAC'd frame whose counter is not above the last one accepted."""


class SecretError(ValueError):
    """A secret value that is not 32 bytes / 64 hex characters."""


class SecretFileError(SecretError):
    """A secret file that cannot be used (format, permissions, not a file)."""

    def __init__(self, path: Path, problem: str) -> None:
        super().__init__(f"robot secret file {path}: {problem}")
        self.path = path


# --- secrets ----------------------------------------------------------------------------


def generate_secret() -> bytes:
    """32 bytes from the OS's CSPRNG."""
    return secrets.token_bytes(SECRET_SIZE)


def check_secret(secret: object) -> bytes:
    """``secret`` as bytes if it is a usable secret (32 bytes, not all zero); else SecretError."""
    if not isinstance(secret, (bytes, bytearray)):
        raise SecretError(f"a robot secret is {SECRET_SIZE} bytes, got {type(secret).__name__}")
    if len(secret) != SECRET_SIZE:
        raise SecretError(f"a robot secret is {SECRET_SIZE} bytes, got {len(secret)}")
    if not any(secret):
        raise SecretError("an all-zero robot secret is not a secret")
    return bytes(secret)


def format_secret(secret: bytes) -> str:
    """The 64 lower-case hex characters a secret file (or a robot's console) holds."""
    return check_secret(secret).hex()


def parse_secret(text: str) -> bytes:
    """A secret from its 64 hex characters (surrounding whitespace ignored); else SecretError.

    For real hardware: the operator copies the robot's secret into the server's
    key file (or the server's into the robot) as this text.
    """
    if not isinstance(text, str):
        raise SecretError(f"a robot secret is given as hex text, got {type(text).__name__}")
    hex_str = text.strip()
    if len(hex_str) != 2 * SECRET_SIZE:
        raise SecretError(f"a robot secret is {2 * SECRET_SIZE} hex characters, got {len(hex_str)}")
    try:
        raw = bytes.fromhex(hex_str)
    except ValueError:
        raise SecretError("a robot secret is hex digits 0-9a-f only") from None
    return check_secret(raw)


def load_or_create_secret(path: Path | str) -> bytes:
    """The secret stored at ``path``; created (mode 0600) with a fresh one when missing.

    Missing parent directories are created with mode 0700.  An existing file
    must be a regular file holding 64 hex characters (plus optional
    whitespace) with no permission for group or others; otherwise
    :class:`SecretFileError` — it is *not* repaired silently, because a key that
    was readable by others may have been read and must be replaced, not
    re-protected (the same rule ``ssh`` applies to private keys).  Creation is
    atomic (written to a temporary file, then hard-linked into place), so two
    processes starting at once end up with the same secret.
    """
    path = Path(path)
    try:
        return _read_secret_file(path)
    except FileNotFoundError:
        pass
    _make_private_dirs(path.parent)
    secret = generate_secret()
    tmp = path.with_name(f".{path.name}.{os.getpid()}.{secrets.token_hex(4)}.tmp")
    fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    try:
        os.fchmod(fd, 0o600)  # whatever the umask
        os.write(fd, (format_secret(secret) + "\n").encode("ascii"))
        os.fsync(fd)
    finally:
        os.close(fd)
    try:
        os.link(tmp, path)
    except FileExistsError:
        # Someone else created it meanwhile: theirs is the one both sides use.
        return _read_secret_file(path)
    finally:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
    log.info("created robot secret %s", path)
    return secret


def _read_secret_file(path: Path) -> bytes:
    st = os.stat(path)  # FileNotFoundError → the caller creates it
    if not stat.S_ISREG(st.st_mode):
        raise SecretFileError(path, "not a regular file")
    mode = stat.S_IMODE(st.st_mode)
    if mode & 0o077:
        raise SecretFileError(
            path,
            f"mode {mode:04o} lets others read it; a secret file must be 0600 "
            "(replace the secret on both sides, then chmod 600)",
        )
    try:
        text = path.read_text(encoding="ascii")
    except UnicodeDecodeError:
        raise SecretFileError(path, "not 64 hex characters (non-ASCII bytes)") from None
    try:
        return parse_secret(text)
    except SecretError as exc:
        raise SecretFileError(path, str(exc)) from None


def _make_private_dirs(directory: Path) -> None:
    missing: list[Path] = []
    d = directory
    while not d.exists():
        missing.append(d)
        d = d.parent
    for d in reversed(missing):
        with contextlib.suppress(FileExistsError):
            os.mkdir(d, 0o700)
            os.chmod(d, 0o700)  # mkdir's mode is filtered by the umask


# --- per-frame MAC ---------------------------------------------------------------------


def frame_mac(key: bytes, direction: int, header: bytes, message: bytes, counter: int) -> bytes:
    """The 16-byte MAC of one frame (see the module docstring for the input layout)."""
    data = bytes((direction,)) + header + message + struct.pack("<I", counter)
    return hmac.new(key, data, hashlib.sha256).digest()[:MAC_SIZE]


class SessionMac:
    """One side's MAC state for one session: seals what it sends, opens what it receives.

    ``sending`` is the direction of this side's own frames; received frames
    are checked as the other direction.  Not thread-safe: the owner serialises
    calls (the link holds its lock, the emulator runs one loop thread).
    """

    def __init__(self, key: bytes, sending: Direction) -> None:
        if len(key) != 32:
            raise ValueError("a session key is 32 bytes")
        self._key = bytes(key)
        self.sending = Direction(sending)
        self.receiving = (
            Direction.ROBOT_TO_HOST
            if self.sending == Direction.HOST_TO_ROBOT
            else Direction.HOST_TO_ROBOT
        )
        self.tx_counter = 0  # the counter the next sealed frame gets
        self.rx_last = -1  # the highest counter accepted so far

    @property
    def exhausted(self) -> bool:
        """True once the send counter is used up: open a new session."""
        return self.tx_counter > MAX_COUNTER

    def seal(self, msg_type: int, seq: int, message: bytes, ver: int = PROTOCOL_MAJOR) -> bytes:
        """Wire bytes (delimiter included) of ``message`` with its counter and MAC appended."""
        if len(message) > MAX_MESSAGE_PAYLOAD:
            raise ValueError(f"message of {len(message)} bytes > {MAX_MESSAGE_PAYLOAD}")
        if self.exhausted:
            raise AuthError("session counter exhausted: open a new session")
        counter = self.tx_counter
        self.tx_counter += 1
        header = frame_header(msg_type, seq, len(message) + TRAILER_SIZE, ver)
        mac = frame_mac(self._key, self.sending, header, message, counter)
        return encode_frame(msg_type, seq, message + struct.pack("<I", counter) + mac, ver)

    def seal_message(self, msg: Message, seq: int = 0) -> bytes:
        return self.seal(msg.TYPE, seq, msg.payload())

    def verify(self, frame: Frame) -> tuple[int, bytes]:
        """``(counter, message payload)`` if ``frame``'s MAC verifies; does not consume it."""
        if len(frame.payload) < TRAILER_SIZE:
            raise MacError("frame has no authentication trailer")
        message = frame.payload[:-TRAILER_SIZE]
        (counter,) = struct.unpack_from("<I", frame.payload, len(message))
        mac = frame.payload[-MAC_SIZE:]
        header = frame_header(frame.type, frame.seq, len(frame.payload), frame.ver)
        expected = frame_mac(self._key, self.receiving, header, message, counter)
        if not hmac.compare_digest(mac, expected):
            raise MacError("MAC does not verify")
        return counter, message

    def open(self, frame: Frame) -> bytes:
        """The message payload of an authentic, fresh ``frame``; raises :class:`AuthError`.

        Only a frame that verifies moves the receive counter, so garbage cannot
        desynchronise a session.
        """
        counter, message = self.verify(frame)
        if counter <= self.rx_last:
            raise ReplayError(f"counter {counter} not above {self.rx_last} (replayed frame)")
        self.rx_last = counter
        return message

    def open_message(self, frame: Frame) -> Message:
        """:meth:`open`, then parse; raises AuthError or MessageError."""
        message = self.open(frame)
        return decode_message(Frame(type=frame.type, seq=frame.seq, payload=message, ver=frame.ver))


# --- handshake -----------------------------------------------------------------------------


def new_nonce() -> bytes:
    return secrets.token_bytes(NONCE_SIZE)


def robot_proof(secret: bytes, hello: Hello, challenge_head: bytes) -> bytes:
    """The robot's 16-byte proof over ``HELLO`` and ``CHALLENGE[0:19]`` (status, nonce)."""
    data = PROOF_LABEL + hello.payload() + challenge_head[:CHALLENGE_PROOF_OFFSET]
    return hmac.new(secret, data, hashlib.sha256).digest()[:MAC_SIZE]


def session_key(secret: bytes, hello: Hello, challenge: Challenge) -> bytes:
    """The 32-byte key of the session opened by this HELLO/CHALLENGE pair."""
    data = SESSION_LABEL + hello.payload() + challenge.payload()
    return hmac.new(secret, data, hashlib.sha256).digest()


def robot_challenge(secret: bytes, hello: Hello, robot_nonce: bytes | None = None) -> Challenge:
    """The robot's CHALLENGE answering ``hello`` (a fresh nonce unless given)."""
    nonce = new_nonce() if robot_nonce is None else robot_nonce
    head = Challenge(status=HelloStatus.OK, robot_nonce=nonce).payload()
    return Challenge(
        status=HelloStatus.OK, robot_nonce=nonce, proof=robot_proof(secret, hello, head)
    )


def robot_session(secret: bytes, hello: Hello, challenge: Challenge) -> SessionMac:
    """The robot's side of the session its CHALLENGE offered (check the AUTH with it)."""
    return SessionMac(session_key(secret, hello, challenge), Direction.ROBOT_TO_HOST)


class HostHandshake:
    """The host's side of one handshake attempt (one per opened port).

    ``hello`` is what to send (repeat it verbatim until answered: the robot
    answers a repeated HELLO with the same CHALLENGE); :meth:`accept` checks
    the robot's CHALLENGE and returns the session, whose first frame is the
    AUTH (:meth:`auth_frame`).
    """

    def __init__(
        self,
        secret: bytes | None,
        *,
        heartbeat_ms: int = 100,
        watchdog_ms: int = 500,
        takeover: bool = False,
    ) -> None:
        self._secret = None if secret is None else check_secret(secret)
        self.hello = Hello(
            heartbeat_ms=heartbeat_ms,
            watchdog_ms=watchdog_ms,
            flags=int(HelloFlag.TAKEOVER) if takeover else 0,
            host_nonce=new_nonce(),
        )

    def accept(self, challenge: Challenge) -> SessionMac:
        """The session if ``challenge`` proves the robot knows the secret; else AuthError."""
        if challenge.status != HelloStatus.OK:
            raise AuthError(f"robot refused the HELLO (status {challenge.status})")
        if self._secret is None:
            raise AuthError("no secret configured for this robot (LinkConfig.secret)")
        expected = robot_proof(self._secret, self.hello, challenge.payload())
        if not hmac.compare_digest(expected, challenge.proof):
            raise AuthError("robot failed authentication (wrong proof: another secret?)")
        return SessionMac(session_key(self._secret, self.hello, challenge), Direction.HOST_TO_ROBOT)

    @staticmethod
    def auth_frame(session: SessionMac) -> bytes:
        """Wire bytes of the AUTH (seq 0) that proves the host knows the secret."""
        return session.seal_message(Auth(), 0)
