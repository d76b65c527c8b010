"""Large planes set apart before the member search (``planners.structure.surfaces``):
a slab with a column through it, a girder under a deck, a truss plane that
is not a surface, LAS ground, the new generator types and the scene's
outlines."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from planners.structure import model_structure
from planners.structure.sections import SECTIONS, member_surface_points
from planners.structure.surfaces import SURFACE_KINDS, find_surfaces
from planners.structure.synthetic import make_scan, match_members

SP = 0.04


def _rect(
    rng: np.random.Generator, o: np.ndarray, a: np.ndarray, b: np.ndarray, sp: float
) -> np.ndarray:
    """Jittered points every ``sp`` on the rectangle o + s a + t b."""
    na = max(2, int(np.linalg.norm(a) / sp))
    nb = max(2, int(np.linalg.norm(b) / sp))
    s, t = np.meshgrid((np.arange(na) + 0.5) / na, (np.arange(nb) + 0.5) / nb, indexing="ij")
    s = s.ravel() + rng.uniform(-0.3, 0.3, s.size) / na
    t = t.ravel() + rng.uniform(-0.3, 0.3, t.size) / nb
    p = o + s[:, None] * a + t[:, None] * b
    return p + rng.normal(0, 0.002, p.shape)


def _slab(
    rng: np.random.Generator, lo: np.ndarray, hi: np.ndarray, sp: float = SP, top: bool = False
) -> np.ndarray:
    """A slab's soffit and edge faces (its top too with ``top``)."""
    dx, dy, dz = hi - lo
    ex, ey, ez = np.eye(3)
    parts = [
        _rect(rng, lo, dx * ex, dy * ey, sp),
        _rect(rng, lo, dx * ex, dz * ez, sp),
        _rect(rng, lo + dy * ey, dx * ex, dz * ez, sp),
        _rect(rng, lo, dy * ey, dz * ez, sp),
        _rect(rng, lo + dx * ex, dy * ey, dz * ez, sp),
    ]
    if top:
        parts.append(_rect(rng, lo + dz * ez, dx * ex, dy * ey, sp))
    return np.concatenate(parts)


def _member(name: str, p0: np.ndarray, p1: np.ndarray, roll: float, sp: float = SP) -> np.ndarray:
    pts, _ = member_surface_points(SECTIONS[name], p0, p1, roll, sp, np.random.default_rng(1))
    return pts


