"""Flip moment (Eq. 9) and counterweight (Eq. 10) against brute-force sums."""

from __future__ import annotations

import numpy as np

import robots
from planners.cmbot.arm import ArmKinematics
from planners.cmbot.balance import (
    arm_mass_points,
    climber_mass_points,
    counterweight_angle,
    flip_moment,
    folded_arm,
    merge,
)
from planners.cmbot.climbing_kinematics import climber_ik_batch
from planners.cmbot.scene import arm_base_pose

MODEL = robots.load_robot("cmbot")
ARM = ArmKinematics.from_model(MODEL)
C = MODEL.params["climber"]
Q_FOLD = np.radians(MODEL.params["arm"]["fold_deg"])


def _stance(d: float, lift: float = 0.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    q, ok = climber_ik_batch(
        np.array([[d, 0.0, lift]]), 0.0, C["l1"], C["l2"], MODEL.climber.joint_limits
    )
    assert ok.all()
    T_wr = np.eye(4)[None]
    return q, T_wr, arm_base_pose(MODEL, q, T_wr)


def test_flip_moment_equals_brute_force_sum():
    rng = np.random.default_rng(0)
    T = 7
    pos = rng.normal(size=(T, 4, 3))
    from planners.cmbot.balance import MassPoints

    pts = MassPoints(pos, np.array([1.0, 2.0, 3.0, 4.0]), ["a", "b", "c", "d"], np.zeros(4, bool))
    pivot = rng.normal(size=(T, 3))
    dt = 0.1
    M = flip_moment(pts, pivot, dt)
    acc = np.gradient(np.gradient(pos, dt, axis=0), dt, axis=0)
    for t in range(T):
        ref = np.zeros(3)
        for k in range(4):
            ref += np.cross(
                pos[t, k] - pivot[t], pts.masses[k] * (np.array([0, 0, -9.81]) - acc[t, k])
            )
        assert np.allclose(M[t], ref)


def test_vertical_position_puts_the_folded_arm_over_j6():
    _q, _T_wr, T_wk = _stance(0.42)
    fa = folded_arm(ARM, Q_FOLD)
    th = fa.vertical_angle(T_wk[:, :3, :3])
    qa = Q_FOLD.copy()
    qa[0] = th[0]
    pts = arm_mass_points(ARM, qa[None], T_wk)
    com = pts.masses @ pts.positions[0] / pts.masses.sum()
    # arm-base mass sits on the axis; the rest must be straight above J6
    assert abs(com[0] - T_wk[0, 0, 3]) < 1e-9
    assert com[2] > T_wk[0, 2, 3]


def test_eq10_counterweight_cancels_the_static_flip_moment():
    """Quasi-static: with θ6 from Eq. 10 (unsaturated), M_y about the rear sole vanishes."""
    q, T_wr, T_wk = _stance(0.30)
    fa = folded_arm(ARM, Q_FOLD)
    R = T_wk[:, :3, :3]
    th_v = fa.vertical_angle(R)
    qa = Q_FOLD.copy()
    qa[0] = th_v[0]
    cl = climber_mass_points(MODEL, q, T_wr)
    pivot = np.zeros((1, 3))
    M_no = flip_moment(merge(cl, arm_mass_points(ARM, qa[None], T_wk)), pivot, None)
    # shrink the demand so the swing is not saturated, then check exact cancellation
    demand = 0.5 * fa.mass * 9.81 * fa.lever(R)[0]
    th = counterweight_angle(np.array([demand]), fa, R, np.radians(89.0))
    qa2 = qa.copy()
    qa2[0] = th[0]
    M2 = flip_moment(merge(cl, arm_mass_points(ARM, qa2[None], T_wk)), pivot, None)
    assert abs((M2[0, 1] - M_no[0, 1]) + demand) < 1e-9
    # and the seed's small-angle form θ6 − θv ≈ My/(m g l_e) holds for small demands
    small = 1e-3 * fa.mass * 9.81 * fa.lever(R)[0]
    th_s = counterweight_angle(np.array([small]), fa, R, np.radians(89.0))
    assert np.isclose(abs(th_s[0] - th_v[0]), 1e-3, rtol=1e-6)
