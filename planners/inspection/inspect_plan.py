"""The ``ara.inspect`` kind's entry point in the one result contract:
:func:`plan_inspection_result` crops a whole-structure scan,
models it (:func:`planners.structure.model_structure`: members, faces,
joints, member graph), plans the ARA's inspection route over it
(:func:`planners.inspection.plan_inspection`: gaps, VOCPP route, mobile /
inch-worm transitions) and shapes the stored
:class:`planners.result.PlanResult`: the summary the scene drawer reads, the
(thinned) cloud and its member labels, the checks and the metrics.

The checks are recomputed from the plan's parts rather than read from its
counters where that is possible: coverage from the spans the main route
drives, feasibility from every transition, and each gap against the jump
reach and the members the main route leaves out.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Hashable, Sequence
from dataclasses import asdict
from typing import Any

import networkx as nx
import numpy as np

from planners.errors import InvalidInputError, UnknownVertexError
from planners.inspection.faces import driving_face
from planners.inspection.gaps import Gap
from planners.inspection.jumps import JumpSetParams
from planners.inspection.layout import LayoutParams
from planners.inspection.params import InspectionParams
from planners.inspection.plan import InspectionPlan, plan_inspection
from planners.inspection.program_plan import plan_route_program, world_origin
from planners.inspection.transitions import Transition
from planners.pointcloud._validate import as_points
from planners.pointcloud.spacing import decide_units, measure_spacing
from planners.result import Check, PlanResult, check_ge
from planners.structure.model import PROFILES, StructureModel
from planners.structure.params import StructureParams
from planners.structure.pipeline import model_structure
from planners.summary import json_safe, thin
from planners.vocpp import Route

__all__ = ["MAX_SCENE_POINTS", "crop", "plan_inspection_result", "validate_crop_box"]

#: Points stored for the scene at most (a 5 mm scan has millions; the browser
#: needs a fraction of them to show which member each point went to).
MAX_SCENE_POINTS = 250_000
#: Where the structure model ends and the route planning begins, as a share of
#: the job's progress (the model is most of the time on every scan measured).
_MODEL_SHARE = 0.85
#: Infeasible transitions named in the check's message at most (the summary lists all).
_LISTED = 5
#: Further transitions named in a few words each (:func:`_short`) at most.
_NAMED = 40
#: Coordinates in the summary are rounded to this many decimals of a metre
#: (10 µm: far below any scan's noise, and short numbers in survey frames).
_DECIMALS = 5

Box = tuple[tuple[float, float, float], tuple[float, float, float]]


def validate_crop_box(box: object) -> None:
    """Raise :class:`InvalidInputError` unless ``box`` is ``None`` or
    ``((xmin, ymin, zmin), (xmax, ymax, zmax))``, finite, min < max on every axis."""
    if box is None:
        return
    try:
        a = np.asarray(box, dtype=float)
    except (TypeError, ValueError):
        a = np.zeros(0)
    if a.shape != (2, 3) or not np.all(np.isfinite(a)) or not np.all(a[0] < a[1]):
        raise InvalidInputError(
            "crop_box_m must be None or ((xmin, ymin, zmin), (xmax, ymax, zmax)) finite "
            f"metres with min < max on every axis, got {box!r}"
        )


def crop(points: np.ndarray, box: Box | None) -> np.ndarray:
    """The points inside the axis-aligned ``box`` (inclusive), or all of them.

    Raises :class:`InvalidInputError` for a malformed box, and for one that
    keeps fewer than 10 points (what a structure model needs), saying what
    the cloud spans so the box can be corrected.
    """
    validate_crop_box(box)
    if box is None:
        return points
    lo, hi = np.asarray(box, dtype=float)
    kept = points[np.all((points >= lo) & (points <= hi), axis=1)]
    if len(kept) < 10:
        raise InvalidInputError(
            f"only {len(kept)} point(s) inside the crop box {lo.tolist()} – {hi.tolist()} m "
            f"(the cloud spans {points.min(axis=0).round(3).tolist()} – "
            f"{points.max(axis=0).round(3).tolist()} m); a structure model needs at least 10"
        )
    return kept


def plan_inspection_result(
    points: np.ndarray,
    *,
    crop_box_m: Box | None = None,
    structure: StructureParams | None = None,
    inspection: InspectionParams | None = None,
    start: int | None = None,
    end: int | None = None,
    units: str = "m",
    progress: Callable[[float, str], None] | None = None,
    robot: Any = None,
    layout: LayoutParams | None = None,
    jumps: JumpSetParams | None = None,
    joint_names: list[str] | None = None,
    mapper: Callable[..., Any] | None = None,
) -> PlanResult:
    """Model the structure in ``points`` (N, 3, any frame) and plan the ARA's
    inspection route over it from vertex ``start`` to ``end`` of the member
    graph (``None``: far-apart free ends); return the stored form.

    ``units`` is the unit of the numbers in ``points``: ``"m"``, ``"mm"``
    (scaled by 0.001 first) or ``"auto"``, decided from the point spacing
    and extent as an upload decides
    (:func:`planners.pointcloud.spacing.decide_units`); the summary's
    ``units`` says which and why.  ``crop_box_m`` is in metres of the
    cloud's frame, applied after the scaling.

    A cloud in which no member is found is not an error: the result holds
    the (empty) model and a failing ``members_found`` check.  Bad input
    raises :mod:`planners.errors` types: a malformed cloud, crop box or
    params (``InvalidInputError``), ``start``/``end`` not a vertex of the
    member graph (``UnknownVertexError``), two vertices in pieces no jump
    joins (``DisconnectedGraphError``).

    With ``robot`` (the ARA model, or a
    :class:`planners.switching.jump.JumpRobot`) the main route's program
    parts are planned too (:func:`planners.inspection.program_plan.plan_route_program`:
    stretches, every inch-worm jump planned with OMPL RRT-Connect, seed
    §3.2): the summary's ``program`` and ``world_origin_m``, the arrays
    ``jump_q``, ``jump_times``, ``jump_offsets``, the checks
    ``jumps_planned``, ``jump_clearance``, ``landings_on_steel``.
    """
    t0 = time.perf_counter()
    raw = as_points(points, "points", dims=3)
    unit, reason = _units(raw, units)
    scale_to_m = 0.001 if unit == "mm" else 1.0
    scaled = raw * scale_to_m if scale_to_m != 1.0 else raw
    pts = crop(scaled, crop_box_m)
    crop_s = time.perf_counter() - t0

    def model_progress(fraction: float, stage: str) -> None:
        if progress is not None:
            progress(_MODEL_SHARE * fraction, f"structure: {stage}")

    # mapper: how a cloud large enough to be modelled in tiles runs them
    # (planners.structure.tiles; the builtin map when None).
    model = model_structure(pts, params=structure, progress=model_progress, mapper=mapper)
    if progress is not None:
        progress(_MODEL_SHARE, "inspection route")
    plan = _plan(model, start, end, inspection)
    checks, extra = _checks(model, plan)
    parts = None
    if robot is not None and plan is not None:

        def jump_progress(fraction: float, stage: str) -> None:
            if progress is not None:
                progress(_MODEL_SHARE + (0.99 - _MODEL_SHARE) * fraction, stage)

        parts = plan_route_program(
            model,
            plan,
            pts,
            robot,
            layout=layout,
            jumps=jumps,
            joint_names=joint_names,
            progress=jump_progress,
        )
        checks += parts.checks
        extra.update(parts.metrics)
    metrics = {
        **_model_metrics(model, len(raw), len(pts)),
        **(_plan_metrics(plan) if plan is not None else {}),
        **extra,
        "crop_time_s": crop_s,
        **{f"structure_{k}_time_s": float(v) for k, v in model.timings_s.items()},
        **(
            {f"inspection_{k}_time_s": float(v) for k, v in plan.timings_s.items()}
            if plan is not None
            else {}
        ),
        "planning_time_s": time.perf_counter() - t0,
    }
    summary = _summary(model, plan, plan.params if plan is not None else inspection)
    summary["units"] = {"unit": unit, "scale_to_m": scale_to_m, "reason": reason}
    summary["preprocess"] = {
        "crop_box_m": crop_box_m,
        "counts": {"input": len(raw), "cropped": len(pts)},
    }
    summary["world_origin_m"] = [float(x) for x in world_origin(pts)]
    summary["program"] = parts.summary if parts is not None else None
    summary["timings_s"] = {
        "crop": crop_s,
        "structure": dict(model.timings_s),
        "inspection": dict(plan.timings_s) if plan is not None else {},
    }
    keep = thin(len(pts), MAX_SCENE_POINTS)
    arrays: dict[str, np.ndarray] = {
        "points": np.asarray(pts[keep], dtype=np.float64),
        "labels": np.asarray(model.labels[keep], dtype=np.int32),
    }
    if parts is not None:
        arrays.update(parts.arrays)
    if progress is not None:
        progress(1.0, "done")
    return PlanResult(summary=json_safe(summary), arrays=arrays, checks=checks, metrics=metrics)


def _units(points: np.ndarray, units: str) -> tuple[str, str]:
    """``("m" | "mm", why)`` for the numbers in ``points``."""
    if units in ("m", "mm"):
        return units, f"set by the request ({units})"
    if units != "auto":
        raise InvalidInputError(f"units must be 'auto', 'm' or 'mm', got {units!r}")
    extent = float(np.ptp(points, axis=0).max()) if len(points) else 0.0
    unit, why = decide_units(measure_spacing(points), extent, len(points))
    return unit, f"auto: {why}"


def _plan(
    model: StructureModel,
    start: int | None,
    end: int | None,
    params: InspectionParams | None,
) -> InspectionPlan | None:
    """The inspection plan, or ``None`` when the model has no span to drive
    (then a given ``start``/``end`` cannot be a vertex of it)."""
    if model.graph.number_of_edges() > 0:
        return plan_inspection(model, start=start, end=end, params=params)
    for name, v in (("start", start), ("end", end)):
        if v is not None:
            raise UnknownVertexError(
                f"{name} vertex {v!r} is not a vertex of the model graph: no member was found "
                "in the cloud, so there are no vertices"
            )
    return None


# ------------------------------------------------------------------ checks


def _checks(
    model: StructureModel, plan: InspectionPlan | None
) -> tuple[list[Check], dict[str, float]]:
    """The plan's checks and the metrics they measure."""
    n = len(model.members)
    found = check_ge("members_found", n, 1, "members found in the cloud")
    if plan is None:
        msg = (
            "no member found in the cloud (nothing linear at any scale, or only short free "
            "pieces): there is nothing to inspect; check the crop box, the units and "
            "linearity_min"
        )
        return [Check(found.name, found.passed, found.value, found.limit, msg)], {}
    off_main = _off_main(model, plan)
    checks = [found, _coverage(model, plan, off_main)]
    bad = plan.infeasible
    checks.append(_feasibility(plan.transitions, bad))
    unexplained = [g for g in plan.gaps if not _gap_explained(g, plan, off_main)]
    checks.append(_gap_check(plan, unexplained))
    return checks, {
        "infeasible_transitions": float(len(bad)),
        "unexplained_gaps": float(len(unexplained)),
    }


