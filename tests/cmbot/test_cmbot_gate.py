"""The coarse-then-fine simulation gate against the dense reference.

``simulate_climb`` evaluates the arm clearances only at every ``coarse_stride``-th
sample and refines a window densely when a bound on the motion inside it says
the clearance could come within reach of the limit or of the smallest
clearance seen.  These tests hold it to the dense gate kept in
``tests/cmbot/_reference_gate.py``: the same verdicts, the same worst values
and the same violations (times, values, places) on passing climbs and on
climbs with a violation injected — an obstacle moved into the arm's path, a
too-fast replay, soles off the bar, the folded arm bent into the climber.
"""

from __future__ import annotations

import dataclasses
import tracemalloc

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import robots
from planners.cmbot import GaitParams, seed_guardrail
from planners.cmbot.arm import ArmKinematics
from planners.cmbot.distance import Cuboid
from planners.cmbot.gait import GaitTrajectory, build_trajectory, chain_limits, plan_footholds
from planners.cmbot.guardrail import Guardrail
from planners.cmbot.scene import arm_base_pose
from planners.cmbot.simulate import CoarseFineClearance, GateReport, _resample, simulate_climb
from tests.cmbot._reference_gate import _resample_dense, simulate_climb_dense

MODEL = robots.load_robot("cmbot")


@dataclasses.dataclass(frozen=True)
class Obstructed(Guardrail):
    """The guardrail with extra obstacle boxes (a bracket moved into the arm's path)."""

    extra: tuple[Cuboid, ...] = ()

    def boxes(self, x_lo: float = -np.inf, x_hi: float = np.inf) -> list[Cuboid]:
        return super().boxes(x_lo, x_hi) + list(self.extra)


@pytest.fixture(scope="module")
def short_climb() -> tuple[Guardrail, GaitTrajectory]:
    """One step (extension + contraction) on the seed guardrail."""
    g = seed_guardrail()
    p = GaitParams()
    moves = plan_footholds(g, 4.6, 4.84, chain_limits(MODEL, p), p.grid_m)
    _, tr = build_trajectory(MODEL, moves, 4.6, p)
    return g, tr


def _sphere_path(tr: GaitTrajectory, k: int) -> np.ndarray:
    """World centre of arm sphere ``k`` at the planned samples."""
    arm = ArmKinematics.from_model(MODEL)
    T_wr = np.broadcast_to(np.eye(4), (len(tr.times), 4, 4)).copy()
    T_wr[:, :3, 3] = tr.rear
    T_wk = arm_base_pose(MODEL, tr.q[:, :5], T_wr)
    c = arm.sphere_centers(arm.frames(tr.q[:, 5:]))[:, k]
    return np.einsum("tij,tj->ti", T_wk[:, :3, :3], c) + T_wk[:, :3, 3]


def assert_same_report(fast: GateReport, dense: GateReport) -> None:
    assert fast.samples == dense.samples and fast.dt_s == dense.dt_s
    assert [c.name for c in fast.checks] == [c.name for c in dense.checks]
    for a, b in zip(fast.checks, dense.checks, strict=True):
        assert a.passed == b.passed, a.name
        assert a.value == pytest.approx(b.value, abs=1e-12), a.name
        assert a.message == b.message, a.name  # worst value, time and place
    assert len(fast.violations) == len(dense.violations)
    for v, w in zip(fast.violations, dense.violations, strict=True):
        assert (v.check, v.t_s, v.where, v.limit) == (w.check, w.t_s, w.where, w.limit)
        assert v.value == pytest.approx(w.value, abs=1e-12)


def test_resample_matches_the_per_interval_linspace(short_climb):
    _, tr = short_climb
    for sub in (1, 2, 5):
        for a, b in zip(
            _resample(tr.times, tr.q, sub), _resample_dense(tr.times, tr.q, sub), strict=True
        ):
            assert np.array_equal(a, b)
    t = np.array([0.0, 0.3, 0.3, 1.0, 2.5, 4.0])
    v = np.sin(t)[:, None] * [1.0, 2.0]
    for a, b in zip(
        _resample(t, v, 3, smooth=True, breaks=(1.0,)),
        _resample_dense(t, v, 3, smooth=True, breaks=(1.0,)),
        strict=True,
    ):
        assert np.array_equal(a, b)


@pytest.mark.parametrize("stride", [1, 3, 16, 64])
def test_passing_climb_equals_dense(short_climb, stride):
    g, tr = short_climb
    dense = simulate_climb_dense(MODEL, g, tr)
    fast = simulate_climb(MODEL, g, tr, coarse_stride=stride, chunk=1000)
    assert dense.passed
    assert_same_report(fast, dense)
    if stride >= 16:  # and it did skip work
        assert fast.clearance_samples["arm_env"] < fast.samples / 2


