"""Scattered lines (:mod:`planners.structure.scattered`): a deep member seen
as points strewn over its whole section is found at a coarse spacing when
members cross it and nothing free lies beside it, and not otherwise."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

import planners.structure.pipeline as pipeline
import planners.structure.scattered as scattered
from planners.structure import StructureParams, model_structure
from planners.structure.joints import closest_points
from planners.structure.model import Member
from planners.structure.scattered import scattered_lines
from planners.structure.synthetic import make_scan, match_members

SPACING = 0.13  # what the model measures on the 10 cm grillage scans
LENGTH = 15.0


def _girder(rng: np.random.Generator, per_m: float = 5.0) -> np.ndarray:
    """Points strewn over an IPE 500's 0.2 × 0.5 m section along x, centred
    on the x axis, ``per_m`` a metre (a 10 cm scan seen past other girders)."""
    n = int(per_m * LENGTH)
    return np.column_stack(
        [rng.uniform(0, LENGTH, n), rng.uniform(-0.1, 0.1, n), rng.uniform(-0.25, 0.25, n)]
    )


def _cross_girders(ys: tuple[float, ...] = (2.0, 2.0, 2.0), z: float = 0.15) -> list[Member]:
    """Cross girders ending at the girder's line at x = 3, 7, 11 (from the +y side)."""
    return [
        Member(i, np.array([[x, 0.1, z], [x, 0.1 + y, z]]), "I", 0.2, 0.1)
        for i, (x, y) in enumerate(zip((3.0, 7.0, 11.0), ys, strict=True))
    ]


def _clutter(rng: np.random.Generator, n: int = 120) -> np.ndarray:
    """Sparse free points away from the girder (other steel's leftovers)."""
    return np.column_stack(
        [rng.uniform(0, LENGTH, n), rng.uniform(4.0, 8.0, n), rng.uniform(-3.0, 3.0, n)]
    )


def _find(pts: np.ndarray, members: list[Member], spacing: float = SPACING, seed: int = 0):
    prm = StructureParams().resolve(spacing)
    radii = np.full(len(members), 0.2)
    return scattered_lines(
        pts,
        np.ones(len(pts), bool),
        members,
        radii,
        spacing,
        prm.max_section_m,
        prm.max_gap_m,
        pipeline._joint_reach(spacing),
        seed,
    )


def _moved(members: list[Member], pts: np.ndarray, rot: Rotation, shift: np.ndarray):
    moved = [
        Member(m.id, rot.apply(m.axis) + shift, m.profile, m.depth_m, m.width_m) for m in members
    ]
    return moved, rot.apply(pts) + shift


@settings(max_examples=20, deadline=None)
@given(seed=st.integers(0, 2**16), per_m=st.floats(4.0, 8.0))
def test_a_girder_of_scattered_points_crossed_by_members_is_found_in_any_frame(
    seed: int, per_m: float
) -> None:
    """A 15 m girder seen as 4–8 points a metre strewn over its section, three
    cross girders framing into it, sparse clutter elsewhere, the scene
    turned and moved anywhere: one line, along the girder within 2°, within
    0.15 m of its centroid line at both ends and over 80 % of its length;
    its points are the girder's, each once; it names the cross girders."""
    rng = np.random.default_rng(seed)
    girder = _girder(rng, per_m)
    pts = np.vstack([girder, _clutter(rng)])
    rot = Rotation.random(random_state=seed)
    shift = rng.uniform(-1e4, 1e4, 3)
    members, moved = _moved(_cross_girders(), pts, rot, shift)
    lines = _find(moved, members, seed=seed)
    assert len(lines) == 1, [ln.axis for ln in lines]
    line = lines[0]
    axis = rot.inv().apply(line.axis - shift)
    d = (axis[1] - axis[0]) / np.linalg.norm(axis[1] - axis[0])
    assert np.degrees(np.arccos(min(1.0, abs(d[0])))) < 2.0, d
    assert np.all(np.linalg.norm(axis[:, 1:], axis=1) < 0.15), axis
    assert abs(axis[1, 0] - axis[0, 0]) >= 0.8 * LENGTH
    assert np.all(line.points < len(girder))
    assert len(np.unique(line.points)) == len(line.points) >= scattered.SCATTER_MIN_POINTS
    assert set(line.crossings) == {0, 1, 2}


def test_a_strip_of_ground_crossed_by_members_is_not_a_member(monkeypatch) -> None:
    """The same number of points a metre, but in a 1.2 m wide strip of
    ground (a plane: as many free points beside the tube as in it), with
    the same cross girders ending on it: no line.  Without the ring test
    (``SCATTER_RING_MAX`` huge) the strip is taken, so the ring is what
    tells them apart."""
    rng = np.random.default_rng(3)
    n = int(3 * 5.0 * LENGTH)
    strip = np.column_stack(
        [rng.uniform(0, LENGTH, n), rng.uniform(-1.2, 1.2, n), rng.normal(0, 0.01, n)]
    )
    members = _cross_girders(z=0.0)
    assert _find(strip, members) == []
    monkeypatch.setattr(scattered, "SCATTER_RING_MAX", 100.0)
    assert len(_find(strip, members)) >= 1