def _driven_members(g: nx.MultiGraph, route: Route) -> set[int]:
    """Members whose spans ``route`` drives (jump edges carry no member)."""
    return {int(g.edges[e]["member"]) for e in route.edges if g.edges[e].get("kind") == "span"}


def _off_main(model: StructureModel, plan: InspectionPlan) -> set[int]:
    """Members whose spans the main route does not drive (recounted from its
    edges, not read from ``plan.uncovered_members``)."""
    driven = _driven_members(plan.graph, plan.route)
    return {m.id for m in model.members if m.id not in driven}


def _coverage(model: StructureModel, plan: InspectionPlan, off_main: set[int]) -> Check:
    """Every member is driven by the main route; the others are named, with
    why: driven only by another route (the robot is carried there) or
    without a span in the member graph."""
    close = plan.params.close_member
    if close is not None:
        driven = close not in off_main
        return Check(
            "members_covered",
            driven,
            float(not driven),
            0.0,
            f"close inspection: the route drives member {close} "
            f"({plan.route.deadhead:.2f} m of steel to reach it)"
            if driven
            else f"close inspection: member {close} is not on the route",
        )
    others = set().union(*(_driven_members(plan.graph, r) for r in plan.routes[1:]))
    left = sorted(off_main)
    carried = [m for m in left if m in others]
    spanless = [m for m in left if m not in others]
    unreachable = sorted(set(plan.unreachable_members) - off_main)
    n = len(model.members)
    parts = []
    if left:
        if carried:
            parts.append(f"{_ids(carried)} only by another route (carry the robot there)")
        if spanless:
            parts.append(f"{_ids(spanless)} on no route (no span in the member graph)")
        parts = [f"{len(left)} of {n} members not on the main route: " + "; ".join(parts)]
    if unreachable:
        onto = "; ".join(_short(t) for t in plan.blocked[:_NAMED])
        more = f"; and {len(plan.blocked) - _NAMED} more" if len(plan.blocked) > _NAMED else ""
        parts.append(
            f"{len(unreachable)} of {n} members not inspected: the ARA cannot get onto "
            f"{_ids(unreachable)} from the route's first member by transitions it can make "
            f"(every way onto them fails: {onto}{more})"
        )
    bad = len(left) + len(unreachable)
    if not bad:
        msg = f"the main route drives all {n} members"
        if plan.unreachable_members == [] and plan.infeasible:
            msg += " and the ARA can get onto each by transitions it can make"
    else:
        msg = "; ".join(parts)
    return Check("members_covered", not bad, float(bad), 0.0, msg)


