"""planners.structure.model_structure: geometry primitives against brute
force, hand-built members with known axes, clutter, frames, bad input, and
the real pc2beam crop against its own instance labels."""

from __future__ import annotations

from pathlib import Path

import networkx as nx
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from sklearn.metrics import adjusted_rand_score

from planners.blasting.surface import Surface
from planners.errors import EmptyInputError, InvalidInputError
from planners.structure import StructureParams, model_structure
from planners.structure.assign import segment_distances
from planners.structure.joints import closest_points

PC2BEAM = (
    Path(__file__).resolve().parents[2]
    / ".."
    / "shared"
    / "data"
    / "pointclouds"
    / "pc2beam_test_points.txt"
)

coord = st.floats(-5, 5, allow_nan=False)
vec3 = st.tuples(coord, coord, coord).map(np.array)


def _samples(a: np.ndarray, b: np.ndarray, n: int = 4001) -> np.ndarray:
    """n points evenly along segment ab."""
    return a + np.outer(np.linspace(0, 1, n), b - a)


@settings(max_examples=60, deadline=None)
@given(vec3, vec3, vec3, vec3)
def test_closest_points_of_segments_match_dense_sampling(p0, p1, q0, q1) -> None:
    if np.linalg.norm(p1 - p0) < 1e-3 or np.linalg.norm(q1 - q0) < 1e-3:
        return
    pa, pb, _, _ = closest_points(p0, p1, q0, q1)
    got = float(np.linalg.norm(pa - pb))
    sp = _samples(p0, p1, 1500)
    sq = _samples(q0, q1, 1500)
    # the segment-to-segment minimum by sampling both segments densely
    best = min(float(np.min(np.linalg.norm(sq - x, axis=1))) for x in sp[::3])
    step = max(np.linalg.norm(p1 - p0), np.linalg.norm(q1 - q0)) / 500
    assert got <= best + 1e-9
    assert got >= best - 2 * step


@settings(max_examples=60, deadline=None)
@given(vec3, vec3, vec3)
def test_segment_distance_matches_dense_sampling(p, a, b) -> None:
    if np.linalg.norm(b - a) < 1e-3:
        return
    d = b - a
    length = float(np.linalg.norm(d))
    u = d / length
    got = segment_distances(p[None], a[None], u[None], np.array([0.0]), np.array([length]))[0, 0]
    samples = _samples(a, b)
    brute = float(np.min(np.linalg.norm(samples - p, axis=1)))
    assert brute - length / 4000 <= got <= brute + 1e-9