@pytest.mark.parametrize("offset_m", [0.10, 0.125, 0.14, 0.30])
def test_obstacle_in_the_arm_path_equals_dense(short_climb, offset_m):
    """A 4 cm cube beside the arm's elbow sphere at mid-swing: at 0.10 m the
    clearance dips below the 5 cm margin, near 0.125–0.14 m it grazes it, at
    0.30 m it only sets the minimum."""
    g, tr = short_climb
    k = len(tr.times) // 4
    p = _sphere_path(tr, 10)[k] + np.array([0.0, offset_m, 0.0])
    obs = Obstructed(g.segments, g.posts, g.params, (Cuboid(p, np.full(3, 0.02), name="box"),))
    dense = simulate_climb_dense(MODEL, obs, tr)
    fast = simulate_climb(MODEL, obs, tr)
    assert_same_report(fast, dense)
    env = next(c for c in dense.checks if c.name == "arm_env_clearance")
    if offset_m == 0.10:
        assert not env.passed and "box" in env.message


def test_too_fast_replay_equals_dense(short_climb):
    """The same motion in a third of the time: joint speeds fail, and the
    larger steps between samples widen the refined windows — still exact."""
    g, tr = short_climb
    fast_tr = dataclasses.replace(tr, times=tr.times / 3.0)
    dense = simulate_climb_dense(MODEL, g, fast_tr)
    assert not next(c for c in dense.checks if c.name == "joint_speeds").passed
    assert_same_report(simulate_climb(MODEL, g, fast_tr), dense)


def test_soles_off_the_bar_equals_dense(short_climb):
    g, tr = short_climb
    off = dataclasses.replace(
        tr, rear=tr.rear + np.array([0.98, 0.0, 0.0]), front=tr.front + np.array([0.98, 0.0, 0.0])
    )
    dense = simulate_climb_dense(MODEL, g, off)
    assert not dense.passed
    assert_same_report(simulate_climb(MODEL, g, off), dense)


def test_arm_bent_into_the_climber_equals_dense(short_climb):
    """J7 driven towards the climbing links during the motion: self and/or
    guardrail clearance fail somewhere; violations identical to the dense gate."""
    g, tr = short_climb
    q = tr.q.copy()
    n = len(q)
    q[:, 6] += np.radians(120.0) * np.sin(np.linspace(0.0, np.pi, n)) ** 2
    bent = dataclasses.replace(tr, q=q)
    dense = simulate_climb_dense(MODEL, g, bent)
    fails = {c.name for c in dense.failed()}
    assert fails & {"self_clearance", "arm_env_clearance"}, dense.summary()
    assert_same_report(simulate_climb(MODEL, g, bent, coarse_stride=32), dense)


@pytest.mark.parametrize("n", [1, 2, 3, 40])
def test_very_short_motions_equal_dense(short_climb, n):
    """A few planning samples (one resampled sample, no window, one window)."""
    g, tr = short_climb
    k = len(tr.times) // 3
    cut = dataclasses.replace(
        tr,
        times=tr.times[k : k + n],
        q=tr.q[k : k + n],
        rear=tr.rear[k : k + n],
        front=tr.front[k : k + n],
        support=tr.support[k : k + n],
    )
    assert_same_report(simulate_climb(MODEL, g, cut), simulate_climb_dense(MODEL, g, cut))


def _dense_walk(values: np.ndarray, limit: float) -> tuple[float, int, np.ndarray]:
    return float(values.min()), int(values.argmin()), np.flatnonzero(values < limit)


@pytest.mark.parametrize("seed", range(6))
def test_coarse_fine_never_misses_on_random_lipschitz_signals(seed):
    """Synthetic clearances that move by at most their step bound, with dips
    to (and exactly onto) the limit, flat holds and ties: same minimum, same
    first argmin, same violations as evaluating every sample."""
    rng = np.random.default_rng(seed)
    n = int(rng.integers(50, 3000))
    steps = rng.uniform(0.0, 0.01, n - 1) * (rng.random(n - 1) < 0.7)  # holds: zero motion
    moves = steps * rng.uniform(-1.0, 1.0, n - 1)
    d = 0.2 + np.concatenate([[0.0], np.cumsum(moves)])
    d = np.round(d, 4)  # ties
    steps = steps + 1e-4  # the rounding is within the bound
    limit = float(np.quantile(d, rng.uniform(0.0, 0.2)))
    cf = CoarseFineClearance(n, limit, int(rng.integers(2, 40)))
    chunk = int(rng.integers(1, 500)) * cf.stride
    s = 0
    calls = 0
    while True:
        e = min(s + chunk, n - 1)

        def ev(k: np.ndarray, s: int = s) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
            nonlocal calls
            calls += len(k)
            return d[s + k], np.zeros(len(k), int), np.zeros(len(k), int)

        cf.add(s, steps[s:e], ev)
        if e >= n - 1:
            break
        s = e
    lo, k, bad = _dense_walk(d, limit)
    assert cf.value.min() == lo and int(cf.value.argmin()) == k
    assert np.array_equal(np.flatnonzero(cf.value < limit), bad)
    assert np.all(cf.value <= d + 1e-12)  # skipped samples hold a lower bound