def _short(t: Transition) -> str:
    """A transition in a few words: where, which members, which check fails."""
    av = t.availability
    which = "S_pa" if not av["plane"] else "S_am" if not av["area"] else "S_hc"
    wrist = av.get("wrist_distance_m")
    extra = f" {wrist:.3f} m > {av['arm_length_m']:.2f} m" if which == "S_hc" and wrist else ""
    return f"vertex {t.vertex} member {t.from_member}→{t.to_member} ({which}{extra})"


def _feasibility(transitions: Sequence[Transition], bad: Sequence[Transition]) -> Check:
    """Every transition's availability checks (Eq. 3.1 for its mode) pass;
    the message names the first few that do not."""
    if not bad:
        msg = f"all {len(transitions)} transitions are feasible"
    else:
        named = "; ".join(
            f"route {t.route} vertex {t.vertex} member {t.from_member}→{t.to_member} "
            f"({t.mode}): {t.reason}"
            for t in bad[:_LISTED]
        )
        rest = bad[_LISTED : _LISTED + _NAMED]
        more = f"; also {'; '.join(_short(t) for t in rest)}" if rest else ""
        if len(bad) > _LISTED + _NAMED:
            more += f"; and {len(bad) - _LISTED - _NAMED} more (the summary lists all)"
        msg = f"{len(bad)} of {len(transitions)} transitions infeasible: {named}{more}"
    return Check("transitions_feasible", not bad, float(len(bad)), 0.0, msg)


