"""Collinear chains (:mod:`planners.structure.chains`): a member seen as
pieces across long occlusion shadows is joined into one, in any frame;
members side by side, too far apart, or in line on both sides of a member
passing between them are not."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

import planners.structure.pipeline as pipeline
from planners.structure import model_structure
from planners.structure.chains import CHAIN_GAP_GAPS, collinear_chains
from planners.structure.model import Member
from planners.structure.synthetic import make_scan, match_members

RADIUS = 0.2  # a 0.4 m deep girder seen on one flange, with its pads
MAX_GAP = 2.0  # StructureParams.max_gap_m
MERGE_DEG = 5.0  # StructureParams.merge_angle_deg


def _piece(
    x0: float, x1: float, rng: np.random.Generator, y: float = 0.0, z: float = 0.1
) -> np.ndarray:
    """Points 10 cm apart on a flange of a girder along x, ``z`` above its axis."""
    n = max(3, int((x1 - x0) / 0.1))
    x = np.linspace(x0, x1, n)
    pts = np.column_stack([x, y + rng.uniform(-0.08, 0.08, n), np.full(n, z)])
    return pts + rng.normal(scale=0.01, size=pts.shape)


def _scene(pieces: list[np.ndarray], extra: list[np.ndarray] | None = None):
    """Members fitted to each point set (axis from its extent along its own
    line) and the labels of the points."""
    sets = pieces + (extra or [])
    members = []
    for i, p in enumerate(sets):
        c = p.mean(axis=0)
        _, _, vt = np.linalg.svd(p - c, full_matrices=False)
        t = (p - c) @ vt[0]
        members.append(
            Member(i, np.array([c + t.min() * vt[0], c + t.max() * vt[0]]), "unknown", 0.0, 0.0)
        )
    pts = np.vstack(sets)
    labels = np.concatenate([np.full(len(p), i) for i, p in enumerate(sets)])
    return pts, labels, members, np.full(len(sets), RADIUS)


def _moved(pts: np.ndarray, members: list[Member], rot: Rotation, shift: np.ndarray):
    moved = [Member(m.id, rot.apply(m.axis) + shift, m.profile, 0.0, 0.0) for m in members]
    return rot.apply(pts) + shift, moved


@settings(max_examples=40, deadline=None)
@given(
    lengths=st.lists(st.floats(2.0, 5.0), min_size=2, max_size=3),
    gaps=st.lists(st.floats(2.5, 5.0), min_size=2, max_size=2),
    seed=st.integers(0, 2**16),
)
def test_the_pieces_of_an_occluded_girder_are_one_member_in_any_frame(
    lengths: list[float], gaps: list[float], seed: int
) -> None:
    """Two or three pieces 2–5 m long on one girder's flange, 2.5–5 m of
    nothing between them (more than the refit rounds bridge), the scene
    turned and moved anywhere: one chain of all the pieces, its axis within
    the flange's offset of the girder's line and from the first piece's
    outer end to the last's."""
    rng = np.random.default_rng(seed)
    pieces, x = [], 0.0
    for k, length in enumerate(lengths):
        pieces.append(_piece(x, x + length, rng))
        x += length + (gaps[k] if k < len(gaps) else 0.0)
    end = x - (0.0 if len(lengths) > len(gaps) else gaps[-1])
    pts, labels, members, radii = _scene(pieces)
    rot = Rotation.random(random_state=seed)
    # the model works relative to the cloud's lowest corner: metres to hundreds
    shift = rng.uniform(-300, 300, 3)
    moved_pts, moved = _moved(pts, members, rot, shift)
    chains = collinear_chains(moved_pts, labels, moved, radii, MERGE_DEG, MAX_GAP)
    assert [g for g, _ in chains] == [list(range(len(pieces)))]
    axis = rot.inv().apply(chains[0][1] - shift)
    axis = axis[np.argsort(axis[:, 0])]
    assert np.allclose(axis[:, 0], [pieces[0][0, 0], end], atol=0.05)
    # the line through the flange: 0.1 m above the axis, as the pieces are
    assert np.all(np.abs(axis[:, 1]) < 0.05) and np.all(np.abs(axis[:, 2] - 0.1) < 0.05)


@settings(max_examples=20, deadline=None)
@given(seed=st.integers(0, 2**16))
def test_a_chain_runs_through_its_pieces_axes_not_its_points_mean(seed: int) -> None:
    """Two pieces of one flange seen more along its edge than across it (a
    coarse scan's view of a girder from one side), each piece's axis on the
    flange's centre line as the refit's box centre puts it, the scene
    anywhere: the chain's axis is that centre line (within 1 cm), where the
    points' mean lies 4–6 cm towards the edge."""
    rng = np.random.default_rng(seed)
    pieces, members = [], []
    for i, (x0, x1) in enumerate([(0.0, 3.0), (6.0, 9.0)]):
        x = np.linspace(x0, x1, 30)
        across = np.column_stack([x, rng.uniform(-0.08, 0.08, 30), np.full(30, 0.1)])
        edge = np.column_stack([x, np.full(30, -0.08), np.full(30, 0.1)])
        pieces.append(np.vstack([across, edge]) + rng.normal(scale=0.005, size=(60, 3)))
        members.append(Member(i, np.array([[x0, 0.0, 0.1], [x1, 0.0, 0.1]]), "unknown", 0.0, 0.0))
    pts = np.vstack(pieces)
    labels = np.repeat([0, 1], 60)
    assert pts[:, 1].mean() < -0.03  # the points do lean to the edge
    rot = Rotation.random(random_state=seed)
    shift = rng.uniform(-300, 300, 3)
    moved_pts, moved = _moved(pts, members, rot, shift)
    radii = np.full(2, RADIUS)
    chains = collinear_chains(moved_pts, labels, moved, radii, MERGE_DEG, MAX_GAP)
    assert [g for g, _ in chains] == [[0, 1]]
    axis = rot.inv().apply(chains[0][1] - shift)
    axis = axis[np.argsort(axis[:, 0])]
    assert np.allclose(axis[:, 0], [0.0, 9.0], atol=0.01)
    assert np.all(np.abs(axis[:, 1]) < 0.01) and np.all(np.abs(axis[:, 2] - 0.1) < 0.01)