def _box_member(a, b, width, depth, spacing, rng, noise=0.002):
    """Surface points of a closed rectangular hollow section from a to b."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    d = (b - a) / np.linalg.norm(b - a)
    ref = np.array([0.0, 0.0, 1.0]) if abs(d[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    u = np.cross(d, ref)
    u /= np.linalg.norm(u)
    v = np.cross(d, u)
    length = float(np.linalg.norm(b - a))
    ts = np.arange(0, length, spacing)
    pts = []
    for side, (w, h) in enumerate(((width, depth), (depth, width))):
        for sign in (-1, 1):
            ss = np.arange(-w / 2, w / 2, spacing)
            T, S = np.meshgrid(ts, ss, indexing="ij")
            T, S = T.ravel(), S.ravel()
            if side == 0:
                p = a + np.outer(T, d) + np.outer(S, u) + np.outer(np.full_like(S, sign * h / 2), v)
            else:
                p = a + np.outer(T, d) + np.outer(S, v) + np.outer(np.full_like(S, sign * h / 2), u)
            pts.append(p)
    out = np.vstack(pts)
    return out + rng.normal(0, noise, out.shape)


def _t_structure(spacing: float = 0.02, seed: int = 0):
    """A 6 m chord along x and a 3 m member rising from its middle at 60°."""
    rng = np.random.default_rng(seed)
    chord = _box_member([0, 0, 0], [6, 0, 0], 0.2, 0.3, spacing, rng)
    top = np.array([3 + 3 * np.cos(np.radians(60)), 0, 3 * np.sin(np.radians(60))])
    # the branch starts at the chord's surface, as a welded member does
    start = np.array([3, 0, 0.15]) + 0.1 * (top - np.array([3, 0, 0])) / 3
    branch = _box_member(start, top, 0.12, 0.12, spacing, rng)
    pts = np.vstack([chord, branch])
    labels = np.concatenate([np.zeros(len(chord), int), np.ones(len(branch), int)])
    axes = np.array([[[0, 0, 0], [6, 0, 0]], [start, top]], dtype=float)
    return pts, labels, axes


def _axis_error(found: np.ndarray, true: np.ndarray) -> tuple[float, float]:
    """(angle in degrees, largest distance of the true axis' middle 80 % from the found line)."""
    df = found[1] - found[0]
    df /= np.linalg.norm(df)
    dt = true[1] - true[0]
    dt /= np.linalg.norm(dt)
    ang = float(np.degrees(np.arccos(min(1.0, abs(df @ dt)))))
    s = np.linspace(0.1, 0.9, 20)
    pts = true[0] + np.outer(s, true[1] - true[0])
    rel = pts - found[0]
    perp = np.linalg.norm(rel - np.outer(rel @ df, df), axis=1)
    return ang, float(perp.max())


def _match(model, axes):
    out = []
    for true in axes:
        errs = [(_axis_error(m.axis, true), m) for m in model.members]
        (ang, dist), m = min(errs, key=lambda e: e[0][0] + 10 * e[0][1])
        out.append((ang, dist, m))
    return out


def test_two_members_meeting_are_found_with_their_joint_and_spans() -> None:
    pts, labels, axes = _t_structure()
    model = model_structure(pts)
    assert len(model.members) == 2
    for ang, dist, _ in _match(model, axes):
        assert ang < 3.0
        assert dist < 0.05
    assert len(model.joints) == 1
    assert np.linalg.norm(model.joints[0].pos - np.array([3, 0, 0])) < 0.3
    assert sorted(model.joints[0].members) == [0, 1]
    # the chord is split at the joint: three spans, one connected graph
    assert model.graph.number_of_edges() == 3
    assert nx.is_connected(model.graph)
    spans = sorted(d["weight"] for _, _, d in model.graph.edges(data=True))
    assert spans[-1] == pytest.approx(3.0, abs=0.35)
    assert adjusted_rand_score(labels, model.labels) > 0.9
    assert model.spacing_m == pytest.approx(0.02, rel=0.5)
    assert set(model.timings_s) >= {"spacing", "features", "lines", "assign", "faces", "graph"}


def test_box_member_gets_four_faces_usable_as_blasting_surfaces() -> None:
    rng = np.random.default_rng(3)
    pts = _box_member([0, 0, 0], [4, 0, 0], 0.2, 0.3, 0.015, rng)
    model = model_structure(pts)
    assert len(model.members) == 1
    m = model.members[0]
    assert m.profile == "box"
    assert sorted([round(m.depth_m, 2), round(m.width_m, 2)]) == pytest.approx([0.2, 0.3], abs=0.03)
    assert len(m.faces) == 4
    for f in m.faces:
        s = f.surface()
        assert isinstance(s, Surface)
        # the face's points lie in its plane, and its normal points away from the axis
        mid = m.axis.mean(axis=0)
        assert float((f.origin - mid) @ f.normal) > 0
        on = np.abs((pts - f.origin) @ f.normal) < 0.01
        assert on.sum() >= 0.8 * f.n_points
        side = 0.2 if f.area_m2 < 1.0 else 0.3
        assert f.area_m2 == pytest.approx(4.0 * side, rel=0.05)


def test_survey_frame_far_from_origin_gives_the_same_model() -> None:
    pts, _, _ = _t_structure()
    offset = np.array([443_670.0, 5_349_620.0, 104.5])
    a = model_structure(pts)
    b = model_structure(pts + offset)
    assert len(a.members) == len(b.members)
    for ma, mb in zip(a.members, b.members, strict=True):
        assert np.allclose(ma.axis + offset, mb.axis, atol=1e-6)
    assert np.array_equal(a.labels, b.labels)
    assert np.allclose(b.graph.nodes[0]["pos"], a.graph.nodes[0]["pos"] + offset)


def test_ground_plane_is_left_unlabelled() -> None:
    pts, _, axes = _t_structure()
    rng = np.random.default_rng(5)
    g = rng.uniform([-2, -3], [8, 3], size=(60_000, 2))
    ground = np.column_stack([g, np.full(len(g), -1.0) + rng.normal(0, 0.003, len(g))])
    model = model_structure(np.vstack([pts, ground]))
    assert len(model.members) == 2
    ground_labels = model.labels[len(pts) :]
    assert (ground_labels == -1).mean() > 0.98
    for ang, dist, _ in _match(model, axes):
        assert ang < 3.0 and dist < 0.05


def test_noise_alone_gives_no_members_not_an_error() -> None:
    rng = np.random.default_rng(1)
    model = model_structure(rng.uniform(0, 3, size=(20_000, 3)))
    assert model.members == []
    assert (model.labels == -1).all()
    assert model.graph.number_of_nodes() == 0


def test_the_same_structure_is_found_at_fine_and_coarse_spacing() -> None:
    for spacing in (0.01, 0.05):
        pts, _, axes = _t_structure(spacing)
        model = model_structure(pts)
        assert len(model.members) == 2, spacing
        for ang, dist, _ in _match(model, axes):
            assert ang < 3.0 and dist < 0.08, spacing


@pytest.mark.parametrize(
    ("points", "error"),
    [
        (np.zeros((5, 3)), EmptyInputError),
        (np.zeros((100, 2)), InvalidInputError),
        (np.full((100, 3), np.nan), InvalidInputError),
        (np.zeros((100, 3)), EmptyInputError),  # spacing cannot be measured
    ],
)
def test_bad_clouds_raise_typed_errors(points, error) -> None:
    with pytest.raises(error):
        model_structure(points)


@pytest.mark.parametrize(
    "params",
    [
        StructureParams(linearity_min=1.5),
        StructureParams(max_section_m=-1.0),
        StructureParams(scales_m=(0.1, -0.2)),
        StructureParams(max_voxels=10),
    ],
)
def test_bad_params_raise_invalid_input(params) -> None:
    pts, _, _ = _t_structure()
    with pytest.raises(InvalidInputError):
        model_structure(pts, params=params)


def test_progress_is_reported_in_order() -> None:
    pts, _, _ = _t_structure()
    seen: list[tuple[float, str]] = []
    model_structure(pts, progress=lambda f, s: seen.append((f, s)))
    fractions = [f for f, _ in seen]
    assert fractions == sorted(fractions) and fractions[-1] == 1.0
    assert [s for _, s in seen][:3] == ["spacing", "surfaces", "features"]


@pytest.mark.skipif(not PC2BEAM.exists(), reason="shared data not present")
def test_pc2beam_crop_two_members_connected_and_routed() -> None:
    from planners.inspection import plan_inspection

    data = np.loadtxt(PC2BEAM)
    model = model_structure(data[:, :3])
    assert len(model.members) == 2
    assert len(model.joints) == 1 and nx.is_connected(model.graph)
    ari = adjusted_rand_score(data[:, 6].astype(int), model.labels)
    assert ari >= 0.9, ari
    # both are I sections; the wide beam is recognised as one (the diagonal,
    # seen from one side and 0.14 m wide, is not reliably: see docs)
    beam = max(model.members, key=lambda m: m.length_m)
    assert beam.profile == "I"
    # its points span 0.36 m vertically over a 1.2 m length tilted ~2°
    assert beam.depth_m == pytest.approx(0.34, abs=0.04)
    plan = plan_inspection(model)
    assert plan.uncovered_members == []
    covered = {model.graph.edges[e]["member"] for e in plan.route.edges}
    assert covered == {0, 1}


def _assign_brute(points, centres, dirs, t0, t1, radius, margin):
    """Reference: every point against every member."""
    d = segment_distances(points, centres, dirs, t0, t1)
    inside = d <= radius[None] + margin
    depth = np.where(inside, d / radius[None], np.inf)
    best = np.argmin(depth, axis=1)
    return np.where(inside.any(axis=1), best, -1), inside.sum(axis=1) >= 2


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 10_000), st.integers(1, 6))
def test_assign_points_with_a_kd_tree_equals_all_pairs(seed: int, m: int) -> None:
    from planners.structure.assign import assign_points

    rng = np.random.default_rng(seed)
    pts = rng.uniform(-2, 2, size=(600, 3))
    centres = rng.uniform(-1, 1, size=(m, 3))
    dirs = rng.normal(size=(m, 3))
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    t0 = -rng.uniform(0.1, 2, m)
    t1 = rng.uniform(0.1, 2, m)
    radius = rng.uniform(0.05, 0.8, m)
    got = assign_points(pts, centres, dirs, t0, t1, radius, 0.03)
    want = _assign_brute(pts, centres, dirs, t0, t1, radius, 0.03)
    assert np.array_equal(got[0], want[0])
    assert np.array_equal(got[1], want[1])