def _gap_explained(gap: Gap, plan: InspectionPlan, off_main: set[int]) -> bool:
    """A joined gap must be within the jump reach and its jump driven by a
    route; a gap left open must be wider than the reach, and one of its two
    pieces wholly off the main route (so the coverage check names it)."""
    reach = plan.params.jump_reach_m
    if plan.params.close_member is not None:
        # one member's route: a gap needs no driving, only the rule on its width
        return gap.width_m <= reach if gap.joined else gap.width_m > reach
    if gap.joined:
        if not gap.width_m <= reach or gap.vertex_a is None or gap.vertex_b is None:
            return False
        ends = {gap.vertex_a, gap.vertex_b}
        return any(
            {u, v} == ends and plan.graph.edges[u, v, k].get("kind") == "jump"
            for r in plan.routes
            for u, v, k in r.edges
        )
    sides = (plan.components[gap.component_a], plan.components[gap.component_b])
    return gap.width_m > reach and any(set(side) <= off_main for side in sides)


def _gap_check(plan: InspectionPlan, unexplained: Sequence[Gap]) -> Check:
    n_open = sum(not g.joined for g in plan.gaps)
    if unexplained:
        msg = f"{len(unexplained)} of {len(plan.gaps)} gaps unexplained: " + "; ".join(
            f"{g.width_m:.3f} m between members {g.member_a} and {g.member_b} "
            f"({'joined' if g.joined else 'open'})"
            for g in unexplained[:_LISTED]
        )
    elif not plan.gaps:
        msg = "the model is one piece: no gap"
    else:
        msg = (
            f"{len(plan.gaps) - n_open} gaps joined by a jump the route takes, "
            f"{n_open} wider than the {plan.params.jump_reach_m:.2f} m reach with the far "
            "piece's members listed as not on the main route"
        )
    return Check("gaps_explained", not unexplained, float(len(unexplained)), 0.0, msg)


