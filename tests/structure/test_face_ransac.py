"""Faces of a member whose section is seen as a blob hardly wider than the
tolerance (planners.structure.faces.ransac_lines)."""

from __future__ import annotations

import numpy as np

from planners.structure import faces
from planners.structure.faces import ransac_lines
from planners.structure.pipeline import model_structure
from planners.structure.synthetic import make_scan, match_members

TOL = 0.039  # 1.5 spacings at 2.6 cm: the tolerance the model uses there


def _tee_end_on(rng: np.random.Generator) -> np.ndarray:
    """A T 100 diagonal's section at 2 cm: its flange as a line of 300
    points, the part of its stem the scanner saw as a blob 4 cm × 6 mm."""
    flange = np.column_stack([rng.normal(-0.06, 0.003, 300), rng.uniform(-0.05, 0.06, 300)])
    stem = np.column_stack([rng.uniform(0.007, 0.047, 100), rng.normal(-0.042, 0.003, 100)])
    return np.vstack([flange, stem])


def _faces_found(uv: np.ndarray, seeds: range) -> list[int]:
    return [len(ransac_lines(uv, TOL, 20, 4, np.random.default_rng(s))) for s in seeds]


def test_a_face_hardly_wider_than_the_tolerance_is_found_for_every_seed(monkeypatch) -> None:
    """Hypotheses from pairs a quarter of the tolerance apart find both faces
    whatever the random draws; pairs required a whole tolerance apart left
    the stem's 4 cm blob with few or no hypotheses, and it was lost for
    some seeds (its points then counted as off every face)."""
    uv = _tee_end_on(np.random.default_rng(0))
    assert _faces_found(uv, range(20)) == [2] * 20
    monkeypatch.setattr(faces, "HYPOTHESIS_SEPARATION", 1.0)
    assert min(_faces_found(uv, range(20))) == 1


def test_warren_tee_diagonals_at_2_cm_keep_their_faces(monkeypatch) -> None:
    """Warren seed 19 at 2 cm: every member is found.  With hypotheses a
    whole tolerance apart, six of its T 100 diagonals (340–660 points)
    lost their stem face, had a quarter of their points off every face and
    were dropped as vegetation (recall 0.57)."""
    scan = make_scan("warren", 19, spacing_m=0.02)
    pts = scan.points / scan.scale

    def recall() -> float:
        model = model_structure(pts)
        found = np.array([m.axis for m in model.members])
        return match_members(scan.true_axes(), scan.true_depths(), found).recall

    assert recall() == 1.0
    monkeypatch.setattr(faces, "HYPOTHESIS_SEPARATION", 1.0)
    assert recall() < 0.7
