"""Stubby members (``pipeline.STUBBY_SLENDERNESS``): one that meets fewer
than two joints is not a member between others (a person-sized box beside
the structure); one between two members is kept."""

from __future__ import annotations

import numpy as np

import planners.structure.pipeline as pipeline
from planners.structure import model_structure
from tests.structure.test_model_structure import _box_member
from tests.structure.test_sparse_rows import _scores

SPACING = 0.02
ORIGIN = np.array([4.5e5, 5.3e6, 120.0])


def _vertical_members(model) -> list:
    return [m for m in model.members if abs(float(m.direction[2])) > 0.95]


def _box_under_a_chord(seed: int = 0) -> np.ndarray:
    """A 6 m chord 2 m up and a 0.40 × 0.50 × 1.6 m box standing under it,
    its top 5 cm below the chord's bottom face: slenderness 3.2."""
    rng = np.random.default_rng(seed)
    chord = _box_member([0, 0, 2.0], [6, 0, 2.0], 0.2, 0.3, SPACING, rng)
    box = _box_member([5.5, 0, 0.25], [5.5, 0, 1.80], 0.40, 0.50, SPACING, rng)
    return np.vstack([chord, box]) + ORIGIN


def test_a_stubby_box_meeting_one_member_is_clutter(monkeypatch) -> None:
    pts = _box_under_a_chord()
    model = model_structure(pts)
    assert len(model.members) == 1 and abs(float(model.members[0].direction[0])) > 0.99
    monkeypatch.setattr(pipeline, "STUBBY_SLENDERNESS", 0.0)
    kept = model_structure(pts)
    assert len(_vertical_members(kept)) == 1, [m.axis - ORIGIN for m in kept.members]


def test_a_stubby_member_between_two_joints_is_kept(monkeypatch) -> None:
    """Frame seed 12 at 10 cm: a member the scan measures stubbier than 3.5
    section depths meets two joints and is a true member (recall 0.95);
    dropping every stubby member loses it (0.90)."""
    kept = _scores("frame", 12)[0]
    assert kept >= 0.95
    monkeypatch.setattr(pipeline, "STUBBY_JOINTS", 99)
    assert _scores("frame", 12)[0] < kept - 0.04


def test_10_cm_persons_beside_a_grillage_are_clutter(monkeypatch) -> None:
    """Grillage seeds 1, 12 and 16 at 10 cm: the person-sized box stands
    1 m outside the footprint with its head within a joint's reach of an
    edge girder, meets it, and was a member in each; the scans' vertical
    members are exactly these (a grillage has none)."""
    from planners.structure.synthetic import make_scan

    for seed in (1, 12, 16):
        scan = make_scan("grillage", seed, spacing_m=0.1)
        pts = scan.points / scan.scale
        assert _vertical_members(model_structure(pts)) == [], seed
    monkeypatch.setattr(pipeline, "STUBBY_SLENDERNESS", 0.0)
    for seed in (1, 12, 16):
        scan = make_scan("grillage", seed, spacing_m=0.1)
        assert len(_vertical_members(model_structure(scan.points / scan.scale))) >= 1, seed
