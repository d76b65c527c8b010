"""Climbing-mechanism kinematics (Eq. 1–8) and the compound-cycloid trajectory (Eq. 11)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import robots
from planners.cmbot.climbing_kinematics import (
    climber_fk,
    climber_fk_explicit,
    climber_ik,
    climber_ik_batch,
    foot_angles,
    wrap_angle,
)
from planners.cmbot.foot_trajectory import compound_cycloid
from planners.errors import InvalidInputError, UnreachableError

MODEL = robots.load_robot("cmbot")
L1 = MODEL.params["climber"]["l1"]
L2 = MODEL.params["climber"]["l2"]
LIM = MODEL.climber.joint_limits


def test_explicit_equations_match_chain():
    """Corrected Eq. 3–5 equal the D-H product of Eq. 1 for arbitrary joints (φy ≠ 0 too)."""
    q = np.random.default_rng(0).uniform(-np.pi, np.pi, (500, 5))
    assert np.allclose(climber_fk_explicit(q, L1, L2), climber_fk(q, L1, L2)[:, :3, 3], atol=1e-12)


def test_foot_angles_eq6_eq7():
    """Eq. 6–7 (corrected): the swing sole's rotation is Rz(θ1)·Ry(φy)·Rz(θ5) with φy = −(θ2+θ3+θ4)."""
    q = np.random.default_rng(1).uniform(-np.pi, np.pi, (200, 5))
    R = climber_fk(q, L1, L2)[:, :3, :3]
    phi_y, _phi_z = foot_angles(q)
    ok = np.abs(np.sin(phi_y)) < 1e-9
    # z axis of the sole: (c1·sinφy, s1·sinφy, cosφy)
    z = np.stack(
        [np.cos(q[:, 0]) * np.sin(phi_y), np.sin(q[:, 0]) * np.sin(phi_y), np.cos(phi_y)], -1
    )
    assert np.allclose(R[:, :, 2], z, atol=1e-12)
    q0 = q.copy()
    q0[:, 3] = -q0[:, 1] - q0[:, 2]  # φy = 0
    R0 = climber_fk(q0, L1, L2)[:, :3, :3]
    yaw = np.arctan2(R0[:, 1, 0], R0[:, 0, 0])
    assert np.allclose(wrap_angle(yaw - (q0[:, 0] + q0[:, 4])), 0.0, atol=1e-12)
    assert not ok.all()  # the random set exercised φy ≠ 0 as well


@settings(max_examples=400, deadline=None)
@given(
    rho=st.floats(0.0, 2 * L2, allow_nan=False),
    elev=st.floats(-np.pi / 2, np.pi / 2),
    az=st.floats(-np.pi, np.pi),
    phi_z=st.floats(-np.pi, np.pi),
)
def test_fk_of_ik_is_identity_over_reachable_set(rho, elev, az, phi_z):
    """FK(IK(p)) = p to 1e-9 for every p the φy = 0 IK accepts; it accepts every
    p within 2·l2 off the J1 axis whose knee-up solution is inside the limits."""
    p = rho * np.array([np.cos(elev) * np.cos(az), np.cos(elev) * np.sin(az), np.sin(elev)])
    q, ok = climber_ik_batch(p, phi_z, L1, L2, LIM)
    if not ok:
        # Refused: off-axis points must really violate a joint limit.
        q_free, ok_free = climber_ik_batch(p, phi_z, L1, L2, None)
        if ok_free:
            assert not MODEL.climber.within_limits(q_free)
        else:
            assert np.hypot(p[0], p[1]) <= 1e-9 or rho > 2 * L2
        return
    T = climber_fk(q, L1, L2)
    assert np.linalg.norm(T[:3, 3] - p) < 1e-9
    assert abs(T[2, 2] - 1.0) < 1e-12  # φy = 0: sole parallel to the stance sole
    assert abs(wrap_angle(np.arctan2(T[1, 0], T[0, 0]) - phi_z)) < 1e-9


@settings(max_examples=300, deadline=None)
@given(
    t1=st.floats(-np.pi + 1e-3, np.pi - 1e-3),
    t2=st.floats(-0.5, 3.0),
    t3=st.floats(-2.9, -0.05),
    t5=st.floats(-np.pi + 1e-3, np.pi - 1e-3),
)
def test_ik_of_fk_recovers_knee_up_joints(t1, t2, t3, t5):
    """IK(FK(q)) = q for knee-up joint vectors with φy = 0 whose foot is ahead of J1 (r > 0)."""
    q = np.array([t1, t2, t3, -t2 - t3, t5])
    r = L2 * np.cos(t2) + L2 * np.cos(t2 + t3)
    if r < 1e-6:
        return
    T = climber_fk(q, L1, L2)
    q2 = climber_ik(T[:3, 3], float(np.arctan2(T[1, 0], T[0, 0])), L1, L2)
    assert np.allclose(wrap_angle(q2 - q), 0.0, atol=1e-8)