def test_a_short_post_between_joints_keeps_its_axis() -> None:
    """Pratt seed 1 at 2 cm: a 2 m UPE 200 post between two chord joints.
    Measured over its whole length, the joints' gussets and chord steel widened
    its section box round after round (the axis walked 12 cm aside) and it was
    lost; measured away from its ends it is found, and so is every other
    member of the scan (the ground truth)."""
    from planners.structure.synthetic import make_scan, match_members

    scan = make_scan("pratt", 1, spacing_m=0.02)
    model = model_structure(scan.points / scan.scale)
    found = np.array([m.axis for m in model.members])
    mm = match_members(scan.true_axes(), scan.true_depths(), found)
    post = next(i for i, m in enumerate(scan.members) if m.section.name == "UPE 200")
    assert post in {t for t, _ in mm.pairs}
    assert mm.recall == 1.0 and mm.precision >= 0.9, (mm.recall, mm.precision)


def _line(centre, direction, half: float, radius: float = 0.05):
    from planners.structure.lines import LineCandidate

    d = np.asarray(direction, float)
    return LineCandidate(
        np.zeros(0, np.int64), np.asarray(centre, float), d / np.linalg.norm(d), -half, half, radius
    )


def test_side_by_side_joins_do_not_chain_past_one_section() -> None:
    """Three parallel lines 0.8 m apart: each neighbouring pair fits in a
    1.2 m section, the three together (1.6 m) do not: the nearer pair joins,
    the third stays apart (a chain of such joins once made a whole truss one member)."""
    from planners.structure.lines import join_groups

    cands = [_line([0, 0, z], [1, 0, 0], 5.0) for z in (0.0, 0.75, 1.6)]
    groups = sorted(sorted(g) for g in join_groups(cands, 5.0, 2.0, 1.2, 12.0))
    assert groups == [[0, 1], [2]]
    # within one section all three join
    cands = [_line([0, 0, z], [1, 0, 0], 5.0) for z in (0.0, 0.5, 1.0)]
    assert [sorted(g) for g in join_groups(cands, 5.0, 2.0, 1.2, 12.0)] == [[0, 1, 2]]


