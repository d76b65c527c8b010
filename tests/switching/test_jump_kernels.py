"""Batched validity / kinematics kernels of the inch-worm jump
against the reference copies of the former ones
(``tests/switching/_reference_collision.py``): FK equal, clearances equal
below the 0.1 m cap (and both ≥ it above), validity decided identically
(also at other margins), batched IK tracks equal to one-at-a-time tracks,
and the landing search returning the same landings."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import robots
from planners.switching import decide_mode
from planners.switching import jump as J
from planners.switching.scenes import make_scene
from tests.switching import _reference_collision as ref

ARA = robots.load_robot("ara")
ROB = J.JumpRobot.from_model(ARA)
LO, HI = ROB.joint_limits[:, 0], ROB.joint_limits[:, 1]


@pytest.fixture(scope="module")
def cx():
    sc = make_scene("perpendicular", 0)
    d = decide_mode(sc.points, camera_to_base=sc.camera_to_base, base_height=0.0, foot=(0.18, 0.12))
    return J._jump_context(ARA, d.foothold_candidates, d.points, 0.0, J.JumpParams()), d


def _configs(rng: np.random.Generator, n: int) -> np.ndarray:
    """Uniform in (slightly beyond) the limits, and near P_conv / mobile
    (where the arm is close to the surfaces and to itself)."""
    parts = [rng.uniform(LO - 0.05, HI + 0.05, (n, 6))]
    for q, sig in ((ROB.q_conv, 0.1), (ROB.q_conv, 0.4), (ROB.q_mobile, 0.05), (ROB.q_mobile, 0.3)):
        parts.append(q + rng.normal(0.0, sig, (n, 6)))
    return np.vstack(parts)


def test_fk_all_equals_reference():
    Q = np.random.default_rng(0).uniform(-4, 4, (500, 6))
    np.testing.assert_allclose(ARA.fk_all(Q), ref.fk_all_reference(ARA, Q), rtol=0, atol=1e-14)
    np.testing.assert_allclose(
        ARA.fk_all(Q[3]), ref.fk_all_reference(ARA, Q[3]), rtol=0, atol=1e-14
    )


def _checkers(ctx, d):
    W1 = ctx.foot1_start
    target = d.foothold_candidates[0]
    return [
        ctx.checker(0, np.eye(4), None),
        ctx.checker(0, np.eye(4), ctx.zone(target)),
        ctx.checker(0, np.eye(4), ctx.zone(ctx.foot1_start)),
        ctx.checker(1, W1, None),
        ctx.checker(1, W1, ctx.zone(ctx.foot2_start)),
    ]


def _assert_same(chk, Q):
    s_ref, c_ref = ref.clearances_reference(chk, Q)
    s_new, c_new = chk.clearances(Q)
    np.testing.assert_array_equal(np.minimum(s_new, J._CAP), np.minimum(s_ref, J._CAP))
    np.testing.assert_array_equal(np.minimum(c_new, J._CAP), np.minimum(c_ref, J._CAP))
    assert np.all(c_new[c_ref >= J._CAP] >= J._CAP)
    np.testing.assert_array_equal(chk.valid(Q), ref.valid_reference(chk, Q))


def test_clearances_and_validity_equal_reference(cx):
    ctx, d = cx
    rng = np.random.default_rng(1)
    n_valid = n_invalid = 0
    for chk in _checkers(ctx, d):
        Q = _configs(rng, 60)
        _assert_same(chk, Q)
        v = chk.valid(Q)
        n_valid, n_invalid = n_valid + int(v.sum()), n_invalid + int((~v).sum())
        for k in range(0, 40, 7):  # small batches (OMPL's single states, segments)
            _assert_same(chk, Q[k : k + 1 + k % 5])
    assert n_valid > 100 and n_invalid > 100  # both outcomes exercised


@pytest.mark.parametrize("margins", [(0.0, 0.0), (0.03, 0.01), (0.08, 0.05), (0.0, 0.09)])
def test_validity_equal_reference_at_other_margins(cx, margins):
    ctx, d = cx
    cm, sm = margins
    params = J.JumpParams(clearance_margin_m=cm, self_margin_m=sm)
    rng = np.random.default_rng(2)
    for chk in _checkers(ctx, d)[::2]:
        chk.params = params
        Q = _configs(rng, 40)
        np.testing.assert_array_equal(chk.valid(Q), ref.valid_reference(chk, Q))


@settings(max_examples=30, deadline=None)
@given(
    st.lists(st.floats(-1.0, 1.0), min_size=6, max_size=6),
    st.floats(0.0, 0.5),
    st.integers(0, 4),
    st.integers(0, 2**31 - 1),
)
def test_validity_equal_reference_hypothesis(cx, u, spread, which, seed):
    # Configurations around an arbitrary point of the joint box, every checker.
    ctx, d = cx
    chk = _checkers(ctx, d)[which]
    centre = (LO + HI) / 2 + np.asarray(u) * (HI - LO) / 2
    Q = centre + np.random.default_rng(seed).normal(0.0, spread + 1e-3, (16, 6))
    _assert_same(chk, Q)


def test_ik_track_batch_equals_ik_track(cx):
    _, d = cx
    W = d.foothold_candidates[0]
    up = J._cartesian_line(W, J._translate(W, W[:3, 2] * 0.04), 6)
    sols = ROB.ik(W, None, 0)
    assert len(sols) >= 3
    batch = ROB.ik_track_batch(up, sols)
    assert sum(t is not None for t in batch) >= 1
    for q, tb in zip(sols, batch, strict=True):
        t1 = ROB.ik_track(up, q)
        assert (t1 is None) == (tb is None)
        if t1 is not None:
            np.testing.assert_allclose(tb, t1, rtol=0, atol=1e-9)


def test_landing_configs_equal_reference(cx):
    ctx, d = cx
    p = ctx.params
    free2 = ctx.checker(0, np.eye(4), None)
    for W in d.foothold_candidates[:2]:
        zone = ctx.checker(0, np.eye(4), ctx.zone(W))
        hover = J._translate(W, W[:3, 2] * p.standoff_m)
        new = J._landing_configs(ROB, W, hover, free2, zone, p, 0)
        old = ref.landing_configs_reference(ROB, W, hover, free2, zone, p, 0)
        assert len(new) == len(old)
        for (g1, a1), (g0, a0) in zip(new, old, strict=True):
            np.testing.assert_allclose(g1, g0, rtol=0, atol=1e-9)
            np.testing.assert_allclose(a1, a0, rtol=0, atol=1e-9)


@pytest.mark.parametrize("anchor", [0, 1])
def test_steps_bound_every_sphere_displacement(cx, anchor):
    """The re-check's step bound (:meth:`_Checker.steps`) is how far
    any sphere centre of either cover moves between consecutive samples, and
    the scene / self parts equal :meth:`clearances`."""
    context, _ = cx
    W = np.eye(4) if anchor == 0 else context.rob.fk_all(ROB.q_conv[None])[0, -1]
    chk = context.checker(anchor, W, None)
    rng = np.random.default_rng(anchor)
    Q = ROB.q_conv + np.cumsum(rng.normal(0.0, 0.03, (300, 6)), axis=0)
    steps = chk.steps(Q)
    F = chk.world(Q)
    for cov in (ROB.cover, ROB.self_cover):
        C = cov.world(F)
        moved = np.linalg.norm(np.diff(C, axis=0), axis=2).max(axis=1)
        assert np.all(steps >= moved - 1e-12)
    moved_any = np.max(
        [
            np.linalg.norm(np.diff(c.world(F), axis=0), axis=2).max(axis=1)
            for c in (ROB.cover, ROB.self_cover)
        ],
        axis=0,
    )
    np.testing.assert_allclose(steps, moved_any, rtol=0, atol=1e-12)  # measured, so tight
    scene, self_c = chk.clearances(Q)
    np.testing.assert_array_equal(chk.scene_clearances(Q), scene)
    np.testing.assert_array_equal(chk.self_clearances(Q), self_c)


@pytest.mark.parametrize("batch", [1, 3, 4, 17])
def test_sphere_cover_world_per_link_equals_the_gather(batch):
    """SphereCover.world transforms per link from 4 configurations on; both
    paths give the gathered-frame result."""
    rng = np.random.default_rng(batch)
    Q = ROB.q_conv + rng.normal(0.0, 0.3, (batch, 6))
    F = ARA.fk_all(Q)
    for cov in (ROB.cover, ROB.self_cover):
        G = F[:, cov.link]
        want = np.einsum("bsij,sj->bsi", G[..., :3, :3], cov.centre) + G[..., :3, 3]
        np.testing.assert_allclose(cov.world(F), want, rtol=0, atol=1e-12)


@settings(max_examples=40, deadline=None)
@given(
    rows=st.integers(1, 6),
    p_a=st.floats(0.0, 1.0),
    p_b=st.floats(0.0, 1.0),
    seed=st.integers(0, 2**16),
)
def test_needed_pairs_equal_the_pair_mask(cx, rows, p_a, p_b, seed):
    """The (row, block) join lists exactly the sphere pairs whose two spheres
    are both needed, each once: brute force over every block's product."""
    ctx, _ = cx
    sp = ctx.checker(0, np.eye(4), None).self_arrays
    rng = np.random.default_rng(seed)
    needA = rng.random((rows, len(sp.sa))) < p_a
    needB = rng.random((rows, len(sp.sb))) < p_b
    r_idx, i, j, key = J._needed_pairs(
        needA, needB, (sp.sa, sp.sa_block), (sp.sb, sp.sb_block), len(sp.a)
    )
    want = set()
    for r in range(rows):
        for ca in np.flatnonzero(needA[r]):
            for cb in np.flatnonzero(needB[r]):
                if sp.sa_block[ca] == sp.sb_block[cb]:
                    want.add(
                        (r, int(sp.sa[ca]), int(sp.sb[cb]), r * len(sp.a) + int(sp.sa_block[ca]))
                    )
    got = list(zip(r_idx.tolist(), i.tolist(), j.tolist(), key.tolist(), strict=True))
    assert len(got) == len(set(got))
    assert set(got) == want
    assert np.all(np.diff(key) >= 0)  # reduceat over runs of equal keys