def test_girders_side_by_side_are_not_a_chain() -> None:
    """Two girders 1.5 m apart, one seen at each end of the span: as far
    along as the pieces of one girder, but not on one line."""
    rng = np.random.default_rng(1)
    pts, labels, members, radii = _scene([_piece(0, 4, rng), _piece(7, 11, rng, y=1.5)])
    assert collinear_chains(pts, labels, members, radii, MERGE_DEG, MAX_GAP) == []
    # the same two pieces in line are one
    pts, labels, members, radii = _scene([_piece(0, 4, rng), _piece(7, 11, rng)])
    assert [g for g, _ in collinear_chains(pts, labels, members, radii, MERGE_DEG, MAX_GAP)] == [
        [0, 1]
    ]


def test_pieces_further_apart_than_the_chain_reach_stay_apart() -> None:
    """A gap over ``CHAIN_GAP_GAPS`` × ``max_gap_m``, or longer than both
    pieces together, is not bridged."""
    rng = np.random.default_rng(2)
    far = CHAIN_GAP_GAPS * MAX_GAP + 0.5
    pts, labels, members, radii = _scene([_piece(0, 5, rng), _piece(5 + far, 10 + far, rng)])
    assert collinear_chains(pts, labels, members, radii, MERGE_DEG, MAX_GAP) == []
    pts, labels, members, radii = _scene([_piece(0, 2, rng), _piece(6.5, 8.5, rng)])
    assert collinear_chains(pts, labels, members, radii, MERGE_DEG, MAX_GAP) == []


def test_a_member_passing_between_two_pieces_stops_the_chain() -> None:
    """Two beams in line with a column through the gap between them are two
    members; a cross girder that only frames into the gap from one side
    does not stop the chain."""
    rng = np.random.default_rng(3)
    beams = [_piece(0, 4, rng), _piece(6.5, 10.5, rng)]
    column = np.column_stack(
        [rng.normal(5.25, 0.03, 40), rng.normal(0, 0.03, 40), np.linspace(-3, 3, 40)]
    )
    pts, labels, members, radii = _scene(beams, [column])
    assert collinear_chains(pts, labels, members, radii, MERGE_DEG, MAX_GAP) == []
    framing = np.column_stack(
        [rng.normal(5.25, 0.03, 40), np.linspace(0.3, 3, 40), rng.normal(0.1, 0.03, 40)]
    )
    pts, labels, members, radii = _scene(beams, [framing])
    chains = collinear_chains(pts, labels, members, radii, MERGE_DEG, MAX_GAP)
    assert [g for g, _ in chains] == [[0, 1]]


def test_a_girder_seen_in_two_pieces_on_a_coarse_scan_is_found(monkeypatch) -> None:
    """Grillage seed 8 at 10 cm: main girder 1 (an HEB 400, 13 m) is seen
    as two pieces, 2.7 m and 5.9 m long, 4.2 m apart with no point between
    them.  Chained, it is found by the issue's criterion; without the
    chains it is not (each piece is under 80 % of its length)."""
    scan = make_scan("grillage", 8, spacing_m=0.1)
    ta, depths = scan.true_axes(), scan.true_depths()

    def found() -> set[int]:
        model = model_structure(scan.points / scan.scale)
        fa = np.array([m.axis for m in model.members])
        return {t for t, _ in match_members(ta, depths, fa).pairs}

    assert 1 in found()
    monkeypatch.setattr(pipeline, "CHAIN_PIECES", False)
    assert 1 not in found()


def test_a_girder_chained_on_one_flanges_edge_is_found() -> None:
    """Grillage seed 11 at 10 cm: main girder 0 (an HEB 400, 18 m) is a
    chain of three pieces seen on its top flange, most points near one
    edge.  Its axis through the pieces' axes is found; through the points'
    mean it lay 0.24 m from the centroid at one end, past its tolerance,
    and covered 51 of 64 samples where 52 are needed."""
    scan = make_scan("grillage", 11, spacing_m=0.1)
    model = model_structure(scan.points / scan.scale)
    fa = np.array([m.axis for m in model.members])
    assert 0 in {t for t, _ in match_members(scan.true_axes(), scan.true_depths(), fa).pairs}