@settings(max_examples=60, deadline=None)
@given(
    st.lists(
        st.tuples(st.floats(-1.5, 1.5), st.floats(-1.5, 1.5), st.floats(-3, 3)),
        min_size=2,
        max_size=9,
    ),
    st.floats(0.3, 1.5),
)
def test_every_joined_group_fits_in_one_section(offsets, max_section: float) -> None:
    """Parallel lines anywhere across and along: whatever joins, no group is
    deeper than ``max_section`` (brute force over all pairs of the group's line ends)."""
    from planners.structure.lines import SECTION_DIRECTIONS, join_groups

    cands = [_line([x, y, 0.0], [0, 0, 1], 1.0) for x, y, _ in offsets]
    cands = [
        _line(c.centre + [0, 0, s], c.direction, 1.0)
        for c, (_, _, s) in zip(cands, offsets, strict=True)
    ]
    for g in join_groups(cands, 5.0, 2.0, max_section, 12.0):
        across = np.array([cands[i].centre[:2] for i in g])
        widest = max(np.linalg.norm(a - b) for a in across for b in across)
        # the extent is measured over SECTION_DIRECTIONS directions: within cos(90° / K)
        bound = max_section / np.cos(np.pi / (2 * SECTION_DIRECTIONS))
        assert widest <= bound + 1e-9, (g, widest)


def test_a_short_truss_is_not_joined_into_one_member() -> None:
    """Pratt seed 18 at 2 cm: a truss 1.7 m deep whose chords, chord edges and
    a diagonal's edge lay side by side within 1.2 m pair by pair; joined in a
    chain they made one 2 m deep "box" and nothing was found."""
    from planners.structure.synthetic import make_scan, match_members

    scan = make_scan("pratt", 18, spacing_m=0.02)
    model = model_structure(scan.points / scan.scale)
    found = np.array([m.axis for m in model.members])
    mm = match_members(scan.true_axes(), scan.true_depths(), found)
    # chained, recall and precision were 0 (19 true members)
    assert mm.recall >= 0.9 and mm.precision >= 0.9, (mm.recall, mm.precision)
    # no member spans the truss (1.7 m between chords; it had a 2 m "box")
    assert max(m.depth_m for m in model.members) < StructureParams().max_section_m


@settings(max_examples=60, deadline=None)
@given(
    st.floats(0.3, 3.0),
    st.floats(2.0, 10.0),
    st.floats(-0.5, 2.5),
    st.floats(-4.0, 4.0),
    st.floats(0.0, 0.3),
)
def test_joining_two_pieces_does_not_depend_on_their_order(
    short: float, long: float, gap: float, tilt_deg: float, offset: float
) -> None:
    """A short piece beyond a long one's end, tilted and offset: whether they
    join is the same whichever is listed first (the short piece is measured
    against the long one's line)."""
    from planners.structure.lines import _should_join

    a = _line([long / 2, 0, 0], [1, 0, 0], long / 2, 0.15)
    t = np.radians(tilt_deg)
    b = _line([long + gap + short / 2, offset, 0], [np.cos(t), np.sin(t), 0], short / 2, 0.15)
    cos5, cos12 = np.cos(np.radians(5.0)), np.cos(np.radians(12.0))
    one = _should_join(a, b, cos5, cos12, 2.0, 1.2)
    other = _should_join(b, a, cos5, cos12, 2.0, 1.2)
    assert (one is None) == (other is None) and one == other


def test_a_long_piece_s_line_decides_collinearity() -> None:
    """A 6.5 m piece and a 1.3 m piece 1.9° off it, end to end, 5 cm aside,
    sections 0.1 m: measured on the long line they are collinear (the short
    one's ends 3 and 7 cm off it); on the short one, the long piece's far end
    is 19 cm off (they were left apart)."""
    from planners.structure.lines import join_groups

    t = np.radians(1.9)
    long = _line([3.25, 0, 0], [1, 0, 0], 3.25, 0.1)
    short = _line([7.15, 0.05, 0], [np.cos(t), np.sin(t), 0], 0.65, 0.1)
    assert [sorted(g) for g in join_groups([short, long], 5.0, 2.0, 1.2, 12.0)] == [[0, 1]]


