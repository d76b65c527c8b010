"""Sensor captures on the wire: header + chunks round-trip, and the host's reassembly
hands on exactly what arrived (complete or not), bounded."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from robots.protocol.capture import (
    CaptureAssembler,
    SensorCapture,
    capture_messages,
    matrix_to_quaternion,
    quaternion_to_matrix,
    rpy_to_matrix,
)
from robots.protocol.framing import MAX_MESSAGE_PAYLOAD, FrameDecoder
from robots.protocol.messages import (
    CHUNK_POINTS,
    MAX_CAPTURE_POINTS,
    CaptureChunk,
    CaptureHeader,
    Message,
    decode_message,
    encode_message,
)

angles = st.floats(-math.pi, math.pi, allow_nan=False)


def pose(xyz: tuple[float, float, float], rpy: tuple[float, float, float]) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = rpy_to_matrix(rpy)
    T[:3, 3] = xyz
    return T


def over_the_wire(msgs: list[Message]) -> list[Message]:
    out = []
    for seq, m in enumerate(msgs):
        wire = encode_message(m, seq)
        assert len(m.payload()) <= MAX_MESSAGE_PAYLOAD
        (frame,) = FrameDecoder().feed(wire)
        out.append(decode_message(frame))
    return out


def assemble(msgs: list[Message], now: float = 0.0) -> tuple[list[SensorCapture], CaptureAssembler]:
    asm = CaptureAssembler()
    got: list[SensorCapture] = []
    for m in msgs:
        assert isinstance(m, CaptureHeader | CaptureChunk)
        got += asm.feed(m, now)
    return got, asm


def some_capture(
    n: int = 100, intensity: bool = True, cid: int = 7, seed: int = 0
) -> list[Message]:
    rng = np.random.default_rng(seed)
    pts = rng.uniform([-1, -1, 0.2], [1, 1, 2.5], (n, 3))
    return capture_messages(
        capture_id=cid,
        run_id=3,
        index=11,
        t_s=12.345,
        camera_to_world=pose((100.0, -20.0, 1.5), (0.1, -0.4, 2.0)),
        points_m=pts,
        intensity=rng.integers(0, 256, n).astype(np.uint8) if intensity else None,
    )


@settings(max_examples=60, deadline=None)
@given(
    st.integers(0, MAX_CAPTURE_POINTS),
    st.booleans(),
    st.tuples(*[st.floats(-2000.0, 2000.0)] * 3),
    st.tuples(angles, st.floats(-math.pi / 2, math.pi / 2), angles),
    st.integers(0, 2**32 - 1),
    st.integers(0, 2**31),
)
def test_capture_round_trip(n, with_intensity, xyz, rpy, cid, seed) -> None:
    rng = np.random.default_rng(seed)
    pts = rng.uniform(-32.7, 32.7, (n, 3))
    inten = rng.integers(0, 256, n).astype(np.uint8) if with_intensity else None
    T = pose(xyz, rpy)
    msgs = capture_messages(
        capture_id=cid,
        run_id=5,
        index=9,
        t_s=3.25,
        camera_to_world=T,
        points_m=pts,
        intensity=inten,
    )
    assert len(msgs) == 1 + math.ceil(n / CHUNK_POINTS)
    got, asm = assemble(over_the_wire(msgs))
    (cap,) = got
    assert not asm.pending
    assert (cap.capture_id, cap.run_id, cap.command_index, cap.complete) == (cid, 5, 9, True)
    assert cap.t_s == pytest.approx(3.25)
    assert cap.points_m.dtype == np.float32 and cap.points_m.shape == (n, 3)
    assert np.abs(cap.points_m - pts).max(initial=0.0) <= 0.0005 + 1e-6
    assert np.allclose(cap.camera_position_m, xyz, atol=1e-6, rtol=0)
    assert np.allclose(cap.camera_rotation, T[:3, :3], atol=1e-8)
    if with_intensity:
        assert cap.intensity is not None and np.array_equal(cap.intensity, inten)
    else:
        assert cap.intensity is None
    # The world points are where the pose says.
    assert np.allclose(cap.world_points(), pts @ T[:3, :3].T + T[:3, 3], atol=1e-3)


@settings(max_examples=100, deadline=None)
@given(
    arrays(np.float64, (4,), elements=st.floats(-1, 1)).filter(lambda q: np.linalg.norm(q) > 0.1)
)
def test_quaternion_round_trip(q) -> None:
    R = quaternion_to_matrix(q)
    assert np.allclose(R @ R.T, np.eye(3), atol=1e-12) and np.linalg.det(R) == pytest.approx(1)
    assert np.allclose(quaternion_to_matrix(matrix_to_quaternion(R)), R, atol=1e-12)


def test_rpy_convention() -> None:
    # URDF: R = Rz(yaw) Ry(pitch) Rx(roll).
    assert np.allclose(rpy_to_matrix((0, 0, math.pi / 2)) @ [1, 0, 0], [0, 1, 0])
    assert np.allclose(rpy_to_matrix((0, math.pi / 2, 0)) @ [1, 0, 0], [0, 0, -1])
    assert np.allclose(rpy_to_matrix((math.pi / 2, 0, 0)) @ [0, 1, 0], [0, 0, 1])


def test_a_lost_chunk_gives_an_incomplete_capture_at_the_next_header() -> None:
    first = some_capture(100, cid=1)  # header + 4 chunks (30, 30, 30, 10)
    second = some_capture(40, cid=2, seed=1)
    lost = first[2]
    assert isinstance(lost, CaptureChunk) and lost.offset == 30
    stream = [m for m in first if m is not lost] + second
    got, asm = assemble(over_the_wire(stream))
    assert [(c.capture_id, c.complete) for c in got] == [(1, False), (2, True)]
    cap = got[0]
    assert cap.meta == {"n_announced": 100.0, "n_received": 70.0}
    assert cap.points_m.shape == (70, 3) and cap.intensity is not None and len(cap.intensity) == 70
    # The points that arrived, in order: 0–29 and 60–99.
    full, _ = assemble(over_the_wire(first))
    keep = np.r_[0:30, 60:100]
    assert np.array_equal(cap.points_m, full[0].points_m[keep])
    assert asm.stats["captures_incomplete"] == 1 and asm.stats["captures_complete"] == 1


def test_timeout_flush_orphans_repeats_and_bounds() -> None:
    msgs = some_capture(65, cid=4)
    asm = CaptureAssembler(timeout_s=1.0)
    assert asm.feed(msgs[0], 10.0) == [] and asm.feed(msgs[1], 10.2) == []
    assert asm.feed(msgs[1], 10.3) == []  # a repeated chunk changes nothing
    assert asm.stats["capture_chunks_repeated"] == 1
    assert asm.expire(11.0) == []  # 0.8 s since the last chunk: still waiting
    (cap,) = asm.expire(11.3)
    assert not cap.complete and len(cap.points_m) == 30
    # Chunks of a capture whose header is lost (or of one already handed on) are dropped.
    assert asm.feed(msgs[2], 12.0) == [] and asm.stats["capture_chunks_orphaned"] == 1
    # A header announcing more than the limit is refused, and its chunks with it.
    big = CaptureHeader(capture_id=9, n_points=MAX_CAPTURE_POINTS + 1)
    assert asm.feed(big, 13.0) == [] and not asm.pending
    assert asm.stats["capture_headers_refused"] == 1
    # Malformed chunks: lengths that disagree, or points beyond the announced count.
    asm.feed(CaptureHeader(capture_id=10, n_points=3, has_intensity=True), 14.0)
    bad = [
        CaptureChunk(
            capture_id=10, offset=0, x_mm=(1, 2), y_mm=(1,), z_mm=(1, 2), intensity=(0, 0)
        ),
        CaptureChunk(
            capture_id=10, offset=2, x_mm=(1, 2), y_mm=(1, 2), z_mm=(1, 2), intensity=(0, 0)
        ),
        CaptureChunk(capture_id=10, offset=0, x_mm=(1,), y_mm=(1,), z_mm=(1,)),  # no intensity
    ]
    for m in bad:
        assert asm.feed(m, 14.1) == []
    assert asm.stats["capture_chunks_invalid"] == 3
    (cap,) = asm.flush()
    assert not cap.complete and len(cap.points_m) == 0
    assert asm.flush() == []


def test_an_empty_capture_is_complete_at_its_header() -> None:
    msgs = some_capture(0, intensity=False)
    assert len(msgs) == 1
    (cap,), _ = assemble(msgs)
    assert cap.complete and cap.points_m.shape == (0, 3) and cap.intensity is None


def test_capture_messages_refuse_what_the_wire_cannot_carry() -> None:
    T = np.eye(4)
    kw = {"capture_id": 1, "run_id": 1, "index": 0, "t_s": 0.0, "camera_to_world": T}
    with pytest.raises(ValueError, match="points >"):
        capture_messages(points_m=np.zeros((MAX_CAPTURE_POINTS + 1, 3)), **kw)
    with pytest.raises(ValueError, match=r"32\.767"):
        capture_messages(points_m=np.array([[0.0, 0.0, 40.0]]), **kw)
    with pytest.raises(ValueError, match="intensities"):
        capture_messages(points_m=np.zeros((2, 3)), intensity=np.zeros(3, np.uint8), **kw)