def test_printed_eq8_disagrees_and_corrected_matches():
    """The printed Eq. 8 (py in θ3, θ2 = θ3/2 − arcsin(pz/√(px²+py²)), θ4 = θ2 − θ3)
    does not reproduce a test target; the corrected form does."""
    p = np.array([0.35, 0.08, 0.05])
    q = climber_ik(p, 0.0, L1, L2)
    assert np.linalg.norm(climber_fk(q, L1, L2)[:3, 3] - p) < 1e-12
    px, py, pz = p
    t1 = np.arctan(py / px)
    c1 = np.cos(t1)
    arg = (py**2 + (pz * c1) ** 2 - 2 * (L2 * c1) ** 2) / (2 * (L2 * c1) ** 2)
    t3 = np.arccos(np.clip(arg, -1, 1))
    t2 = t3 / 2 - np.arcsin(pz / np.hypot(px, py))
    t4 = t2 - t3
    printed = np.array([t1, t2, t3, t4, 0.0])
    assert np.linalg.norm(climber_fk(printed, L1, L2)[:3, 3] - p) > 1e-2


def test_ik_refuses_with_reason():
    with pytest.raises(UnreachableError, match="exceeds the reach"):
        climber_ik(np.array([2 * L2 + 0.01, 0, 0]), 0.0, L1, L2)
    with pytest.raises(UnreachableError, match="J1 axis"):
        climber_ik(np.array([0.0, 0.0, 0.2]), 0.0, L1, L2)
    with pytest.raises(InvalidInputError):
        climber_ik(np.array([np.nan, 0, 0]), 0.0, L1, L2)


# --------------------------------------------------------------- Eq. 11
S, H, D, TB = 0.24, 0.05, 0.0, 10.0


def test_cycloid_endpoints_apex_and_smoothness():
    t = np.linspace(0, TB, 20001)
    pos, vel, acc = compound_cycloid(t, S, H, D, TB)
    assert np.allclose(pos[0], 0.0) and np.allclose(pos[-1], [S, D, 0.0], atol=1e-12)
    assert abs(pos[:, 2].max() - H) < 1e-9 and abs(t[np.argmax(pos[:, 2])] - TB / 2) < 1e-3
    assert np.all(pos[:, 2] >= -1e-15)
    assert np.all(np.diff(pos[:, 0]) >= 0)  # never steps back
    # analytic derivatives agree with central differences (and there are no jumps)
    dt = t[1] - t[0]
    v_fd = np.gradient(pos, dt, axis=0)
    a_fd = np.gradient(vel, dt, axis=0)
    assert np.allclose(v_fd[1:-1], vel[1:-1], atol=1e-6)
    assert np.allclose(a_fd[1:-1], acc[1:-1], atol=1e-5)


@pytest.mark.parametrize("S_,D_", [(0.24, 0.0), (-0.24, 0.0), (0.3, 0.02)])
def test_cycloid_rest_at_liftoff_and_touchdown_numerically(S_, D_):
    """Velocity and acceleration vanish at t = 0 and t = Tb (finite differences of positions only)."""
    h = 1e-4
    for t0, sgn in ((0.0, 1.0), (TB, -1.0)):
        ts = t0 + sgn * h * np.arange(4)
        p = compound_cycloid(ts, S_, H, D_, TB)[0]
        v = (p[1] - p[0]) / h
        a = (p[2] - 2 * p[1] + p[0]) / h**2
        assert np.all(np.abs(v) < 1e-6), v
        assert np.all(np.abs(a) < 1e-3), a
    # extension and contraction phases both use it: the mirrored step as well
    p = compound_cycloid(np.array([TB]), S_, H, D_, TB)[0][0]
    assert np.allclose(p, [S_, D_, 0.0])


def test_cycloid_rejects_bad_parameters():
    with pytest.raises(InvalidInputError):
        compound_cycloid(np.zeros(1), S, H, D, 0.0)
    with pytest.raises(InvalidInputError):
        compound_cycloid(np.zeros(1), S, -1.0, D, TB)
