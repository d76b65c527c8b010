"""robots.protocol.auth: secrets and their files, the handshake, per-frame MAC and counters."""

from __future__ import annotations

import os
import stat
import threading
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

# deadline=None everywhere: a loaded 2-core machine must not fail a property on time.
from robots.adapters import LinkConfig
from robots.protocol.auth import (
    MAX_COUNTER,
    SECRET_SIZE,
    TRAILER_SIZE,
    AuthError,
    Direction,
    HostHandshake,
    MacError,
    ReplayError,
    SecretError,
    SecretFileError,
    SessionMac,
    format_secret,
    generate_secret,
    load_or_create_secret,
    parse_secret,
    robot_challenge,
    robot_session,
)
from robots.protocol.framing import (
    CRC_SIZE,
    MAX_MESSAGE_PAYLOAD,
    FrameDecoder,
    FrameError,
    cobs_decode,
    crc16,
    decode_frame,
    parse_raw_frame,
)
from robots.protocol.messages import (
    Auth,
    Challenge,
    HelloFlag,
    HelloStatus,
    JointsCmd,
    State,
    decode_message,
)

KEY = bytes(range(32))


def pair() -> tuple[SessionMac, SessionMac]:
    return SessionMac(KEY, Direction.HOST_TO_ROBOT), SessionMac(KEY, Direction.ROBOT_TO_HOST)


# --- secrets --------------------------------------------------------------------------


def test_parse_secret_accepts_64_hex_and_refuses_the_rest() -> None:
    s = generate_secret()
    assert len(s) == SECRET_SIZE and parse_secret(format_secret(s)) == s
    assert parse_secret(f"  {s.hex().upper()}\n") == s
    for bad, why in [
        ("ab" * 31, "64 hex characters"),
        ("ab" * 33, "64 hex characters"),
        ("zz" * 32, "hex digits"),
        ("00" * 32, "all-zero"),
    ]:
        with pytest.raises(SecretError, match=why):
            parse_secret(bad)
    with pytest.raises(SecretError, match="hex text"):
        parse_secret(s)  # type: ignore[arg-type]


def test_load_or_create_secret_creates_private_file_and_dirs(tmp_path: Path) -> None:
    old = os.umask(0o022)  # a typical umask would otherwise give 0644 / 0755
    try:
        path = tmp_path / "data" / "robots" / "ara.key"
        s = load_or_create_secret(path)
    finally:
        os.umask(old)
    assert stat.S_IMODE(path.stat().st_mode) == 0o600
    for d in (path.parent, path.parent.parent):
        assert stat.S_IMODE(d.stat().st_mode) == 0o700
    assert path.read_text() == s.hex() + "\n"
    assert load_or_create_secret(path) == s  # stable across restarts
    assert [p.name for p in path.parent.iterdir()] == ["ara.key"]  # no temp file left


def test_secret_file_problems_are_typed_errors(tmp_path: Path) -> None:
    loose = tmp_path / "loose.key"
    loose.write_text(generate_secret().hex())
    loose.chmod(0o640)
    with pytest.raises(SecretFileError, match="mode 0640") as exc:
        load_or_create_secret(loose)
    assert exc.value.path == loose
    loose.chmod(0o600)
    assert len(load_or_create_secret(loose)) == SECRET_SIZE
    bad = tmp_path / "bad.key"
    bad.write_text("hello")
    bad.chmod(0o600)
    with pytest.raises(SecretFileError, match="64 hex characters"):
        load_or_create_secret(bad)
    binary = tmp_path / "binary.key"
    binary.write_bytes(b"\xff" * 64)
    binary.chmod(0o600)
    with pytest.raises(SecretFileError, match="non-ASCII"):
        load_or_create_secret(binary)
    (tmp_path / "dir.key").mkdir(mode=0o700)
    with pytest.raises(SecretFileError, match="regular file"):
        load_or_create_secret(tmp_path / "dir.key")


