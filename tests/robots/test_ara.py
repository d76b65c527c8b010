"""ARA model: FK vs yourdfpy, Jacobian vs finite differences, IK round trips,
parameters file vs URDF."""

from __future__ import annotations

import numpy as np
import pytest
import yourdfpy
from hypothesis import given, settings
from hypothesis import strategies as st

import robots

ARA = robots.load_robot("ara")
LO, HI = ARA.joint_limits[:, 0], ARA.joint_limits[:, 1]


@pytest.fixture(scope="module")
def urdf() -> yourdfpy.URDF:
    return yourdfpy.URDF.load(str(ARA.urdf_path), build_scene_graph=True, load_meshes=False)


def _q(seed: int) -> np.ndarray:
    return np.random.default_rng(seed).uniform(LO, HI)


def test_structure_matches_seed():
    assert ARA.dof == 6
    # Seed §3.2: joints 2 and 5 about y, the others about z.
    axes = ["xyz"[int(np.argmax(np.abs(a)))] for a in ARA.joint_axes]
    assert axes == ["z", "y", "z", "z", "y", "z"]
    assert ARA.params["robot"]["joint_axes"] == axes
    np.testing.assert_allclose(ARA.fk(ARA.q_mobile)[:3, 3], [-0.5, 0, 0], atol=1e-12)


@pytest.mark.parametrize("seed", range(8))
def test_fk_matches_yourdfpy(urdf, seed):
    q = _q(seed)
    urdf.update_cfg(dict(zip(ARA.joint_names, q, strict=True)))
    frames = ARA.fk_all(q)
    for i, link in enumerate(ARA.link_names):
        ref = urdf.get_transform(link, "base_link")
        np.testing.assert_allclose(frames[i], ref, atol=1e-10, err_msg=link)
    np.testing.assert_allclose(
        ARA.camera_to_base, urdf.get_transform("camera_optical", "base_link"), atol=1e-12
    )


def test_batched_fk_equals_single():
    Q = np.array([_q(s) for s in range(5)])
    np.testing.assert_allclose(ARA.fk_all(Q), np.array([ARA.fk_all(q) for q in Q]), atol=1e-14)


@settings(max_examples=30, deadline=None)
@given(st.integers(0, 2**31 - 1))
def test_jacobian_matches_finite_differences(seed):
    q = _q(seed)
    J = ARA.jacobian(q)
    h = 1e-6
    T0 = ARA.fk(q)
    for i in range(6):
        dq = np.zeros(6)
        dq[i] = h
        Tp, Tm = ARA.fk(q + dq), ARA.fk(q - dq)
        v = (Tp[:3, 3] - Tm[:3, 3]) / (2 * h)
        dR = (Tp[:3, :3] - Tm[:3, :3]) / (2 * h) @ T0[:3, :3].T  # = [ω]×
        w = np.array([dR[2, 1], dR[0, 2], dR[1, 0]])
        np.testing.assert_allclose(J[:3, i], v, atol=1e-6)
        np.testing.assert_allclose(J[3:, i], w, atol=1e-6)


@settings(max_examples=25, deadline=None)
@given(st.integers(0, 2**31 - 1))
def test_ik_round_trip_on_reachable_poses(seed):
    """Any FK pose of an in-limits q is reachable; IK must find a q' with
    FK(q') = T (q' may differ from q: the arm has several solutions)."""
    T = ARA.fk(_q(seed))
    q = ARA.ik(T)
    assert q is not None
    assert ARA.within_limits(q)
    np.testing.assert_allclose(ARA.fk(q), T, atol=1e-5)


def test_ik_prefers_q0_and_rejects_unreachable():
    q_true = _q(11)
    q = ARA.ik(ARA.fk(q_true), q0=q_true + 0.05)
    np.testing.assert_allclose(q, q_true, atol=1e-4)
    far = np.eye(4)
    far[:3, 3] = [2.0, 0, 0]  # beyond the 0.6 m reach
    assert ARA.ik(far) is None


def test_params_agree_with_urdf():
    p = ARA.params
    arm = p["arm"]
    o = ARA.joint_origins[:, :3, 3]
    np.testing.assert_allclose(o[0], [0, 0, arm["j1_above_sole_m"]])
    np.testing.assert_allclose(o[1], [0, 0, arm["j2_above_j1_m"]])
    np.testing.assert_allclose(-o[2:5, 0], [arm["link2_m"], arm["link3_m"], arm["link4_m"]])
    assert arm["link2_m"] + arm["link3_m"] + arm["link4_m"] == pytest.approx(arm["foot_spacing_m"])
    np.testing.assert_allclose(np.degrees(LO), p["joints"]["lower_deg"], atol=1e-9)
    np.testing.assert_allclose(np.degrees(HI), p["joints"]["upper_deg"], atol=1e-9)
    np.testing.assert_allclose(ARA.camera_to_base[:3, 3], p["camera"]["xyz_m"])
    view = ARA.camera_to_base[:3, 2]
    assert np.degrees(np.arcsin(-view[2])) == pytest.approx(p["camera"]["pitch_down_deg"])
    feet = [s for s in ARA.collision_shapes if s.kind == "box" and s.link in ("base_link", "foot1")]
    assert feet[0].size[:2] == (p["foot"]["length_m"], p["foot"]["width_m"])
    assert ARA.within_limits(ARA.q_conv)
    # Every value in params.toml is annotated (seed vs chosen).
    text = ARA.urdf_path.with_name("params.toml").read_text()
    for line in text.splitlines():
        if "=" in line and not line.lstrip().startswith("#"):
            assert "# seed" in line or "# chosen" in line, line


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 2**16), b=st.integers(1, 60))
def test_cross_and_unit_axes_equal_the_numpy_forms(seed, b):
    """The IK loop's shortcuts give the very values of the forms they
    replace: ``_cross`` = ``np.cross`` (last axis and axis 1), joint axes
    taken as frame columns = the einsum with the axis vectors."""
    from robots.ara.model import _cross

    rng = np.random.default_rng(seed)
    a, c = rng.normal(size=(b, 6, 3)), rng.normal(size=(b, 6, 3))
    np.testing.assert_array_equal(_cross(a, c), np.cross(a, c))
    A, C = rng.normal(size=(b, 3, 3)), rng.normal(size=(1, 3, 3))
    np.testing.assert_array_equal(_cross(A, C, axis=1), np.cross(A, C, axis=1))
    frames = ARA.fk_all(rng.uniform(LO, HI, (b, 6)))
    axes, origins = ARA._joint_frames(frames)
    want = np.einsum("...ij,...j->...i", frames[..., 1:7, :3, :3], ARA.joint_axes)
    np.testing.assert_array_equal(axes, want)
    np.testing.assert_array_equal(origins, frames[..., 1:7, :3, 3])