def _walk_brute(ahead: np.ndarray, step: float, max_growth: float) -> float:
    """The end of a walk over points at ``ahead`` (m past the end, on the
    axis): stretch k = [k·step, (k+1)·step) is entered while every stretch
    before it and it hold a point; the end is the farthest point entered."""
    reached = 0.0
    k = 0
    while (k + 1) * step <= max_growth + step:
        inside = ahead[(ahead > k * step) & (ahead < (k + 1) * step) & (ahead <= max_growth)]
        if k * step >= max_growth or len(inside) == 0:
            break
        reached = float(inside.max())
        k += 1
    return reached


@settings(max_examples=80, deadline=None)
@given(
    st.lists(st.floats(0.01, 3.0), min_size=0, max_size=30),
    st.floats(0.05, 0.5),
    st.floats(0.2, 2.5),
)
def test_grow_end_walks_over_the_points_that_continue_the_axis(
    offsets: list[float], step: float, max_growth: float
) -> None:
    from scipy.spatial import cKDTree

    from planners.structure.assign import grow_end

    ahead = np.array(offsets)
    # keep clear of stretch boundaries, where rounding decides
    ahead = ahead[np.abs(ahead / step - np.round(ahead / step)) > 1e-6]
    ahead = ahead[np.abs(ahead - max_growth) > 1e-6]
    d = np.array([0.6, 0.8, 0.0])
    end = np.array([10.0, 5.0, 2.0])
    own = end - np.outer(np.linspace(0.1, 1.0, 10), d)  # the member itself, behind its end
    pts = np.vstack([own, end + np.outer(ahead, d)]) if len(ahead) else own
    free = np.ones(len(pts), bool)
    got = grow_end(pts, cKDTree(pts), free, end, d, 0.0, 1.0, 0.05, step, max_growth)
    want = _walk_brute(ahead, step, max_growth) if len(ahead) else 0.0
    assert got == pytest.approx(want, abs=1e-9)
    # backwards from the member's far end it walks over nothing of this
    back = grow_end(pts, cKDTree(pts), free, end, d, -1.0, -1.0, 0.05, step, 0.0)
    assert back == 0.0


def test_grow_end_stops_at_points_not_free_and_at_a_plane() -> None:
    from scipy.spatial import cKDTree

    from planners.structure.assign import grow_end

    d = np.array([1.0, 0.0, 0.0])
    line = np.column_stack([np.arange(0.05, 1.5, 0.05), np.zeros(29), np.zeros(29)])
    tree = cKDTree(line)
    free = np.ones(len(line), bool)
    assert grow_end(line, tree, free, np.zeros(3), d, 0.0, 1.0, 0.05, 0.1, 2.0) == pytest.approx(
        1.45
    )
    # a neighbour's points (labelled) are not walked over
    free[line[:, 0] > 0.72] = False
    assert grow_end(line, tree, free, np.zeros(3), d, 0.0, 1.0, 0.05, 0.1, 2.0) == pytest.approx(
        0.70
    )
    # a plane continuing the end: as many points beside the axis as on it
    g = np.arange(-0.2, 0.21, 0.05)
    xs, ys = np.meshgrid(np.arange(0.05, 1.5, 0.05), g, indexing="ij")
    plane = np.column_stack([xs.ravel(), ys.ravel(), np.zeros(xs.size)])
    ptree = cKDTree(plane)
    pfree = np.ones(len(plane), bool)
    assert grow_end(plane, ptree, pfree, np.zeros(3), d, 0.0, 1.0, 0.075, 0.1, 2.0) == 0.0


def _assert_chords_found_at_10_cm(kind: str, seed: int) -> None:
    """Both chords of the generator's truss ``kind`` / ``seed`` scanned at
    10 cm are found (the issue's criterion), at a precision ≥ 0.9.  (For a
    while this asked only 0.8 at 5°, 0.9 at 10°: Pratt seed 12's
    sparse channel posts leaned 5.5–7° by least squares; with the hull
    direction they are within 5° and the former bound holds again.)"""
    from planners.structure.synthetic import make_scan, match_members

    scan = make_scan(kind, seed, spacing_m=0.1)
    model = model_structure(scan.points / scan.scale)
    found = np.array([m.axis for m in model.members])
    mm = match_members(scan.true_axes(), scan.true_depths(), found)
    chords = [i for i, m in enumerate(scan.members) if m.role == "chord"]
    assert set(chords) <= {t for t, _ in mm.pairs}, (kind, seed, mm.pairs)
    assert mm.precision >= 0.9, mm.precision