def test_concurrent_creation_agrees_on_one_secret(tmp_path: Path) -> None:
    path = tmp_path / "robots" / "cmbot.key"
    results: list[bytes] = []
    threads = [
        threading.Thread(target=lambda: results.append(load_or_create_secret(path)))
        for _ in range(8)
    ]
    for t in threads:
        t.start()
    for t in threads:
        t.join(10)
    assert len(results) == 8 and len(set(results)) == 1
    assert parse_secret(path.read_text()) == results[0]


def test_link_config_validates_and_hides_the_secret() -> None:
    s = generate_secret()
    assert LinkConfig(secret=s).secret == s
    assert s.hex() not in repr(LinkConfig(secret=s)) and str(s) not in repr(LinkConfig(secret=s))
    with pytest.raises(SecretError, match="32 bytes"):
        LinkConfig(secret=b"short")
    with pytest.raises(SecretError):
        LinkConfig(secret=s.hex())  # type: ignore[arg-type]


# --- per-frame MAC ----------------------------------------------------------------------

messages = st.one_of(
    st.builds(
        JointsCmd,
        run_id=st.integers(0, 2**32 - 1),
        index=st.integers(0, 2**32 - 1),
        duration_ms=st.integers(0, 2**32 - 1),
        q_urad=st.lists(st.integers(-(2**31), 2**31 - 1), max_size=7).map(tuple),
    ),
    st.builds(
        State,
        run_id=st.integers(0, 2**32 - 1),
        q_urad=st.lists(st.integers(-(2**31), 2**31 - 1), max_size=16).map(tuple),
        odometry_um=st.lists(st.integers(-(2**31), 2**31 - 1), max_size=16).map(tuple),
    ),
)


@settings(deadline=None)
@given(st.lists(st.tuples(messages, st.integers(0, 0xFFFF)), min_size=1, max_size=8))
def test_sealed_frames_round_trip_in_order(items: list) -> None:
    host, robot = pair()
    wire = b"".join(host.seal_message(m, seq) for m, seq in items)
    frames = FrameDecoder().feed(wire)
    assert len(frames) == len(items)
    for frame, (msg, seq) in zip(frames, items, strict=True):
        assert frame.seq == seq and len(frame.payload) == len(msg.payload()) + TRAILER_SIZE
        assert robot.open_message(frame) == msg
    assert robot.rx_last == len(items) - 1 and host.tx_counter == len(items)


@settings(deadline=None)
@given(messages, st.data())
def test_any_altered_byte_with_a_fixed_crc_is_dropped(msg: object, data: st.DataObject) -> None:
    host, robot = pair()
    raw = cobs_decode(host.seal_message(msg, 3)[:-1])[:-CRC_SIZE]  # type: ignore[arg-type]
    at = data.draw(st.integers(0, len(raw) - 1))
    bit = data.draw(st.integers(0, 7))
    altered = bytearray(raw)
    altered[at] ^= 1 << bit
    fixed = bytes(altered) + crc16(bytes(altered)).to_bytes(2, "little")
    try:
        frame = parse_raw_frame(fixed)
    except FrameError:
        return  # version or length byte changed: the frame layer already refuses it
    with pytest.raises(MacError):
        robot.open(frame)
    assert robot.rx_last == -1  # a bad frame does not move the counter


def test_replay_is_dropped_and_gaps_are_fine() -> None:
    host, robot = pair()
    wires = [host.seal_message(Auth(), 0) for _ in range(4)]
    assert robot.open(decode_frame(wires[0])) == b""
    with pytest.raises(ReplayError):
        robot.open(decode_frame(wires[0]))  # the same frame again
    assert robot.open(decode_frame(wires[3])) == b""  # frames 1 and 2 were lost: fine
    with pytest.raises(ReplayError):
        robot.open(decode_frame(wires[2]))  # older than the last accepted one


