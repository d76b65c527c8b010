"""The planning-time part of the ``ara.inspect`` robot program (seed 000 §3.1–3.2): lay out the main route's stretches and jump sites
(:mod:`.layout`), plan every jump (:mod:`.jumps`), place the stretches after
each planned jump, and shape what the compiler reads — the ``program``
part of the summary, the jump trajectories as arrays — with the checks on
the jumps.  The command program itself is assembled from exactly these
stored parts by the plan kind (``server/kinds/ara_inspect.py``), both at
planning time (for the program checks) and when compiling.

World frame: ``world_origin_m`` is zeros unless the cloud's coordinates
exceed 10 km in magnitude (a survey frame), then the cloud's bounding-box
minimum floored to whole metres; poses in ``program`` are in the model
(cloud) frame, and the compiler subtracts the origin for ``base_pose``.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.spatial import cKDTree

from planners.inspection.jumps import (
    JumpSetParams,
    PlannedJumps,
    adapt_robot,
    face_samples,
    plan_site_jumps,
    reach_test,
)
from planners.inspection.layout import (
    LayoutParams,
    ProgramLayout,
    layout_program,
    next_placement,
    relayout_stretch,
)
from planners.inspection.plan import InspectionPlan
from planners.result import Check, check_ge
from planners.structure.model import StructureModel

__all__ = ["ProgramParts", "plan_route_program", "world_origin"]

#: Coordinates beyond this (m) put the world origin at the cloud's corner.
FAR_M = 10_000.0
#: Sites named in a check's message at most.
_LISTED = 5


def world_origin(points: np.ndarray) -> np.ndarray:
    """float64 (3,): zeros unless some coordinate of ``points`` exceeds
    :data:`FAR_M` in magnitude, then the bounding-box minimum floored to
    whole metres."""
    p = np.asarray(points, float).reshape(-1, 3)
    if len(p) == 0 or float(np.max(np.abs(p))) <= FAR_M:
        return np.zeros(3)
    return np.floor(p.min(axis=0)).astype(np.float64)


@dataclass
class ProgramParts:
    """What :func:`plan_route_program` stores: ``summary`` (JSON-ready),
    ``arrays``, ``checks``, ``metrics``, and the layout and jumps for tests."""

    summary: dict[str, Any]
    arrays: dict[str, np.ndarray]
    checks: list[Check]
    metrics: dict[str, float]
    layout: ProgramLayout
    jumps: PlannedJumps
    timings_s: dict[str, float] = field(default_factory=dict)


def _mat(T: np.ndarray | None) -> list[list[float]] | None:
    return None if T is None else [[float(x) for x in row] for row in np.asarray(T, float)]


def plan_route_program(
    model: StructureModel,
    plan: InspectionPlan,
    points: np.ndarray,
    robot: Any,
    *,
    layout: LayoutParams | None = None,
    jumps: JumpSetParams | None = None,
    joint_names: list[str] | None = None,
    progress: Callable[[float, str], None] | None = None,
    mapper: Callable[..., list[Any]] | None = None,
) -> ProgramParts:
    """Stretches and planned jumps of ``plan``'s main route (seed §3.2 per
    jump: :func:`planners.switching.jump.plan_inchworm_jump`, OMPL
    RRT-Connect), stored for the compiler.

    ``robot``: the ARA model (or a ``JumpRobot``); ``points``: the scan the
    model was made from (model frame, metres).  Stretches are placed in
    driving order; a stretch after a jump that could not be planned, and
    every later one, is left unplaced (the program ends before that jump,
    and the ``jumps_planned`` check names it)."""
    lp = layout or LayoutParams()
    jp = jumps or JumpSetParams()
    obstacles = np.vstack([np.asarray(points, float).reshape(-1, 3), face_samples(model, 0.02)])
    # Reachable placements (seed §3.2): with a robot model, each site's feet
    # go where the arm can land foot 1 (layout.reachable_placement).
    adapted = adapt_robot(robot, jp.jump)
    reach = reach_test(robot, model, points, jp, adapted=adapted) if adapted is not None else None
    lay = layout_program(model, plan, lp, obstacles=obstacles, reach=reach)

    def plan_all() -> PlannedJumps:
        return plan_site_jumps(
            robot,
            lay,
            model,
            points,
            jp,
            foot=(lp.foot_length_m, lp.foot_width_m),
            progress=progress,
            mapper=mapper,
        )

    pj = plan_all()
    if reach is not None:
        pj = _relayout_close_jumps(lay, pj, plan, reach, obstacles, lp, jp, plan_all)
    placed = 1 if lay.stretches and lay.stretches[0].edges else 0
    for r in range(1, len(lay.stretches)):
        prev = lay.stretches[r - 1]
        if prev.ends_in is None:
            break
        pl = pj.placed[prev.ends_in]
        if pl.foot2 is None:
            break
        relayout_stretch(lay, plan, r, pl.foot2)
        placed = r + 1

    # ---- arrays: the unique jumps' trajectories, concatenated
    lens = [0 if p is None else len(p.times) for p in pj.plans]
    offsets = np.r_[0, np.cumsum(lens)].astype(np.int64)
    n_j = len(joint_names) if joint_names else 6
    qs = [p.joint_trajectory for p in pj.plans if p is not None]
    ts = [p.times for p in pj.plans if p is not None]
    arrays = {
        "jump_q": np.vstack(qs).astype(np.float64) if qs else np.zeros((0, n_j)),
        "jump_times": np.concatenate(ts).astype(np.float64) if ts else np.zeros(0),
        "jump_offsets": offsets,
    }
    unique = []
    for k, p in enumerate(pj.plans):
        unique.append(
            {
                "index": k,
                "error": pj.errors[k],
                "planned": p is not None,
                "foot1_target": _mat(p.foot1_target) if p is not None else None,
                "foot2_target": _mat(p.foot2_target) if p is not None else None,
                "duration_s": float(p.times[-1]) if p is not None else None,
                "phases": [
                    {
                        "name": ph.name,
                        "anchor": ph.anchor,
                        "magnets": ph.magnets,
                        "start": ph.start,
                        "stop": ph.stop,
                        "t_start_s": ph.t_start_s,
                        "t_end_s": ph.t_end_s,
                    }
                    for ph in p.phases
                ]
                if p is not None
                else [],
                "magnet_commands": p.magnet_commands if p is not None else [],
                "sites": [pl.site for pl in pj.placed if pl.unique == k],
            }
        )
    sites = []
    for site, pl in zip(lay.sites, pj.placed, strict=True):
        t = plan.transitions[site.transition]
        sites.append(
            {
                "transition": site.transition,
                "vertex": _json_vertex(site.vertex),
                "landing_vertex": _json_vertex(site.landing_vertex),
                "from_member": site.from_member,
                "to_member": site.to_member,
                "kind": t.kind,
                "joint": [float(x) for x in site.joint],
                "standing": _mat(site.standing),
                "landing_target": _mat(site.landing),
                "unique": pl.unique,
                "foot1": _mat(pl.foot1),
                "foot2": _mat(pl.foot2),
                "min_clearance_m": pl.min_clearance_m,
                "min_self_clearance_m": pl.min_self_clearance_m,
                "on_steel": pl.on_steel,
                "landing_misfit_m": pl.landing_misfit_m,
                "error": pl.error,
            }
        )
    stretches = [
        {
            "start": _mat(st.start),
            "waypoints": [[float(x) for x in w] for w in st.waypoints],
            "members": list(st.members),
            "ends_in": st.ends_in,
        }
        for st in lay.stretches[:placed]
    ]
    summary = {
        "world_origin_m": [float(x) for x in world_origin(points)],
        "joint_names": list(joint_names or []),
        "foot_spacing_m": lp.foot_spacing_m,
        "capture_every_m": lp.capture_every_m,
        "clearance_margin_m": jp.jump.clearance_margin_m,
        "stretches": stretches,
        "stretches_total": len(lay.stretches),
        "sites": sites,
        "unique_jumps": unique,
        "planner_calls": pj.planner_calls,
        "timings_s": dict(pj.timings_s),
    }
    checks = _checks(plan, lay, pj, jp)
    metrics = {
        "jump_sites": float(len(lay.sites)),
        "jumps_unique": float(len(pj.plans)),
        "jumps_planned": float(sum(pl.foot1 is not None for pl in pj.placed)),
        "jump_planner_calls": float(pj.planner_calls),
        **{f"jump_{k}_time_s": float(v) for k, v in pj.timings_s.items()},
    }
    clear = [pl.min_clearance_m for pl in pj.placed if pl.min_clearance_m is not None]
    if clear:
        metrics["jump_min_clearance_m"] = float(min(clear))
    return ProgramParts(summary, arrays, checks, metrics, lay, pj)


def _too_close(pl: Any, jp: JumpSetParams) -> bool:
    """A placed jump under the scene or self clearance margin."""
    return pl.min_clearance_m is not None and (
        pl.min_clearance_m < jp.jump.clearance_margin_m
        or (pl.min_self_clearance_m is not None and pl.min_self_clearance_m < jp.jump.self_margin_m)
    )


def _relayout_close_jumps(
    lay: ProgramLayout,
    pj: PlannedJumps,
    plan: InspectionPlan,
    reach: Callable[[np.ndarray, np.ndarray, np.ndarray], bool],
    obstacles: np.ndarray,
    lp: LayoutParams,
    jp: JumpSetParams,
    plan_all: Callable[[], PlannedJumps],
) -> PlannedJumps:
    """Sites whose planned jump comes closer than the margins move on to
    their next reachable placement (:func:`planners.inspection.layout.next_placement`,
    seed §3.2) and every jump is planned again, at most
    ``lp.clearance_relayouts`` rounds.  A site whose new placement plans no
    jump at all goes back to the closest-but-planned one (whose clearance
    the ``jump_clearance`` check then reports, failing); the margins
    themselves are never lowered."""
    tree = cKDTree(obstacles) if len(obstacles) else None
    tried: dict[int, set[tuple[float, float, float, float]]] = {}
    fallback: dict[int, tuple[np.ndarray, np.ndarray, tuple[float, float, float, float]]] = {}
    for _ in range(int(lp.clearance_relayouts)):
        moved = False
        for pl in pj.placed:
            site = lay.sites[pl.site]
            retry = _too_close(pl, jp) or (pl.foot1 is None and pl.site in fallback)
            if not retry or site.reachable is not True:
                continue
            seen = tried.setdefault(pl.site, set())
            seen.add(site.offsets_m)
            if pl.foot1 is not None:
                fallback.setdefault(pl.site, (site.standing, site.landing, site.offsets_m))
            if next_placement(site, reach, tree, obstacles, lp, frozenset(seen)):
                moved = True
        if not moved:
            break
        pj = plan_all()
    back = False
    for pl in pj.placed:
        if pl.foot1 is None and pl.site in fallback:
            site = lay.sites[pl.site]
            site.standing, site.landing, site.offsets_m = fallback[pl.site]
            back = True
    if back:
        pj = plan_all()
    if lay.stretches and lay.stretches[0].edges and lay.stretches[0].ends_in is not None:
        relayout_stretch(lay, plan, 0, lay.stretches[0].start)
    return pj


def _json_vertex(v: Any) -> int | str:
    return int(v) if isinstance(v, int | np.integer) else repr(v)


def _name(plan: InspectionPlan, site_transition: int) -> str:
    t = plan.transitions[site_transition]
    return f"transition {site_transition} (vertex {t.vertex}, member {t.from_member}→{t.to_member})"


def _checks(
    plan: InspectionPlan, lay: ProgramLayout, pj: PlannedJumps, jp: JumpSetParams
) -> list[Check]:
    """``jumps_planned`` (every jump site planned, else the first few named
    with the planner's reason), ``jump_clearance`` (the smallest clearance of
    every placed jump against its own site's obstacles ≥ the margin),
    ``landings_on_steel`` (both feet of every placed jump on the landing
    face)."""
    n = len(pj.placed)
    bad = [(lay.sites[pl.site].transition, pl.error) for pl in pj.placed if pl.foot1 is None]
    if not bad:
        msg = (
            f"all {n} inch-worm jumps planned ({len(pj.plans)} distinct geometries, "
            f"{pj.planner_calls} planner calls)"
        )
    else:
        named = "; ".join(f"{_name(plan, t)}: {e}" for t, e in bad[:_LISTED])
        more = f"; and {len(bad) - _LISTED} more" if len(bad) > _LISTED else ""
        msg = f"{len(bad)} of {n} inch-worm jumps not planned: {named}{more}"
    checks = [Check("jumps_planned", not bad, float(len(bad)), 0.0, msg)]
    clear = [pl.min_clearance_m for pl in pj.placed if pl.min_clearance_m is not None]
    margin = jp.jump.clearance_margin_m
    if clear:
        worst = min(range(len(clear)), key=lambda i: clear[i])
        c = check_ge(
            "jump_clearance",
            float(clear[worst]),
            margin,
            "smallest clearance of the placed jumps",
            " m",
        )
        checks.append(c)
    else:
        checks.append(
            Check(
                "jump_clearance",
                n == 0,
                None,
                margin,
                "no jump to measure" if n == 0 else "no jump was planned: no clearance measured",
            )
        )
    off = [
        (lay.sites[pl.site].transition, pl.landing_misfit_m)
        for pl in pj.placed
        if pl.foot1 is not None and not pl.on_steel
    ]
    placed = sum(pl.foot1 is not None for pl in pj.placed)
    if off:
        named = "; ".join(
            f"{_name(plan, t)} ({'?' if m is None or not math.isfinite(m) else f'{m * 1000:.1f} mm'} off the plane)"
            for t, m in off[:_LISTED]
        )
        msg = f"{len(off)} of {placed} placed jumps land a foot off the landing face: {named}"
    else:
        msg = f"both feet of all {placed} placed jumps land on the landing face"
    checks.append(Check("landings_on_steel", not off, float(len(off)), 0.0, msg))
    return checks
