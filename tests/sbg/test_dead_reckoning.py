"""U-turn dead reckoning, seed 003 §3.3 Eq. 10–11."""

from __future__ import annotations

import math

import numpy as np
import pytest

from planners.sbg.dead_reckoning import dr_integrate, dr_step


def test_eq10_eq11_hand_case() -> None:
    # Start (0, 0, θ = 0 = heading up).  Step 1: v_l = v_r = 0.02 m/s, ΔT = 1 s:
    #   ΔX = 0.02·sin0 = 0, ΔZ = 0.02·cos0 = 0.02, Δθ = 0.
    # Step 2: v_l = 0.02, v_r = 0: ΔX = 0.01·sin0 = 0, ΔZ = 0.01, Δθ = 0.02/0.18 = 1/9 = 0.1111111 rad.
    # Step 3: v = 0.02 at θ = 1/9: ΔX = 0.02·sin(1/9) = 0.00221765,
    #   ΔZ = 0.02·cos(1/9) = 0.01987667.
    B = 0.18
    s = dr_step(0.0, 0.0, 0.0, 0.02, 0.02, B, 1.0)
    assert s == pytest.approx((0.0, 0.02, 0.0))
    s = dr_step(*s, 0.02, 0.0, B, 1.0)
    assert s == pytest.approx((0.0, 0.03, 1 / 9), abs=1e-12)
    s = dr_step(*s, 0.02, 0.02, B, 1.0)
    assert s == pytest.approx((0.00221765, 0.04987667, 1 / 9), abs=1e-8)


def test_vectorised_matches_steps() -> None:
    rng = np.random.default_rng(0)
    vl, vr = rng.uniform(-0.02, 0.02, 50), rng.uniform(-0.02, 0.02, 50)
    X, Z, th = dr_integrate(0.1, -0.2, 0.3, vl, vr, 0.18, 0.05)
    s = (0.1, -0.2, 0.3)
    for k in range(50):
        s = dr_step(*s, vl[k], vr[k], 0.18, 0.05)
        assert (X[k + 1], Z[k + 1], th[k + 1]) == pytest.approx(s, abs=1e-12)


def test_imu_yaw_replaces_encoder_yaw_in_turns() -> None:
    # An in-place 90° right turn whose encoders claim 100° (slip): with the IMU
    # increments the heading ends at exactly 90°.
    n = 100
    B, dT = 0.18, 0.1
    w_enc = math.radians(100.0) / (n * dT)
    vl, vr = np.full(n, w_enc * B / 2), np.full(n, -w_enc * B / 2)
    _, _, th_enc = dr_integrate(0.0, 0.0, 0.0, vl, vr, B, dT)
    _, _, th_imu = dr_integrate(
        0.0, 0.0, 0.0, vl, vr, B, dT, yaw_increments=np.full(n, math.radians(0.9))
    )
    assert math.degrees(th_enc[-1]) == pytest.approx(100.0)
    assert math.degrees(th_imu[-1]) == pytest.approx(90.0)