def test_gate_memory_is_bounded_by_the_chunk(short_climb):
    """Peak memory of the gate does not grow with the number of samples: the
    per-sample FK, distance and flip-moment arrays live per chunk
    (GATE_CHUNK samples), only 1-D per-sample results and the resampled
    joints span the motion.  The same motion replayed 8× as finely costs
    about what the default replay does, and less than the dense gate at
    half that resolution."""
    g, tr = short_climb

    def peak(f, substeps: int) -> tuple[float, int]:
        tracemalloc.start()
        rep = f(MODEL, g, tr, substeps=substeps)
        p = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
        return p / 1e6, rep.samples

    base, n2 = peak(simulate_climb, 2)
    fine, n16 = peak(simulate_climb, 16)
    dense, n8 = peak(simulate_climb_dense, 8)
    assert n16 > 7 * n2 and n8 > 3 * n2
    assert fine < 1.5 * base + 10.0, (base, fine)
    assert fine < dense, (fine, dense)
    assert fine < 120.0, fine


@settings(max_examples=40, deadline=None, derandomize=True)
@given(
    seed=st.integers(0, 2**31 - 1),
    speed=st.floats(0.0, 0.2),
    window=st.integers(1, 70),
    cap=st.sampled_from([0.05, 0.3, 1.0]),
    masked=st.booleans(),
)
def test_windowed_static_clearance_equals_dense(seed, speed, window, cap, masked):
    """The arm gate's windowed min_clearance (Lipschitz bounds per window, exact
    distances of the surviving pairs only) returns the dense reference's
    clearance at every sample, and the sphere and box that give it wherever
    the clearance is below the cap (ties aside, the same pair)."""
    from scipy.spatial.transform import Rotation

    from planners.cmbot.simulate import min_clearance
    from tests.cmbot._reference_gate import min_clearance_dense

    rng = np.random.default_rng(seed)
    T, N, M = 150, 9, 7
    start = rng.uniform(-0.6, 0.6, (N, 3))
    steps = rng.normal(size=(T, N, 3)) * speed / np.sqrt(3)
    centers = start + np.cumsum(steps, axis=0)  # random walks, some through the boxes
    radii = rng.uniform(0.0, 0.08, N)
    boxes = (
        rng.uniform(-0.6, 0.6, (M, 3)),
        rng.uniform(0.02, 0.4, (M, 3)),
        Rotation.random(M, random_state=seed % 1000).as_matrix(),
    )
    mask = rng.random((N, M)) < 0.8 if masked else None
    got = min_clearance(centers, radii, boxes, mask=mask, cap=cap, window=window)
    ref = min_clearance_dense(centers, radii, boxes, mask=mask, cap=cap)
    np.testing.assert_allclose(got[0], ref[0], rtol=0, atol=1e-12)
    below = ref[0] < cap
    assert np.array_equal(got[1][below], ref[1][below])
    assert np.array_equal(got[2][below], ref[2][below])


@settings(max_examples=30, deadline=None, derandomize=True)
@given(seed=st.integers(0, 2**31 - 1), speed=st.floats(0.0, 0.2), window=st.integers(1, 70))
def test_windowed_self_clearance_equals_dense(seed, speed, window):
    """min_pair_clearance (the arm gate's self-clearance) equals the dense
    distance of every listed pair at every sample, and names the same pair."""
    from planners.cmbot.simulate import min_pair_clearance

    rng = np.random.default_rng(seed)
    T, N = 120, 10
    centers = rng.uniform(-0.5, 0.5, (N, 3)) + np.cumsum(
        rng.normal(size=(T, N, 3)) * speed / np.sqrt(3), axis=0
    )
    radii = rng.uniform(0.0, 0.1, N)
    pairs = np.argwhere(np.triu(rng.random((N, N)) < 0.6, 1))
    d, k = min_pair_clearance(centers, radii, pairs, window=window)
    dense = (
        np.linalg.norm(centers[:, pairs[:, 0]] - centers[:, pairs[:, 1]], axis=-1)
        - radii[pairs[:, 0]]
        - radii[pairs[:, 1]]
    )
    np.testing.assert_allclose(d, dense.min(axis=1), rtol=0, atol=1e-12)
    assert np.array_equal(k, dense.argmin(axis=1))