def test_a_tube_of_points_no_member_crosses_is_not_a_member() -> None:
    """The girder's points with one cross girder only (needs two), or with
    the cross girders 2 m clear of its line: no line."""
    rng = np.random.default_rng(5)
    pts = np.vstack([_girder(rng), _clutter(rng)])
    assert _find(pts, _cross_girders()[:1]) == []
    clear = [
        Member(m.id, m.axis + np.array([0.0, 2.0, 0.0]), m.profile, m.depth_m, m.width_m)
        for m in _cross_girders()
    ]
    assert _find(pts, clear) == []
    assert len(_find(pts, _cross_girders())) == 1


def test_a_tube_along_a_member_already_found_is_a_piece_of_it() -> None:
    """A member already lies along the girder: its leftover points are not a
    second member."""
    rng = np.random.default_rng(6)
    pts = np.vstack([_girder(rng), _clutter(rng)])
    members = _cross_girders()
    members.append(Member(3, np.array([[0.0, 0.0, 0.1], [LENGTH, 0.0, 0.1]]), "I", 0.5, 0.2))
    assert _find(pts, members) == []


def test_a_fine_scan_resolves_the_section_and_is_not_searched() -> None:
    """At 2 cm a 0.3 m tube is 15 spacings across: the line features see
    such a section, and the search does not run (the same points give a
    line at 13 cm)."""
    rng = np.random.default_rng(7)
    pts = np.vstack([_girder(rng), _clutter(rng)])
    assert _find(pts, _cross_girders(), spacing=0.02) == []
    assert len(_find(pts, _cross_girders(), spacing=SPACING)) == 1


def test_the_search_is_deterministic() -> None:
    rng = np.random.default_rng(8)
    pts = np.vstack([_girder(rng), _clutter(rng)])
    a, b = _find(pts, _cross_girders()), _find(pts, _cross_girders())
    assert len(a) == len(b) == 1
    assert np.array_equal(a[0].axis, b[0].axis) and np.array_equal(a[0].points, b[0].points)


def test_grillage_inner_main_girder_seen_as_scattered_points_is_found(monkeypatch) -> None:
    """Grillage seed 14 at 10 cm: its inner main girder (an 18.6 m IPE 500
    seen past the outer one as 118 points scattered over its section) is
    found, meets the cross girders framing into it at joints, and is on the
    route.  Without the scattered lines it is not found."""
    from planners.inspection import plan_inspection

    scan = make_scan("grillage", 14, spacing_m=0.1)
    pts = scan.points / scan.scale
    target = 2
    assert scan.members[target].role == "main"
    ta, depths = scan.true_axes(), scan.true_depths()

    def found(model) -> bool:
        axes = np.array([m.axis for m in model.members])
        return target in {t for t, _ in match_members(ta, depths, axes).pairs}

    model = model_structure(pts)
    assert found(model)
    axes = np.array([m.axis for m in model.members])
    k = next(k for t, k in match_members(ta, depths, axes).pairs if t == target)
    assert sum(k in j.members for j in model.joints) >= 2
    plan = plan_inspection(model)
    driven = {plan.graph.edges[e]["member"] for r in plan.routes for e in r.edges}
    assert k in driven
    monkeypatch.setattr(pipeline, "SCATTERED_LINES", False)
    assert not found(model_structure(pts))


def test_closest_points_helper_agrees_with_the_crossing_rule() -> None:
    """The crossing rule measures segment to segment: a cross girder ending
    0.5 m short of the line (within the tube radius plus the joints' reach)
    crosses it, one ending 1 m short does not."""
    reach = 0.3 + pipeline._joint_reach(SPACING)
    line = np.array([[0.0, 0.0, 0.0], [LENGTH, 0.0, 0.0]])
    d = np.array([1.0, 0.0, 0.0])
    near = Member(0, np.array([[5.0, 0.5, 0.0], [5.0, 3.0, 0.0]]), "I", 0.2, 0.1)
    far = Member(1, np.array([[9.0, 1.0, 0.0], [9.0, 3.0, 0.0]]), "I", 0.2, 0.1)
    p, q, _, _ = closest_points(line[0], line[1], near.axis[0], near.axis[1])
    assert np.linalg.norm(p - q) == 0.5
    got = scattered._crossing_members(line[0], line[1], d, [near, far], reach)
    assert got == (0,)
