"""Pre-processing: the structure plane is recovered and its outliers removed."""

from __future__ import annotations

import numpy as np
import pytest

from planners.errors import EmptyInputError, InfeasibleError
from planners.navigation.evaluate import transfer_labels
from planners.navigation.preprocess import PlaneFrame, preprocess

from ._shared import structure


@pytest.mark.parametrize("shape", ["cross", "i", "pratt"])
def test_plane_and_outliers(shape: str) -> None:
    st = structure(shape, 0)
    pre = preprocess(st.points)
    true_n = st.to_robot[:3, 2]
    angle = np.degrees(np.arccos(min(1.0, abs(float(pre.frame.normal @ true_n)))))
    assert angle < 0.5
    # Processed points lie on the fitted plane and near true steel.
    assert np.allclose(pre.frame.to_plane(pre.points3d), pre.points2d, atol=1e-9)
    h = (pre.points3d - pre.frame.origin) @ pre.frame.normal
    assert np.max(np.abs(h)) < 1e-9
    gt = transfer_labels(pre.points3d, st, tol_m=0.03)
    assert np.mean(gt >= 0) > 0.995
    assert pre.counts["input"] >= pre.counts["voxel"] >= pre.counts["plane"]


def test_frame_round_trip_and_orientation() -> None:
    n = np.array([0.05, -0.03, 1.0])
    frame = PlaneFrame.from_plane(n, 0.02)
    assert frame.normal[2] > 0
    assert np.allclose(np.cross(frame.e1, frame.e2), frame.normal)
    uv = np.random.default_rng(0).normal(size=(50, 2))
    assert np.allclose(frame.to_plane(frame.lift(uv)), uv)
    # e1 is the robot x axis projected onto the plane.
    x = np.array([1.0, 0.0, 0.0])
    proj = x - (x @ frame.normal) * frame.normal
    assert np.allclose(frame.e1, proj / np.linalg.norm(proj))


def test_no_plane_and_empty() -> None:
    rng = np.random.default_rng(0)
    blob = rng.uniform(-0.4, 0.4, size=(3000, 3))  # a volume, no plane
    with pytest.raises(InfeasibleError, match="no structure plane"):
        preprocess(blob, min_plane_points=1000)
    far = rng.uniform(10, 11, size=(100, 3))
    with pytest.raises(EmptyInputError, match="pass-through"):
        preprocess(far)