def test_a_chord_split_by_a_joint_is_one_member_at_10_cm() -> None:
    """Warren seed 2 at 10 cm: the 20.8 m chord's regions stopped 1.5 m short
    of each other round a joint, its points there left unlabelled, and the
    pieces 2.3 m apart (more than ``max_gap_m``) stayed two members, neither
    covering 80 % of the chord.  Walking the ends over those points joins
    them."""
    _assert_chords_found_at_10_cm("warren", 2)


def test_gap_filled_needs_points_all_along_and_no_plane_beside() -> None:
    from scipy.spatial import cKDTree

    from planners.structure.assign import gap_filled

    d = np.array([0.0, 1.0, 0.0])
    ts = np.arange(0.0, 6.0, 0.3)
    line = np.column_stack([np.zeros(len(ts)), ts, np.zeros(len(ts))])
    free = np.ones(len(line), bool)
    tree = cKDTree(line)
    assert gap_filled(line, tree, free, np.zeros(3), d, 0.5, 5.5, 0.1, 2.0)
    # a 2.4 m hole in the stretch is an occlusion gap longer than allowed
    holed = line[(ts < 2.0) | (ts > 4.4)]
    assert not gap_filled(
        holed, cKDTree(holed), free[: len(holed)], np.zeros(3), d, 0.5, 5.5, 0.1, 2.0
    )
    # ... and one of 1.5 m is allowed
    holed = line[(ts < 2.0) | (ts > 3.5)]
    assert gap_filled(holed, cKDTree(holed), free[: len(holed)], np.zeros(3), d, 0.5, 5.5, 0.1, 2.0)
    # the same points as the middle row of a plane (ground): not a member's stretch
    xs, ys = np.meshgrid(np.arange(-0.3, 0.31, 0.1), ts, indexing="ij")
    plane = np.column_stack([xs.ravel(), ys.ravel(), np.zeros(xs.size)])
    pfree = np.ones(len(plane), bool)
    assert not gap_filled(plane, cKDTree(plane), pfree, np.zeros(3), d, 0.5, 5.5, 0.15, 2.0)
    # unless the points beside are labelled (members crossing the line)
    assert gap_filled(plane, cKDTree(plane), ~pfree, np.zeros(3), d, 0.5, 5.5, 0.15, 2.0)
    # a stretch no longer than the allowed gap needs no points
    assert gap_filled(
        line[:0], cKDTree(np.zeros((1, 3))), free[:0], np.zeros(3), d, 0.0, 1.9, 0.1, 2.0
    )


def test_collinear_pieces_further_apart_than_the_gap_are_joined_over_a_filled_stretch() -> None:
    from planners.structure.lines import join_groups

    a = _line([0.0, 0.0, 0.0], [1.0, 0.0, 0.0], 4.0, radius=0.2)  # x −4 … 4
    b = _line([11.0, 0.02, 0.0], [1.0, 0.0, 0.0], 3.0, radius=0.2)  # x 8 … 14: 4 m apart
    calls: list[tuple[float, float]] = []

    def filled(p, q, t_from, t_to):
        calls.append((t_from, t_to))
        return True

    assert sorted(sorted(g) for g in join_groups([a, b], 5.0, 2.0, 1.2, 12.0)) == [[0], [1]]
    got = join_groups([a, b], 5.0, 2.0, 1.2, 12.0, filled, 8.0)
    assert [sorted(g) for g in got] == [[0, 1]]
    # the stretch asked about is the one between the pieces, on the longer's line
    assert calls and all(sorted(c) == pytest.approx([4.0, 8.0], abs=0.05) for c in calls)
    # an empty stretch, or one further than the bridge reaches, is not joined
    assert len(join_groups([a, b], 5.0, 2.0, 1.2, 12.0, lambda *_: False, 8.0)) == 2
    assert len(join_groups([a, b], 5.0, 2.0, 1.2, 12.0, filled, 3.5)) == 2
    # a row of pieces offset by more than half a section is not bridged
    c = _line([11.0, 0.15, 0.0], [1.0, 0.0, 0.0], 3.0, radius=0.2)
    assert len(join_groups([a, c], 5.0, 2.0, 1.2, 12.0, filled, 8.0)) == 2


