"""DENSO VM-6083: URDF vs D-H chain, closed-form IK (all branches, least
change, accuracy), axisymmetric-tool IK, parameter file marks."""

from __future__ import annotations

import re

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from robots import load_robot
from robots.denso_vm6083 import PARAMS_PATH, select_least_change
from robots.kinematics import solve_ik_dls

ROBOT = load_robot("denso_vm6083")
LO, HI = ROBOT.joint_limits[:, 0], ROBOT.joint_limits[:, 1]


def _pose_err(A: np.ndarray, B: np.ndarray) -> tuple[float, float]:
    """Position error (mm) and rotation error (deg) between two poses."""
    dp = np.linalg.norm(A[:3, 3] - B[:3, 3]) * 1000.0
    c = np.clip((np.trace(A[:3, :3].T @ B[:3, :3]) - 1.0) / 2.0, -1.0, 1.0)
    return float(dp), float(np.degrees(np.arccos(c)))


joint_vectors = st.lists(st.floats(0.0, 1.0), min_size=6, max_size=6).map(
    lambda u: LO + np.asarray(u) * (HI - LO)
)


def test_description_matches_design_facts():
    assert ROBOT.joint_names == [f"joint{i}" for i in range(1, 7)]
    np.testing.assert_allclose(
        np.degrees(ROBOT.joint_limits),
        [[-170, 170], [-90, 135], [-80, 165], [-185, 185], [-120, 120], [-360, 360]],
    )
    np.testing.assert_allclose(ROBOT.d, [0.475, 0, 0, 0.445, 0, 0.09])
    np.testing.assert_allclose(ROBOT.a, [0.18, 0.385, -0.1, 0, 0, 0])
    np.testing.assert_allclose(ROBOT.alpha, [-np.pi / 2, 0, np.pi / 2, -np.pi / 2, np.pi / 2, 0])
    np.testing.assert_allclose(ROBOT.offset, [0, -np.pi / 2, np.pi / 2, 0, 0, 0])
    assert ROBOT.urdf_path.exists()


def test_params_file_marks_every_value():
    for line in PARAMS_PATH.read_text().splitlines():
        s = line.strip()
        if not s or s.startswith("#") or s.startswith("[") or s.startswith("name"):
            continue
        assert re.search(r"#\s*(seed|chosen)", s), f"unmarked value in params.toml: {s}"


def test_urdf_agrees_with_dh_chain():
    yourdfpy = pytest.importorskip("yourdfpy")
    urdf = yourdfpy.URDF.load(str(ROBOT.urdf_path))
    # same joint limits in the URDF
    for j, name in enumerate(ROBOT.joint_names):
        lim = urdf.joint_map[name].limit
        assert np.isclose(lim.lower, LO[j]) and np.isclose(lim.upper, HI[j])
    rng = np.random.default_rng(3)
    for _ in range(20):
        q = rng.uniform(LO, HI)
        urdf.update_cfg(q)
        for link in ("link1", "link2", "link3", "link4", "link5", "link6", "flange"):
            np.testing.assert_allclose(
                urdf.get_transform(link, "base_link"), ROBOT.fk(q, link), atol=1e-12
            )


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(joint_vectors)
def test_fk_ik_round_trip(q):
    T = ROBOT.fk(q)
    for q0 in (q, None):
        sol = ROBOT.ik(T, q0)
        assert sol is not None
        assert ROBOT.within_limits(sol)
        dp, dr = _pose_err(ROBOT.fk(sol), T)
        assert dp < 0.01 and dr < 0.01  # issue 5: 0.01 mm and 0.01°
    # with q itself as the reference the least change is (numerically) zero
    assert np.abs(ROBOT.ik(T, q) - q).max() < 1e-6


@settings(max_examples=100, deadline=None)
@given(joint_vectors)
def test_all_branches_reach_the_pose_and_the_choice_is_least_change(q):
    T = ROBOT.fk(q)
    Q, ok = ROBOT.ik_all(T, q)
    assert ok.any()
    for k in np.nonzero(ok)[0]:
        dp, dr = _pose_err(ROBOT.fk(Q[k]), T)
        assert dp < 0.01 and dr < 0.01
    q_ref = np.zeros(6)
    Q, ok = ROBOT.ik_all(T, q_ref)
    k = select_least_change(Q, ok, q_ref)
    d = np.abs(Q - q_ref)
    score = d.max(axis=1) + 1e-3 * np.linalg.norm(d, axis=1)
    assert score[k] == pytest.approx(score[ok].min())
    np.testing.assert_allclose(ROBOT.ik(T, q_ref), Q[k])


def test_closed_form_finds_every_numeric_solution():
    """Solutions found by DLS from random starts are all among ours."""
    rng = np.random.default_rng(11)
    for _ in range(8):
        q = rng.uniform(LO, HI)
        T = ROBOT.fk(q)
        Q, ok = ROBOT.ik_all(T, q)
        for s in range(3):
            qn = solve_ik_dls(ROBOT, T, rng.uniform(LO, HI), restarts=0, seed=s)
            if qn is None:
                continue
            # compare modulo 2π on J4/J6 (equivalent joint values)
            d = np.abs((Q[ok] - qn + np.pi) % (2 * np.pi) - np.pi)
            # near the wrist singularity only q4 + q6 is determined
            assert d.max(axis=1).min() < 1e-5 or abs(np.sin(qn[4])) < 1e-4


def test_unreachable_pose_returns_none():
    T = np.eye(4)
    T[:3, 3] = [2.0, 0.0, 0.5]  # beyond the 0.84 m reach
    assert ROBOT.ik(T) is None
    with pytest.raises(ValueError):
        ROBOT.ik(np.eye(3))


def test_axis_ik_keeps_j6_and_hits_position_and_axis():
    rng = np.random.default_rng(5)
    q = rng.uniform(LO, HI, size=(50, 6))
    F = ROBOT.frames(q)[:, -1]
    q_ref = np.array([0, -1.3, 2.8, 0, 0.5, 0.7])
    Q, ok = ROBOT.ik_axis(F[:, :3, 3], F[:, :3, 2], q_ref)
    assert ok.any(axis=1).all()
    for i in range(50):
        for k in np.nonzero(ok[i])[0]:
            T = ROBOT.fk(Q[i, k])
            assert Q[i, k, 5] == pytest.approx(0.7)
            assert np.linalg.norm(T[:3, 3] - F[i, :3, 3]) < 1e-8
            assert T[:3, 2] @ F[i, :3, 2] > 1 - 1e-10


def test_with_base_moves_the_chain():
    B = np.eye(4)
    B[:3, 3] = [0.5, 0.375, 0.37]
    placed = ROBOT.with_base(B)
    q = np.array([0.3, -0.2, 1.0, 0.4, -0.5, 0.1])
    np.testing.assert_allclose(placed.fk(q), B @ ROBOT.fk(q), atol=1e-12)
    sol = placed.ik(placed.fk(q), q)
    np.testing.assert_allclose(sol, q, atol=1e-9)
    assert np.allclose(ROBOT.base, np.eye(4))  # the original is untouched