def _ids(ids: Sequence[int]) -> str:
    head = ", ".join(str(i) for i in ids[:10])
    return f"member{'s' if len(ids) > 1 else ''} {head}" + (" …" if len(ids) > 10 else "")


# ------------------------------------------------------------------ metrics


def _model_metrics(model: StructureModel, n_input: int, n_cropped: int) -> dict[str, float]:
    counts = model.profile_counts()
    return {
        "member_count": float(len(model.members)),
        **{f"member_count_{p}": float(counts.get(p, 0)) for p in PROFILES},
        "face_count": float(len(model.faces)),
        "joint_count": float(len(model.joints)),
        "points_input": float(n_input),
        "points_cropped": float(n_cropped),
        "points_on_members": float(np.count_nonzero(model.labels >= 0)),
        "spacing_m": float(model.spacing_m),
    }


def _plan_metrics(plan: InspectionPlan) -> dict[str, float]:
    r = plan.route
    out = {
        "route_length_m": float(r.length),
        "route_lower_bound_m": float(r.lower_bound),
        "deadhead_m": float(r.deadhead),
        "total_length_m": float(plan.length_m),
        "total_lower_bound_m": float(plan.lower_bound_m),
        "routes": float(len(plan.routes)),
        "jumps": float(plan.jumps),
        "transitions": float(len(plan.transitions)),
        "gap_count": float(len(plan.gaps)),
        "gaps_joined": float(sum(g.joined for g in plan.gaps)),
        "uncovered_members": float(len(plan.uncovered_members)),
        "unreachable_members": float(len(plan.unreachable_members)),
    }
    if r.lower_bound > 0:  # a route of one zero-length span has no ratio
        out["route_length_ratio"] = float(r.length / r.lower_bound)
    return out


# ------------------------------------------------------------------ summary


def _xyz(p: np.ndarray) -> list[float]:
    return [round(float(x), _DECIMALS) for x in np.asarray(p, float).reshape(-1)]


def _vertex(v: Hashable) -> int | str:
    """A routing-graph vertex for JSON: model vertices and split vertices are
    ints (the model graph numbers its vertices), anything else its repr."""
    return int(v) if isinstance(v, int | np.integer) else repr(v)


def _order(v: Hashable) -> tuple[int, int, str]:
    """Sort key: int vertices in numeric order, then any others by repr."""
    return (0, int(v), "") if isinstance(v, int | np.integer) else (1, 0, repr(v))


def _route(g: nx.MultiGraph, r: Route) -> dict[str, Any]:
    return {
        "vertices": [_vertex(v) for v in r.vertices],
        "edges": [[_vertex(u), _vertex(v), _vertex(k)] for u, v, k in r.edges],
        "kinds": [str(g.edges[e].get("kind", "span")) for e in r.edges],
        "length_m": r.length,
        "lower_bound_m": r.lower_bound,
        "deadhead_m": r.deadhead,
        "method": r.method,
        "optimality_gap": r.optimality_gap,
    }


def _transition(t: Transition) -> dict[str, Any]:
    return {
        "route": t.route,
        "index": t.index_in_route,
        "vertex": _vertex(t.vertex),
        "landing_vertex": _vertex(t.landing_vertex),
        "kind": t.kind,
        "from_member": t.from_member,
        "to_member": t.to_member,
        "from_face": t.from_face,
        "to_face": t.to_face,
        "mode": t.mode,
        "angle_deg": t.angle_deg,
        "availability": dict(t.availability),
        "feasible": t.feasible,
        "reason": t.reason,
    }


def _gap(g: Gap, plan: InspectionPlan, off_main: set[int]) -> dict[str, Any]:
    sides = (plan.components[g.component_a], plan.components[g.component_b])
    return {
        "components": [g.component_a, g.component_b],
        "members": [g.member_a, g.member_b],
        "points": [_xyz(g.point_a), _xyz(g.point_b)],
        "width_m": g.width_m,
        "joined": g.joined,
        "vertices": [None if v is None else _vertex(v) for v in (g.vertex_a, g.vertex_b)],
        "explained": _gap_explained(g, plan, off_main),
        # the piece the main route leaves out, when the gap is open
        "unreached_members": next(
            (list(s) for s in sides if not g.joined and set(s) <= off_main), []
        ),
    }