def test_persistent_section_drops_stubs_seen_only_at_joints() -> None:
    from planners.structure.faces import persistent_section

    rng = np.random.default_rng(3)
    t = np.sort(rng.uniform(0.0, 10.0, 300))
    # the chord's own points: a 0.3 m square outline seen all along
    side = rng.integers(0, 4, len(t))
    s = rng.uniform(-0.15, 0.15, len(t))
    uv = np.where(
        (side % 2 == 0)[:, None],
        np.column_stack([np.where(side == 0, -0.15, 0.15), s]),
        np.column_stack([s, np.where(side == 1, -0.15, 0.15)]),
    )
    # stubs: at three joints, points up to 0.6 m off the chord, 10 each
    stub_t = np.repeat([2.25, 5.25, 8.25], 10) + rng.uniform(-0.2, 0.2, 30)
    stub_uv = np.column_stack([rng.uniform(0.3, 0.6, 30), rng.uniform(-0.05, 0.05, 30)])
    all_uv = np.vstack([uv, stub_uv])
    all_t = np.concatenate([t, stub_t])
    keep = persistent_section(all_uv, all_t, 0.2, 0.5, 0.3)
    assert not keep[len(t) :].any()
    assert keep[: len(t)].mean() > 0.95
    # a fine scan (many points a stretch) keeps everything
    assert persistent_section(all_uv, all_t, 0.2, 0.5, 0.3, max_points=5.0).all()
    # too short to tell what persists
    short = all_t < 1.4
    assert persistent_section(all_uv[short], all_t[short], 0.2, 0.5, 0.3).all()


def test_chords_keep_their_sections_among_diagonals_at_10_cm() -> None:
    """Warren seed 6 at 10 cm: each diagonal leaves 5–10 points inside a
    chord's envelope at its joint, a fifth of a chord's points at this
    spacing; the section box grew to the diagonals round after round, the
    axes went 0.2 m aside and neither chord was found (recall 0.33).  The
    box from the cells seen all along the chord finds both."""
    _assert_chords_found_at_10_cm("warren", 6)


def test_a_chord_in_its_truss_plane_is_not_taken_for_a_surface_at_10_cm() -> None:
    """Pratt seed 12 at 10 cm: each chord's largest face lies in the truss's
    plane, and the diagonals and posts (a member every metre, cells three
    spacings wide) covered 59 % of the cells beside it, so both chords were
    dropped as pieces of a larger surface (recall 0.26).  Without the steel
    members crossing it the plane does not go on.  The same holds for the
    lanes of ``clutter.parallel_rows``: the posts and diagonals a metre apart
    read as rows beside the chords (recall 0.42 when only the cell coverage
    was measured again without them)."""
    _assert_chords_found_at_10_cm("pratt", 12)


def test_pieces_of_ground_crossing_each_other_stay_clutter() -> None:
    """Only members kept as steel are left out of a plane's continuation:
    pieces of ground that look linear cross each other too (Pratt seed 2 at
    2 cm: leaving out every crossing candidate kept a 3.3 m strip of ground
    as a member)."""
    from planners.structure.synthetic import make_scan

    scan = make_scan("pratt", 2, spacing_m=0.02)
    model = model_structure(scan.points / scan.scale)
    for m in model.members:
        clutter = float((scan.labels[model.labels == m.id] < 0).mean())
        assert clutter < 0.5, (m.id, m.length_m, clutter)


def test_a_column_s_base_does_not_tilt_its_axis_at_10_cm() -> None:
    """Frame seed 14 at 10 cm: a 3.6 m HEB 300 column's lower half held a few
    wide points at its base; the box of that half moved, and the direction
    through the two halves' box centres leaned 6.3° (found at 5° only).  The
    halves' boxes from the cells seen along the column keep it upright."""
    from planners.structure.synthetic import _angles_deg, make_scan

    scan = make_scan("frame", 14, spacing_m=0.1)
    model = model_structure(scan.points / scan.scale)
    column = scan.true_axes()[0:1]
    assert scan.members[0].role == "column"
    found = np.array([m.axis for m in model.members])
    near = [
        k
        for k, m in enumerate(model.members)
        if np.linalg.norm(m.axis.mean(axis=0) - column[0].mean(axis=0)) < 0.5
    ]
    assert near, "no member at the column"
    assert float(_angles_deg(column, found[near]).min()) < 1.0


def test_persistent_section_keeps_a_member_seen_whole_only_near_the_scanner() -> None:
    """A girder seen whole near the scanners (web and flange) and by one
    flange far from them: the flange's cells persist, the web's are seen in
    a fifth of the stretches, but they hold most of the points, so they are
    the member's own and not stubs."""
    from planners.structure.faces import persistent_section

    rng = np.random.default_rng(5)
    flange_t = rng.uniform(0.0, 18.0, 200)
    # cells 0.1 wide: the flange and web lie mid-cell, away from the noise's reach
    flange_uv = np.column_stack([rng.uniform(-0.2, 0.2, 200), np.full(200, 0.25)])
    web_t = np.concatenate([rng.uniform(0.0, 2.0, 150), rng.uniform(16.0, 18.0, 150)])
    web_uv = np.column_stack([np.full(300, 0.05), rng.uniform(-0.2, 0.2, 300)])
    uv = np.vstack([flange_uv, web_uv]) + rng.normal(0.0, 0.003, (500, 2))
    t = np.concatenate([flange_t, web_t])
    # without the share rule the web goes (but where it meets the flange)
    # and the box shrinks to the flange
    web = np.arange(len(t)) >= 200
    dropped = ~persistent_section(uv, t, 0.1, 0.5, 0.3)
    assert dropped[web & (uv[:, 1] < 0.1)].all() and not dropped[~web].any()
    assert persistent_section(uv, t, 0.1, 0.5, 0.3, min_kept=0.5).all()


