"""Reachable jump placements of the inspection layout (seed §3.2)."""

from __future__ import annotations

import itertools
from typing import Any

import numpy as np
from shapely.geometry import box

from planners.inspection.jumps import unreachable_reason
from planners.inspection.layout import (
    DriveLine,
    JumpSite,
    LayoutParams,
    _on_face,
    next_placement,
    pose_from,
    reachable_placement,
)
from robots import load_robot

ARA: Any = load_robot("ara")


def _line(
    width: float, origin: tuple[float, float, float], normal: tuple[float, float, float]
) -> DriveLine:
    n = np.asarray(normal, float)
    d = np.array([1.0, 0.0, 0.0]) if abs(n[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    return DriveLine(
        0, 0, np.asarray(origin, float), d, n, -2.0, 2.0, box(-3, -width / 2, 3, width / 2)
    )


def test_on_face_brute_force() -> None:
    p = LayoutParams()
    ln = _line(0.31, (0, 0, 0), (0, 0, 1))
    for t in np.arange(-0.12, 0.121, 0.01):
        T = pose_from(np.array([0.0, t, 0.0]), np.array([1.0, 0, 0]), np.array([0, 0, 1.0]))
        expect = abs(t) + 0.06 + 0.01 <= 0.155 + 1e-9
        assert _on_face(ln, T, (-0.59, 0.09), p) == expect, t


def test_the_cheapest_accepted_placement_is_chosen() -> None:
    """Against every candidate enumerated independently: the placement kept
    is accepted by the test and no cheaper candidate is."""
    p = LayoutParams(max_reach_tries=10_000)
    la = _line(0.31, (0, 0, 0), (0, 0, 1))
    lb = _line(0.31, (0.6, 0, 0.3), (0, 0, 1))
    S0 = pose_from(np.zeros(3), np.array([1.0, 0, 0]), np.array([0, 0, 1.0]))
    L0 = pose_from(np.array([0.6, 0, 0.3]), np.array([1.0, 0, 0]), np.array([0, 0, 1.0]))

    def accept(S: np.ndarray, L: np.ndarray, joint: np.ndarray) -> bool:
        return bool(S[1, 3] > 0.07 and L[0, 3] > 0.62)  # across ≥ 8 cm, landing ≥ 2 cm on

    site = JumpSite(0, 0, 0, 0, 1, S0, L0, np.zeros(3), lb, la)
    reachable_placement(site, la, lb, (-1.0, 1.0), accept, None, np.zeros((0, 3)), p)
    assert site.reachable is True
    assert accept(site.standing, site.landing, site.joint)
    cost = (
        site.offsets_m[0] + abs(site.offsets_m[1]) + abs(site.offsets_m[2]) + abs(site.offsets_m[3])
    )
    across = (0.0, 0.04, -0.04, 0.08, -0.08)
    best = min(
        b + abs(t) + abs(a) + abs(u)
        for b, t, a, u in itertools.product(
            (0.0, 0.05, 0.1), across, (0.0, -0.05, 0.05, 0.1), across
        )
        if t > 0.07 and a > 0.02
    )
    assert abs(cost - best) < 1e-9
    # nothing accepted: the nearest placement stays, named unreachable
    site2 = JumpSite(0, 0, 0, 0, 1, S0, L0, np.zeros(3), lb, la)
    capped = LayoutParams()
    reachable_placement(
        site2, la, lb, (-1.0, 1.0), lambda *a: False, None, np.zeros((0, 3)), capped
    )
    assert site2.reachable is False and np.array_equal(site2.standing, S0)
    assert site2.reach_tries == capped.max_reach_tries


def test_next_placement_skips_the_planned_ones() -> None:
    """After a placement whose jump came too close, the next is the cheapest
    accepted one not yet planned (brute force over the same candidates),
    measured from the nearest placement, not from the current one; with
    every accepted one skipped the site keeps its placement."""
    p = LayoutParams(max_reach_tries=10_000)
    la = _line(0.31, (0, 0, 0), (0, 0, 1))
    lb = _line(0.31, (0.6, 0, 0.3), (0, 0, 1))
    S0 = pose_from(np.zeros(3), np.array([1.0, 0, 0]), np.array([0, 0, 1.0]))
    L0 = pose_from(np.array([0.6, 0, 0.3]), np.array([1.0, 0, 0]), np.array([0, 0, 1.0]))

    def accept(S: np.ndarray, L: np.ndarray, joint: np.ndarray) -> bool:
        return bool(S[1, 3] > 0.07 or L[0, 3] > 0.62)

    site = JumpSite(0, 0, 0, 0, 1, S0, L0, np.zeros(3), lb, la)
    reachable_placement(site, la, lb, (-1.0, 1.0), accept, None, np.zeros((0, 3)), p)
    first = site.offsets_m
    skip = frozenset({first})
    assert next_placement(site, accept, None, np.zeros((0, 3)), p, skip)
    assert site.offsets_m not in skip and accept(site.standing, site.landing, site.joint)
    across = (0.0, 0.04, -0.04, 0.08, -0.08)
    cands = [
        c
        for c in itertools.product((0.0, 0.05, 0.1), across, (0.0, -0.05, 0.05, 0.1), across)
        if (c[1] > 0.07 or c[2] > 0.02) and c not in skip
    ]
    best = min(b + abs(t) + abs(a) + abs(u) for b, t, a, u in cands)
    got = site.offsets_m
    assert abs(got[0] + abs(got[1]) + abs(got[2]) + abs(got[3]) - best) < 1e-9
    # the placement is the nearest one moved by the offsets (not the first choice's)
    expect = S0[:3, 3] - got[0] * S0[:3, 0] + got[1] * S0[:3, 1]
    assert np.allclose(site.standing[:3, 3], expect)
    # every accepted placement skipped: nothing found, the site stays where it was
    everything = frozenset(cands) | skip
    before = site.standing.copy(), site.offsets_m
    assert not next_placement(site, accept, None, np.zeros((0, 3)), p, everything)
    assert np.array_equal(site.standing, before[0]) and site.offsets_m == before[1]
    assert site.reachable is True


def test_unreachable_reason_names_the_arm() -> None:
    W = np.eye(4)
    W[:3, 3] = (0.149, 0.013, -0.452)  # a chord's top flange to the diagonal under it
    W[:3, :3] = np.array([[0.43, 0, -0.9], [0, -1, 0], [-0.9, 0, -0.43]]).T @ np.diag([1, 1, 1])
    W[:3, 2] = (0.0, 1.0, 0.0)
    W[:3, 0] = (0.43, 0.0, -0.9)
    W[:3, 1] = np.cross(W[:3, 2], W[:3, 0])
    why = unreachable_reason(ARA, W)
    assert why is not None and "0.50 m" in why
    ok = np.eye(4)
    ok[:3, 3] = (0.3, 0.0, 0.0)
    assert unreachable_reason(ARA, ok) is None