def _summary(
    model: StructureModel, plan: InspectionPlan | None, inspection: InspectionParams | None
) -> dict[str, Any]:
    """Model, graph, routes, transitions and gaps as the scene drawer reads them."""
    members = []
    for m in model.members:
        drive = driving_face(m, inspection.foot_width_m if inspection is not None else None)
        members.append(
            {
                "id": m.id,
                "axis": [_xyz(m.axis[0]), _xyz(m.axis[1])],
                "profile": m.profile,
                "depth_m": m.depth_m,
                "width_m": m.width_m,
                "length_m": m.length_m,
                "n_points": m.n_points,
                "fragments": m.fragments,
                "driving_face": None if drive is None else drive.id,
                "faces": [
                    {
                        "id": f.id,
                        "kind": f.kind,
                        "outline": [_xyz(p) for p in f.outline()],
                        "normal": [round(float(x), 6) for x in f.normal],
                        "area_m2": f.area_m2,
                        "n_points": f.n_points,
                    }
                    for f in m.faces
                ],
            }
        )
    g = plan.graph if plan is not None else nx.MultiGraph(model.graph)
    out: dict[str, Any] = {
        "spacing_m": model.spacing_m,
        "structure_params": dict(model.params),
        "inspection_params": asdict(inspection or InspectionParams()),
        "members": members,
        "joints": [
            {"id": j.id, "pos": _xyz(j.pos), "members": [int(x) for x in j.members]}
            for j in model.joints
        ],
        # Decks, slabs, walls and ground set apart from the members (drawn in the scene).
        "surfaces": [
            {
                "id": int(sf.id),
                "kind": sf.kind,
                "normal": [round(float(x), 6) for x in sf.normal],
                "offset_m": round(float(sf.offset), _DECIMALS),
                "outline": [_xyz(q) for q in sf.outline],
                "area_m2": float(sf.area_m2),
                "n_points": int(sf.n_points),
            }
            for sf in model.surfaces
        ],
        "graph": {
            # "split" vertices (gap ends on a span) are routing-only: not a
            # start or end a plan can be asked for
            "nodes": [
                {
                    "id": _vertex(v),
                    "pos": _xyz(d["pos"]),
                    "kind": str(d.get("kind", "")),
                    "degree": int(g.degree(v)),
                }
                for v, d in sorted(g.nodes(data=True), key=lambda x: _order(x[0]))
            ],
            "edges": [
                {
                    "u": _vertex(u),
                    "v": _vertex(v),
                    "key": int(k),
                    "kind": str(d.get("kind", "span")),
                    "member": d.get("member"),
                    "length_m": float(d["weight"]),
                }
                for u, v, k, d in g.edges(keys=True, data=True)
            ],
        },
        "start": None,
        "end": None,
        "route": None,
        "routes": [],
        "transitions": [],
        "gaps": [],
        "components": [],
        "covered_members": [],
        "uncovered_members": [m.id for m in model.members],
        "unreachable_members": [],
        "blocked_transitions": [],
        "jumps": 0,
        "length_m": 0.0,
        "lower_bound_m": 0.0,
    }
    if plan is None:
        return out
    out.update(
        start=_vertex(plan.route.vertices[0]),
        end=_vertex(plan.route.vertices[-1]),
        route=_route(plan.graph, plan.route),
        routes=[_route(plan.graph, r) for r in plan.routes],
        transitions=[_transition(t) for t in plan.transitions],
        gaps=[_gap(x, plan, _off_main(model, plan)) for x in plan.gaps],
        components=[list(c) for c in plan.components],
        covered_members=list(plan.covered_members),
        uncovered_members=list(plan.uncovered_members),
        unreachable_members=list(plan.unreachable_members),
        blocked_transitions=[_transition(t) for t in plan.blocked],
        jumps=plan.jumps,
        length_m=plan.length_m,
        lower_bound_m=plan.lower_bound_m,
    )
    return out