def _column_through_slab(
    seed: int, x: float, y: float, z_slab: float, yaw: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """A 6 m HEB 300 column through a 10 × 8 m slab 0.2 m thick: points,
    member labels (0 column, −1 slab), the column's axis, and the slab's mask."""
    rng = np.random.default_rng(seed)
    lo, hi = np.array([0.0, 0.0, z_slab]), np.array([10.0, 8.0, z_slab + 0.2])
    slab = _slab(rng, lo, hi)
    axis = np.array([[x, y, 0.0], [x, y, 6.0]])
    col = _member("HEB 300", axis[0], axis[1], yaw)
    # the column's surface inside the slab is hidden
    col = col[(col[:, 2] < z_slab - 0.002) | (col[:, 2] > z_slab + 0.202)]
    pts = np.concatenate([slab, col])
    lab = np.concatenate([np.full(len(slab), -1), np.zeros(len(col), np.int64)])
    return pts, lab, axis, lab < 0


@settings(max_examples=4, deadline=None, derandomize=True)
@given(
    seed=st.integers(0, 2**16),
    x=st.floats(2.0, 8.0),
    y=st.floats(2.0, 6.0),
    z=st.floats(2.5, 3.5),
    yaw=st.floats(0, np.pi),
)
def test_slab_points_are_set_apart_the_column_mostly_not(
    seed: int, x: float, y: float, z: float, yaw: float
) -> None:
    pts, _, _, slab = _column_through_slab(seed, x, y, z, yaw)
    surfaces, on = find_surfaces(pts, SP, 1.2, seed=0)
    assert [s.kind for s in surfaces] == ["deck/slab"]
    (s,) = surfaces
    assert abs(s.normal[2]) > 0.999 and abs(s.offset - z) < 0.01
    assert on[slab].mean() > 0.97  # its soffit and its edge faces
    # the column loses at most the band round the slab: nothing covers
    # much of either side of it, so the slab's band (0.4 m) goes both ways
    assert on[~slab].mean() < 0.15
    lost = pts[~slab & on]
    assert lost.size == 0 or (lost[:, 2].min() > z - 0.45 and lost[:, 2].max() < z + 0.45)


def test_a_column_through_a_slab_is_one_member_and_the_slab_none() -> None:
    pts, _, axis, slab = _column_through_slab(3, 4.3, 3.1, 3.0, 0.4)
    model = model_structure(pts, params=None)
    assert [s.kind for s in model.surfaces] == ["deck/slab"]
    assert len(model.members) == 1
    m = model.members[0]
    assert abs(m.direction[2]) > 0.99
    got = match_members(axis[None], [0.3], m.axis[None])
    assert got.recall == 1.0 and got.precision == 1.0
    assert (model.labels[slab] == -1).all()


def test_without_the_separation_the_slab_is_not_set_apart() -> None:
    from planners.structure import pipeline

    pts, _, _, _ = _column_through_slab(3, 4.3, 3.1, 3.0, 0.4)
    old = pipeline.SEPARATE_SURFACES
    pipeline.SEPARATE_SURFACES = False
    try:
        model = model_structure(pts)
    finally:
        pipeline.SEPARATE_SURFACES = old
    assert model.surfaces == []


def test_a_girder_under_a_deck_is_found_from_its_web_and_bottom_flange() -> None:
    rng = np.random.default_rng(5)
    sec = SECTIONS["IPE 500"]
    z_soffit = 4.0
    deck = _slab(rng, np.array([-1.0, -3.0, z_soffit]), np.array([13.0, 3.0, z_soffit + 0.25]))
    axis = np.array([[0.0, 0.0, z_soffit - sec.h / 2], [12.0, 0.0, z_soffit - sec.h / 2]])
    g = _member("IPE 500", axis[0], axis[1], 0.0)
    g = g[g[:, 2] < z_soffit - 0.002]  # its top flange's top is in the deck
    pts = np.concatenate([deck, g])
    model = model_structure(pts)
    assert [s.kind for s in model.surfaces] == ["deck/slab"]
    got = match_members(axis[None], [sec.h], np.array([m.axis for m in model.members]))
    assert got.recall == 1.0 and got.precision == 1.0
    assert len(model.members) == 1
    # nothing of the deck is a member's
    assert (model.labels[: len(deck)] == -1).all()


def test_a_truss_plane_is_no_surface() -> None:
    """A vertical plane of strips (chords, posts, diagonals: a lattice with
    metres of air between them) holds no square larger than a section."""
    rng = np.random.default_rng(2)
    parts = []
    for z in (0.0, 2.0):  # chords' webs, 0.3 m deep
        parts.append(
            _rect(rng, np.array([0, 0, z]), np.array([12.0, 0, 0]), np.array([0, 0, 0.3]), SP)
        )
    for x in np.arange(0.0, 12.1, 2.0):  # posts, 0.2 m wide
        parts.append(
            _rect(rng, np.array([x, 0, 0]), np.array([0.2, 0, 0]), np.array([0, 0, 2.3]), SP)
        )
    pts = np.concatenate(parts)
    surfaces, on = find_surfaces(pts, SP, 1.2, seed=0)
    assert surfaces == [] and not on.any()


def test_ground_and_walls_are_named_and_the_result_is_deterministic() -> None:
    rng = np.random.default_rng(4)
    ground = _rect(rng, np.array([-5.0, -5, 0]), np.array([10.0, 0, 0]), np.array([0, 10.0, 0]), SP)
    wall = _rect(rng, np.array([-4.0, 3, 0]), np.array([8.0, 0, 0]), np.array([0, 0, 3.0]), SP)
    pts = np.concatenate([ground, wall])
    a, on_a = find_surfaces(pts, SP, 1.2, seed=0)
    b, on_b = find_surfaces(pts, SP, 1.2, seed=0)
    assert sorted(s.kind for s in a) == ["ground", "wall"]
    assert np.array_equal(on_a, on_b)
    assert [(s.kind, s.offset) for s in a] == [(s.kind, s.offset) for s in b]
    # the wall's points are left out of the member search; the ground's stay
    # in it (``GROUND_OUT``: the clutter stage drops its pieces), but for
    # the wall's foot and its band round the rim (a pier's end faces; here
    # the ground along the foot, 1.2 m each side: 19 of its 100 m²)
    assert on_a[len(ground) :].mean() > 0.97 and on_a[: len(ground)].mean() < 0.25
    # a column a metre in front of the wall's middle is not taken
    col = _member("HEB 300", np.array([0.0, 2.0, 0.0]), np.array([0.0, 2.0, 3.0]), 0.0)
    _, on_c = find_surfaces(np.concatenate([pts, col]), SP, 1.2, seed=0)
    assert on_c[len(pts) :].mean() < 0.1
    for s in a:
        assert s.kind in SURFACE_KINDS and s.outline.shape[1] == 3
        assert np.abs(s.outline @ s.normal - s.offset).max() < 1e-6


def test_las_ground_class_names_the_ground_and_leaves_its_points_out() -> None:
    rng = np.random.default_rng(6)
    low = _rect(rng, np.array([0.0, 0, 3]), np.array([8.0, 0, 0]), np.array([0, 8.0, 0]), SP)
    rough = rng.uniform([0, 0, -0.3], [8, 8, 0.3], (4000, 3))  # terrain: no plane
    pts = np.concatenate([low, rough])
    cls = np.concatenate([np.full(len(low), 1), np.full(len(rough), 2)])
    surfaces, on = find_surfaces(pts, SP, 1.2, seed=0, classification=cls)
    assert on[len(low) :].all()
    # a level surface with nothing under it but ground is a slab when the
    # caller's classes say where the ground is
    assert [s.kind for s in surfaces] == ["deck/slab"]
    cls2 = np.full(len(pts), 2)
    surfaces2, _ = find_surfaces(pts, SP, 1.2, seed=0, classification=cls2)
    assert [s.kind for s in surfaces2] == ["ground"]
    with pytest.raises(Exception, match="classification"):
        model_structure(pts, classification=cls[:-1])


@pytest.mark.parametrize("kind", ["deck", "frame_slabs"])
def test_new_generator_types(kind: str) -> None:
    sc = make_scan(kind, 0, spacing_m=0.1)
    roles = {m.role for m in sc.members}
    kinds = [k for k, _ in sc.surfaces]
    # most of the scan is concrete and ground, not steel
    assert (sc.labels < 0).mean() > 0.4
    if kind == "deck":
        assert 3 <= sum(m.role == "main" for m in sc.members) <= 5
        assert "cross" in roles and kinds.count("deck/slab") == 1 and "wall" in kinds
        # the scanner under the deck sees its soffit
        soffit = sc.surfaces[kinds.index("deck/slab")][1]
        z = float(soffit[0, 2])
        assert np.sum(np.abs(sc.points[:, 2] - z) < 0.01) > 200
        # the girders' tops are in the deck: no point of a girder above the soffit
        mains = [m.id for m in sc.members if m.role == "main"]
        assert sc.points[np.isin(sc.labels, mains), 2].max() <= z + 0.01
    else:
        cols = [m for m in sc.members if m.role == "column"]
        assert 2 <= kinds.count("deck/slab") <= 4 and "ground" in kinds
        # columns run on through the slabs, from the ground to the roof
        assert all(float(m.axis[1, 2] - m.axis[0, 2]) > 5.5 for m in cols)
    assert make_scan(kind, 0, spacing_m=0.1).points.tobytes() == sc.points.tobytes()


def test_the_scene_draws_surface_outlines() -> None:
    from server.scene import ara_inspect

    calls: list[tuple[str, Any]] = []

    class Scene:
        def add_line_segments(self, name: str, **kw: Any) -> None:
            calls.append((name, kw))

        def add_label(self, name: str, **kw: Any) -> None:
            calls.append((name, kw))

    class Ctx:
        scene = Scene()

    res = {
        "surfaces": [
            {"id": 0, "kind": "deck/slab", "outline": [[0, 0, 1], [2, 0, 1], [2, 2, 1], [0, 2, 1]]}
        ]
    }
    ara_inspect._draw_surfaces(Ctx(), "/r", res, lambda p: np.asarray(p, np.float32))  # type: ignore[arg-type]
    (seg,) = [kw for n, kw in calls if n == "/r/surfaces"]
    assert seg["points"].shape == (4, 2, 3) and seg["colors"] == ara_inspect.SURFACE_RGB
    assert [kw["text"] for n, kw in calls if n.startswith("/r/surface_labels")] == ["deck/slab"]
    calls.clear()
    ara_inspect._draw_surfaces(Ctx(), "/r", {}, lambda p: p)  # type: ignore[arg-type]
    assert calls == []