def test_persistent_section_share_rule_still_drops_stubs() -> None:
    """Stubs are a few percent of a chord's points: the share rule does not
    bring them back (the hand-built chord of the stub test)."""
    from planners.structure.faces import persistent_section

    rng = np.random.default_rng(3)
    t = rng.uniform(0.0, 10.0, 300)
    uv = np.column_stack([rng.uniform(-0.15, 0.15, 300), rng.choice([-0.15, 0.15], 300)])
    stub_t = np.repeat([2.25, 5.25, 8.25], 10) + rng.uniform(-0.2, 0.2, 30)
    stub_uv = np.column_stack([rng.uniform(0.3, 0.6, 30), rng.uniform(-0.05, 0.05, 30)])
    keep = persistent_section(
        np.vstack([uv, stub_uv]), np.concatenate([t, stub_t]), 0.2, 0.5, 0.3, min_kept=0.5
    )
    assert not keep[300:].any() and keep[:300].mean() > 0.95


def _row_regions(points: np.ndarray, spacing: float) -> np.ndarray:
    from planners.structure.features import line_features
    from planners.structure.lines import grow_regions

    prm = StructureParams().resolve(spacing)
    assert prm.scales_m is not None
    feat = line_features(points, spacing, prm.scales_m, prm.k_neighbours, prm.max_voxels)
    keep = np.ones(len(feat.linearity), bool)
    region = grow_regions(feat, prm.linearity_min, prm.link_angle_deg, keep, spacing)
    return region[feat.grid.inverse]


@settings(max_examples=25, deadline=None)
@given(st.floats(0.05, 0.12), st.floats(0.5, 1.5), st.integers(0, 1000))
def test_a_sparse_row_in_a_fine_scan_is_one_region_and_a_gap_splits_it(
    step: float, gap: float, seed: int
) -> None:
    """A member far from every scanner is a row of points several spacings
    apart (a cross girder in a 2 cm scan: 9 cm).  Its voxels link into one
    region; two such rows with a gap of 0.5 m or more between them stay two."""
    rng = np.random.default_rng(seed)
    a = np.arange(0.0, 2.5, step)
    b = a + a[-1] + gap
    pts = np.column_stack([np.concatenate([a, b]), np.zeros(2 * len(a)), np.zeros(2 * len(a))])
    pts = pts + rng.normal(0.0, 0.002, pts.shape) + [1000.0, 2000.0, 50.0]
    reg = _row_regions(pts, 0.02)
    first, second = reg[: len(a)], reg[len(a) :]
    # the ends of a row are less linear (half a neighbourhood): the middle
    mid = slice(len(a) // 4, 3 * len(a) // 4)
    assert (first[mid] >= 0).all() and len(set(first[mid])) == 1
    assert (second[mid] >= 0).all() and len(set(second[mid])) == 1
    assert set(first[first >= 0]).isdisjoint(set(second[second >= 0]))


def test_a_sparse_row_was_split_without_the_row_link(monkeypatch) -> None:
    """The check above fails without the link along the row (each voxel a
    region of its own)."""
    import planners.structure.lines as lines

    pts = np.column_stack([np.arange(0.0, 2.5, 0.09), np.zeros(28), np.zeros(28)])
    assert len(set(_row_regions(pts, 0.02)[7:21])) == 1
    monkeypatch.setattr(lines, "LINK_ROW", 0.0)
    assert len(set(_row_regions(pts, 0.02)[7:21])) > 5


def test_sparse_cross_girders_and_a_girder_seen_by_one_flange_at_2_cm() -> None:
    """Grillage seed 1 at 2 cm: three IPE 200 cross girders are rows of 27–47
    points (no region formed); seed 11: an 18 m HEB 400 seen whole near the
    scanners and by its top flange in the middle, whose box shrank to that
    flange (axis 0.24 m off).  All four are found."""
    from planners.structure.synthetic import make_scan, match_members

    for seed, wanted in ((1, {6, 7, 8}), (11, {0})):
        scan = make_scan("grillage", seed, spacing_m=0.02)
        model = model_structure(scan.points / scan.scale)
        found = np.array([m.axis for m in model.members])
        mm = match_members(scan.true_axes(), scan.true_depths(), found)
        assert wanted <= {t for t, _ in mm.pairs}, (seed, mm.pairs)
        assert mm.precision >= 0.9, (seed, mm.precision)
