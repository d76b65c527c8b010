"""Arm FK/Jacobian (Table 2, Eq. 12–13), gradient projection (Eq. 14),
escape velocities (Eq. 15–20) and statics — against finite differences."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import robots
from planners.cmbot.arm import ArmKinematics, gradient_projection, pinv, rotation_error
from planners.cmbot.avoidance import AvoidanceParams, combine, escape_speed, escape_velocities

MODEL = robots.load_robot("cmbot")
ARM = ArmKinematics.from_model(MODEL)
angles = st.lists(st.floats(-np.pi, np.pi, allow_nan=False), min_size=7, max_size=7)


@settings(max_examples=60, deadline=None)
@given(q=angles)
def test_jacobian_matches_finite_differences(q):
    q = np.array(q)
    J = ARM.jacobian(q)
    h = 1e-6
    T0 = ARM.tool_pose(q)
    for i in range(7):
        dq = np.zeros(7)
        dq[i] = h
        Tp, Tm = ARM.tool_pose(q + dq), ARM.tool_pose(q - dq)
        v = (Tp[:3, 3] - Tm[:3, 3]) / (2 * h)
        w = rotation_error(Tp[:3, :3], T0[:3, :3]) / h  # rotation per unit angle, base frame
        assert np.allclose(J[:3, i], v, atol=1e-6)
        assert np.allclose(J[3:, i], w, atol=1e-5)


def test_sphere_jacobians_match_finite_differences():
    q = np.random.default_rng(2).uniform(-2, 2, 7)
    F = ARM.frames(q)
    C = ARM.sphere_centers(F)
    idx = np.arange(len(ARM.spheres))
    Jc = ARM.sphere_jacobians(F, C, idx)
    h = 1e-6
    for i in range(7):
        dq = np.zeros(7)
        dq[i] = h
        fd = (ARM.sphere_centers(ARM.frames(q + dq)) - ARM.sphere_centers(ARM.frames(q - dq))) / (
            2 * h
        )
        assert np.allclose(Jc[:, :, i], fd, atol=1e-6)


def test_gradient_projection_tracks_and_null_term_is_invisible():
    rng = np.random.default_rng(4)
    for _ in range(20):
        q = rng.uniform(-2, 2, 7)
        J = ARM.jacobian(q)
        v = rng.normal(size=6)
        Z = rng.normal(size=7)
        b0 = gradient_projection(J, v)
        b1 = gradient_projection(J, v, Z)
        assert np.allclose(J @ b0, v, atol=1e-8) and np.allclose(J @ b1, v, atol=1e-8)
        # J⁺v is the minimum-norm solution
        assert np.linalg.norm(b0) <= np.linalg.norm(b1) + 1e-12
        assert np.allclose(pinv(J), J.T @ np.linalg.inv(J @ J.T), atol=1e-8)


def test_eq15_escape_speed_profile():
    p = AvoidanceParams(d_s=0.15, v_max=0.3)
    d = np.array([-0.01, 0.0, 0.075, 0.15, 0.2])
    s = escape_speed(d, p.d_s, p.v_max)
    assert np.allclose(s, [0.3, 0.3, 0.15, 0.0, 0.0])
    assert np.all(np.diff(escape_speed(np.linspace(0, 0.15, 50), 0.15, 0.3)) <= 0)
    u = np.array([[0.0, 0.0, 1.0]])
    assert np.allclose(escape_velocities(np.array([0.075]), u, p), [[0, 0, 0.15]])


def test_eq20_keeps_the_tool_on_track_and_moves_spheres_away():
    rng = np.random.default_rng(5)
    q = np.radians([90, 45, 50, -85, 0, -15, 180])
    F = ARM.frames(q)
    J = ARM.jacobian_from_frames(F)
    C = ARM.sphere_centers(F)
    idx = np.array([10, 20])
    Jc = ARM.sphere_jacobians(F, C, idx)
    v = rng.normal(size=6) * 0.1
    s = np.array([[0.0, 0.1, 0.0], [0.0, 0.1, 0.0]])
    bt, bn = combine(J, v, Jc.reshape(-1, 7), s.reshape(-1), damping=0.0)
    assert np.allclose(J @ (bt + bn), v, atol=1e-8)  # Eq. 20 keeps the tool velocity
    # the null-space term is the least-squares best at the escape (Eq. 19)
    N = np.eye(7) - pinv(J) @ J
    A = Jc.reshape(-1, 7) @ N
    resid = lambda z: np.linalg.norm(Jc.reshape(-1, 7) @ (bt + N @ z) - s.reshape(-1))  # noqa: E731
    z_star = np.linalg.pinv(A, rcond=1e-10) @ (s.reshape(-1) - Jc.reshape(-1, 7) @ bt)
    assert np.allclose(N @ z_star, bn, atol=1e-8)
    for _ in range(20):
        assert resid(z_star) <= resid(z_star + rng.normal(size=7)) + 1e-12


@pytest.mark.parametrize("payload", [0.0, 5.0])
def test_gravity_torques_are_the_gradient_of_potential_energy(payload):
    """τ = ∂V/∂q with V = −Σ m g·r (independent check of −Σ J_mᵀ m g)."""
    g = np.array([-9.81, 0.0, 0.0])
    q = np.random.default_rng(6).uniform(-2, 2, 7)

    def V(qq):
        F = ARM.frames(qq)
        pts = [F[k, :3, :3] @ ARM.coms[k] + F[k, :3, 3] for k in range(8)]
        e = -sum(m * (g @ p) for m, p in zip(ARM.masses, pts, strict=True))
        return e - payload * (g @ F[-1, :3, 3])

    tau = ARM.gravity_torques(q, g, payload)
    h = 1e-6
    fd = np.array([(V(q + h * np.eye(7)[i]) - V(q - h * np.eye(7)[i])) / (2 * h) for i in range(7)])
    assert np.allclose(tau, fd, atol=1e-5)