def test_wrong_key_reflection_and_missing_trailer_fail() -> None:
    host, _robot = pair()
    wire = host.seal_message(Auth(), 0)
    with pytest.raises(MacError):
        SessionMac(bytes(32 * [7]), Direction.ROBOT_TO_HOST).open(decode_frame(wire))
    # A host frame reflected back to a host does not verify (direction byte).
    with pytest.raises(MacError):
        SessionMac(KEY, Direction.HOST_TO_ROBOT).open(decode_frame(wire))
    from robots.protocol.messages import encode_message

    with pytest.raises(MacError, match="no authentication trailer"):
        SessionMac(KEY, Direction.ROBOT_TO_HOST).open(decode_frame(encode_message(Auth(), 0)))


def test_counter_exhaustion_forces_a_new_session() -> None:
    host, _ = pair()
    host.tx_counter = MAX_COUNTER
    host.seal_message(Auth(), 0)  # the last counter is still usable
    assert host.exhausted
    with pytest.raises(AuthError, match="exhausted"):
        host.seal_message(Auth(), 0)


def test_largest_messages_fit_with_their_trailer() -> None:
    host, robot = pair()
    # STATE with 7 joints and 4 wheels, CMD_JOINTS with 7 joints: far below the limit.
    for msg in (State(q_urad=(1,) * 7, odometry_um=(2,) * 4), JointsCmd(q_urad=(3,) * 7)):
        assert robot.open_message(decode_frame(host.seal_message(msg, 1))) == msg
    assert len(State(q_urad=(0,) * 23, odometry_um=(0,) * 23).payload()) <= MAX_MESSAGE_PAYLOAD
    with pytest.raises(ValueError, match="221 bytes > 220"):
        host.seal(0x10, 1, bytes(MAX_MESSAGE_PAYLOAD + 1))


# --- handshake ----------------------------------------------------------------------------


def test_handshake_gives_both_sides_the_same_session() -> None:
    secret = generate_secret()
    hs = HostHandshake(secret, watchdog_ms=300, takeover=True)
    assert hs.hello.flags & HelloFlag.TAKEOVER and hs.hello.watchdog_ms == 300
    challenge = robot_challenge(secret, hs.hello)
    host = hs.accept(challenge)
    robot = robot_session(secret, hs.hello, challenge)
    auth = decode_frame(HostHandshake.auth_frame(host))
    assert decode_message(auth.__class__(auth.type, auth.seq, robot.open(auth))) == Auth()
    reply = robot.seal_message(State(run_id=5), 0)
    assert host.open_message(decode_frame(reply)) == State(run_id=5)
    # Every handshake has fresh nonces, so a fresh key.
    hs2 = HostHandshake(secret)
    assert hs2.hello.host_nonce != hs.hello.host_nonce
    with pytest.raises(MacError):
        robot_session(secret, hs2.hello, robot_challenge(secret, hs2.hello)).open(auth)


def test_host_refuses_a_robot_without_the_secret() -> None:
    secret = generate_secret()
    hs = HostHandshake(secret)
    with pytest.raises(AuthError, match="robot failed authentication"):
        hs.accept(robot_challenge(generate_secret(), hs.hello))
    # A proof replayed from another handshake (other host nonce) fails too.
    old = HostHandshake(secret)
    with pytest.raises(AuthError, match="robot failed authentication"):
        hs.accept(robot_challenge(secret, old.hello))
    with pytest.raises(AuthError, match="refused"):
        hs.accept(Challenge(status=HelloStatus.LINE_BUSY))
    with pytest.raises(AuthError, match="no secret configured"):
        HostHandshake(None).accept(robot_challenge(secret, HostHandshake(None).hello))


def test_session_key_binds_every_hello_field() -> None:
    """An altered HELLO (e.g. a longer watchdog, a takeover flag) gives another key."""
    from dataclasses import replace

    secret = generate_secret()
    hs = HostHandshake(secret)
    challenge = robot_challenge(secret, hs.hello)
    auth = decode_frame(HostHandshake.auth_frame(hs.accept(challenge)))
    for changed in (
        replace(hs.hello, watchdog_ms=2000),
        replace(hs.hello, flags=int(HelloFlag.TAKEOVER)),
        replace(hs.hello, heartbeat_ms=1000),
    ):
        with pytest.raises(MacError):
            robot_session(secret, changed, challenge).open(auth)