def _random_frames(rng: np.random.Generator, T: int, G: int, speed: float) -> np.ndarray:
    """(T,G,4,4) rigid frames drifting and turning over time."""
    from scipy.spatial.transform import Rotation

    rot = Rotation.from_rotvec(
        (rng.normal(size=(G, 3)) + np.cumsum(rng.normal(size=(T, G, 3)) * speed, axis=0)).reshape(
            -1, 3
        )
    ).as_matrix()
    F = np.broadcast_to(np.eye(4), (T, G, 4, 4)).copy()
    F[..., :3, :3] = rot.reshape(T, G, 3, 3)
    F[..., :3, 3] = rng.uniform(-0.3, 0.3, (G, 3)) + np.cumsum(
        rng.normal(size=(T, G, 3)) * speed, axis=0
    )
    return F


@settings(max_examples=40, deadline=None, derandomize=True)
@given(
    seed=st.integers(0, 2**31 - 1),
    speed=st.floats(0.0, 0.1),
    window=st.integers(1, 60),
    cap=st.sampled_from([0.05, 0.3, 1.0]),
    groups=st.integers(1, 4),
    per_group=st.booleans(),
    per_group_local=st.booleans(),
)
def test_culled_clearance_equals_brute_force(
    seed, speed, window, cap, groups, per_group, per_group_local
):
    """culled_clearance (windowed Lipschitz culling in each group's moving
    frame, exact distances of the surviving pairs in the world) against every
    sphere–box pair evaluated in the world: the same capped clearance per
    sample, the same sphere and box wherever it is below the cap, and the same
    capped minimum per group and sphere — or, from the groups' frames
    (``per_group_local``), a lower bound of it within the slack."""
    from planners.cmbot.distance import point_box_closed_form
    from planners.cmbot.simulate import _CULL_SLACK_M, culled_clearance

    rng = np.random.default_rng(seed)
    T, S, M = 90, 8, 9
    F = _random_frames(rng, T, groups, speed)
    group = rng.integers(0, groups, M)
    origin = _random_frames(rng, 1, M, 0.0)[0]  # each box in its group's frame
    half = rng.uniform(0.02, 0.3, (M, 3))
    radii = rng.uniform(0.0, 0.08, S)
    world = rng.uniform(-0.6, 0.6, (S, 3)) + np.cumsum(
        rng.normal(size=(T, S, 3)) * speed / np.sqrt(3), axis=0
    )
    Tb = F[:, group] @ origin  # (T,M,4,4) world boxes
    bc, bR = Tb[..., :3, 3], Tb[..., :3, :3]
    local = np.einsum("tgji,tgsj->tgsi", F[..., :3, :3], world[:, None] - F[:, :, None, :3, 3])

    def pairs(rows: np.ndarray, si: np.ndarray, bi: np.ndarray) -> np.ndarray:
        rel = world[rows][:, si] - bc[rows][:, bi]
        d, _ = point_box_closed_form(rel, half[bi], bR[rows][:, bi], directions=False)
        return d - radii[si]

    out, sph, box, per = culled_clearance(
        local,
        radii,
        (origin[:, :3, 3], half, origin[:, :3, :3]),
        group,
        pairs,
        cap=cap,
        window=window,
        per_group=per_group,
        per_group_local=per_group_local,
    )
    every = np.broadcast_to(np.arange(S)[:, None], (S, M)).ravel()
    boxes = np.broadcast_to(np.arange(M)[None, :], (S, M)).ravel()
    dense = pairs(np.arange(T), every, boxes).reshape(T, S, M)
    flat = dense.reshape(T, -1)
    np.testing.assert_allclose(out, np.minimum(flat.min(axis=1), cap), rtol=0, atol=1e-12)
    below = flat.min(axis=1) < cap
    k = flat.argmin(axis=1)
    assert np.array_equal(sph[below], (k // M)[below])
    assert np.array_equal(box[below], (k % M)[below])
    if per_group:
        assert per is not None
        ref = np.full((T, groups, S), cap)
        for g in range(groups):
            if np.any(group == g):
                ref[:, g] = np.minimum(dense[:, :, group == g].min(axis=2), cap)
        ref = ref.reshape(T, -1)
        if per_group_local:
            assert np.all(per <= ref + 1e-12)
            assert np.all(per >= ref - _CULL_SLACK_M - 1e-12)
        else:
            np.testing.assert_allclose(per, ref, rtol=0, atol=1e-12)
    else:
        assert per is None