@settings(max_examples=12, deadline=None)
@given(anchor=st.sampled_from([0, 1]), sigma=st.floats(0.005, 0.08), seed=st.integers(0, 2**16))
def test_self_steps_bound_the_self_clearance_change(cx, anchor, sigma, seed):
    """The self re-check's step bound holds for the clearance it bounds
    (recomputed by brute force over every sphere pair) and, measured in the
    links' own frames, does not depend on where the anchor stands."""
    context, _ = cx
    W = np.eye(4) if anchor == 0 else context.rob.fk_all(ROB.q_conv[None])[0, -1]
    chk = context.checker(anchor, W, None)
    rng = np.random.default_rng(seed)
    Q = np.clip(ROB.q_conv + np.cumsum(rng.normal(0.0, sigma, (60, 6)), axis=0), LO, HI)
    bound = chk.self_steps(Q)
    _, exact = ref.clearances_reference(chk, Q)  # capped at _CAP like the re-check's values
    assert np.all(np.abs(np.diff(exact)) <= bound + 1e-12)
    other = context.checker(1 - anchor, np.eye(4) if anchor else W, None)
    np.testing.assert_allclose(other.self_steps(Q), bound, rtol=0, atol=1e-12)


@settings(max_examples=40, deadline=None)
@given(
    n_pts=st.integers(1, 400),
    spacing=st.sampled_from([0.004, 0.01, 0.03, 0.1]),
    reach=st.floats(0.0, 0.4),
    seed=st.integers(0, 2**16),
)
def test_maybe_within_is_a_superset_of_brute_force(n_pts, spacing, reach, seed):
    """The thinned-tree test never says "far" of a centre that has an
    obstacle point within its reach (brute force over every point), and is
    not vacuous: a centre beyond reach + v·√3 of every point is "far"."""
    from planners.switching.collision import _THIN_M, PointObstacles

    rng = np.random.default_rng(seed)
    pts = rng.integers(0, 12, (n_pts, 3)) * spacing + rng.normal(0, spacing / 4, (n_pts, 3))
    obs = PointObstacles(pts)
    centres = rng.uniform(pts.min(0) - 0.3, pts.max(0) + 0.3, (7, 5, 3))
    radii = rng.uniform(0.0, reach, (7, 5))
    got = obs.maybe_within(centres, radii)
    d = np.linalg.norm(centres[..., None, :] - pts, axis=-1).min(axis=-1)
    assert got.shape == (7, 5)
    assert np.all(got[d < radii])  # superset: nothing within reach is called far
    assert not np.any(got[d >= radii + _THIN_M * np.sqrt(3.0) + 1e-12])
    assert not PointObstacles(np.zeros((0, 3))).maybe_within(centres, radii).any()
