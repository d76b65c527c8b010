"""Row links of the region growing (``lines.grow_regions``): the step along a
voxel's line against a brute-force computation, a long link only along the
line, and the 10 cm Warren seeds it finds with the earlier setting undone."""

from __future__ import annotations

import itertools
import statistics

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial import cKDTree

import planners.structure.lines as lines
import planners.structure.pipeline as pipeline
from planners.structure import StructureParams, model_structure
from planners.structure.features import line_features
from planners.structure.synthetic import make_scan, match_members

ORIGIN = np.array([569_000.0, 5_384_000.0, 160.0])  # a survey frame far from 0


def _regions(points: np.ndarray, spacing: float) -> np.ndarray:
    prm = StructureParams().resolve(spacing)
    assert prm.scales_m is not None
    feat = line_features(points, spacing, prm.scales_m, prm.k_neighbours, prm.max_voxels)
    keep = np.ones(len(feat.linearity), bool)
    region = lines.grow_regions(feat, prm.linearity_min, prm.link_angle_deg, keep, spacing)
    return region[feat.grid.inverse]


def _brute_step(c: np.ndarray, d: np.ndarray, nb: np.ndarray) -> np.ndarray:
    out = []
    for i in range(len(c)):
        t = sorted(float((c[j] - c[i]) @ d[i]) for j in nb[i])
        steps = [b - a for a, b in itertools.pairwise(t) if b - a > 0]
        out.append(statistics.median(steps) if steps else np.inf)
    return np.array(out)


@settings(max_examples=40, deadline=None)
@given(st.integers(2, 60), st.integers(1, 9), st.integers(0, 10_000), st.booleans())
def test_the_step_along_a_line_matches_a_brute_force_median(
    n: int, k: int, seed: int, on_a_line: bool
) -> None:
    rng = np.random.default_rng(seed)
    if on_a_line:  # rows with repeated positions too (zero steps are skipped)
        c = np.outer(np.round(rng.uniform(0, 3, n), 1), [1.0, 0.5, 0.0])
    else:
        c = rng.normal(0, 1, (n, 3))
    d = rng.normal(0, 1, (n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    kk = min(k, n)
    _, nb = cKDTree(c).query(c, k=kk)
    nb = np.asarray(nb).reshape(n, kk)
    got = lines._row_step(c, d, nb)
    want = _brute_step(c, d, nb)
    assert np.array_equal(np.isinf(got), np.isinf(want))
    fin = np.isfinite(want)
    np.testing.assert_allclose(got[fin], want[fin], rtol=1e-9, atol=1e-9)


@pytest.mark.parametrize("step", [0.05, 0.12, 0.3])
def test_the_step_at_the_end_of_a_row_is_the_rows_step(step: float) -> None:
    """The neighbourhood's spacing 2r/(n − 1) doubles at a row's end (one-sided);
    the step along the line does not, so the last voxel reaches no farther."""
    c = np.outer(np.arange(20) * step, [0.6, 0.8, 0.0])
    d = np.tile([0.6, 0.8, 0.0], (20, 1))
    _, nb = cKDTree(c).query(c, k=9)
    np.testing.assert_allclose(lines._row_step(c, d, np.asarray(nb)), step, rtol=1e-9)


@settings(max_examples=20, deadline=None)
@given(st.floats(0.36, 0.45), st.floats(0.12, 0.3), st.floats(0.0, 1.0), st.integers(0, 10_000))
def test_a_parallel_row_beside_a_sparse_row_is_not_linked_to_it(
    offset: float, step: float, shift: float, seed: int
) -> None:
    """Two sparse rows (a 10 cm scan's far members, or the ground's scan rows)
    ``offset`` apart sideways: within the row link's reach, but not along the
    line, so each is one region of its own; with the alignment undone they
    are one."""
    rng = np.random.default_rng(seed)
    x = np.arange(0.0, 4.0, step)
    n = len(x)
    a = np.column_stack([x, np.zeros(n), np.zeros(n)])
    b = np.column_stack([x + shift * step, np.full(n, offset), np.zeros(n)])
    pts = np.vstack([a, b]) + rng.normal(0, 0.003, (2 * n, 3)) + ORIGIN
    mid = slice(n // 4, 3 * n // 4)
    reg = _regions(pts, 0.1)
    first, second = set(reg[:n][mid]), set(reg[n:][mid])
    assert len(first) == 1 and len(second) == 1 and -1 not in first | second
    assert first.isdisjoint(second)
    old = lines.LINK_ROW_ALIGN_DEG
    try:
        lines.LINK_ROW_ALIGN_DEG = 90.0
        reg = _regions(pts, 0.1)
    finally:
        lines.LINK_ROW_ALIGN_DEG = old
    assert not set(reg[:n][mid]).isdisjoint(set(reg[n:][mid]))


def _warren_10cm(seed: int) -> tuple[float, float]:
    scan = make_scan("warren", seed, spacing_m=0.1)
    model = model_structure(scan.points / scan.scale)
    found = np.array([m.axis for m in model.members])
    mm = match_members(scan.true_axes(), scan.true_depths(), found)
    return mm.recall, mm.precision


def test_long_links_along_the_line_find_a_10_cm_warren_s_diagonals(monkeypatch) -> None:
    """Warren seeds 12 and 17 at 10 cm: diagonals one or two points across,
    10–30 cm apart along their length.  Before the links along the line,
    recall was 0.55 and 0.63; with this module's step but the reach 1.2
    steps in any direction it is 0.55 and 0.50; with the reach along the
    line every member of seed 17 and all but one of seed 12 are found."""
    for seed in (12, 17):
        recall, precision = _warren_10cm(seed)
        assert recall >= 0.95 and precision >= 0.94, (seed, recall, precision)
    monkeypatch.setattr(lines, "LINK_ROW", 1.2)
    monkeypatch.setattr(lines, "LINK_ROW_ALIGN_DEG", 90.0)
    # the sparse rows, the bridging rows and the refit without crowded
    # stretches (later stages) recover some of these diagonals by other
    # ways; the links along the line are measured without them
    monkeypatch.setattr(pipeline, "SPARSE_ROWS", False)
    monkeypatch.setattr(pipeline, "BRIDGE_ROWS", False)
    monkeypatch.setattr(pipeline, "CROWDED_REFIT", False)
    for seed in (12, 17):
        recall, _ = _warren_10cm(seed)
        assert recall < 0.6, (seed, recall)
