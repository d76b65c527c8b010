"""From a finding to a maintenance plan, and the plan's outcome back on the finding.

:func:`blast_params` turns a corrosion / coating-loss finding on a face of an
``ara.inspect`` structure model into ``blast`` params: the surface is the
finding's region (or a square patch around its point) on the face's plane,
clipped to the face's outline; the plan's scan is the obstacle cloud (its
points off that plane); the base is searched near the surface
(:mod:`planners.blasting.base_placement`) — or the plan fails saying no base
within the limits reaches it.  :func:`inspect_params` turns a finding into a
close-inspection ``ara.inspect`` plan over the same scan that drives to the
finding's member from the given start.

:class:`OutcomeRecorder` listens to the event bus; when an execution of such
a plan ends it writes the outcome onto the link (spots blasted, coverage of
a completed blast run as the planner measured it for those spots) and, for a
completed run, asks the operator for the finding's new condition state.
"""

from __future__ import annotations

import logging
import threading
from concurrent.futures import ThreadPoolExecutor
from typing import Any

import numpy as np
import shapely
from shapely.geometry import Polygon, box

from server.events import EventBus
from server.store import NotFoundError, Store
from server.store.findings import Finding
from server.store.maintenance import MaintenanceStore

log = logging.getLogger(__name__)

#: finding types a blast plan treats (sand-blasting removes rust and coating)
BLASTABLE = ("corrosion", "coating_loss")
#: an execution in one of these has ended (for now: a resume makes a new outcome)
ENDED = ("completed", "aborted", "faulted", "interrupted")


class MaintenanceError(ValueError):
    """The finding cannot become the requested plan; the message says why (HTTP 422)."""

    def __init__(self, field: str, message: str) -> None:
        super().__init__(message)
        self.field = field


def _face(source: dict[str, Any], f: Finding) -> dict[str, Any]:
    if f.member_id is None or f.face_id is None:
        raise MaintenanceError(
            "face_id", "a blast plan needs the finding's face: set member_id and face_id"
        )
    member = next((m for m in source.get("members", []) if m["id"] == f.member_id), None)
    face = next((g for g in (member or {}).get("faces", []) if g["id"] == f.face_id), None)
    if face is None:
        raise MaintenanceError(
            "face_id", f"plan {f.plan_id} has no face {f.face_id} on member {f.member_id}"
        )
    return dict(face)


def _frame(face: dict[str, Any]) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Origin, unit normal, x and y axes of the face's plane (x along its first edge)."""
    outline = np.asarray(face["outline"], dtype=float)
    n = np.asarray(face["normal"], dtype=float)
    n /= np.linalg.norm(n)
    origin = outline.mean(axis=0)
    e = outline[1] - outline[0]
    x = e - (e @ n) * n
    if np.linalg.norm(x) < 1e-9:  # a degenerate first edge: any in-plane axis
        x = np.cross(n, [1.0, 0.0, 0.0] if abs(n[0]) < 0.9 else [0.0, 1.0, 0.0])
    x /= np.linalg.norm(x)
    return origin, n, x, np.cross(n, x)


def blast_surface(face: dict[str, Any], f: Finding, patch_m: float) -> dict[str, Any]:
    """The ``polygon`` param: the finding's region on the face's plane ∩ the face."""
    origin, n, x, y = _frame(face)

    def uv(p: Any) -> np.ndarray:
        d = np.asarray(p, dtype=float).reshape(-1, 3) - origin
        return np.column_stack([d @ x, d @ y])

    face_poly = shapely.make_valid(Polygon(uv(face["outline"])))
    if f.region_m is not None:
        region = shapely.make_valid(Polygon(uv(f.region_m)))
    elif f.point_m is not None:
        c = uv(f.point_m)[0]
        region = box(*(c - patch_m / 2), *(c + patch_m / 2))
    else:  # _locate() refuses a finding without either
        raise MaintenanceError("region_m", "the finding has neither a point nor a region")
    area = face_poly.intersection(region)
    if not isinstance(area, Polygon):  # keep the largest piece of a split region
        parts = [g for g in getattr(area, "geoms", []) if isinstance(g, Polygon)]
        area = max(parts, key=lambda g: g.area) if parts else Polygon()
    if area.is_empty or area.area < 1e-4:
        raise MaintenanceError(
            "region_m",
            f"the finding's region covers {area.area * 1e4:.1f} cm² of face {face['id']}: "
            "nothing to blast (is it on this face?)",
        )
    ring = np.asarray(shapely.geometry.polygon.orient(area).exterior.coords)[:-1]
    return {
        "origin_m": origin.tolist(),
        "normal": n.tolist(),
        "x_axis": x.tolist(),
        "boundary_m": ring.round(6).tolist(),
        "holes_m": [],
    }


def scan_cloud_id(store: Store, source: Any, actor: str) -> str:
    """The stored cloud the source plan's model came from; a sample scan is
    generated again (deterministic from its name and seed) and stored."""
    params = source.params
    res = source.result or {}
    if (res.get("units") or {}).get("unit") == "mm":
        raise MaintenanceError(
            "plan_id",
            f"plan {source.id} scaled its cloud from millimetres: upload the scan in metres "
            "and inspect it again to plan maintenance on it",
        )
    if params.get("cloud_id"):
        try:
            store.get_cloud(params["cloud_id"])
        except NotFoundError:
            raise MaintenanceError(
                "plan_id", f"plan {source.id}'s cloud {params['cloud_id']} is no longer stored"
            ) from None
        return str(params["cloud_id"])
    from planners.structure.synthetic import SCAN_SAMPLES

    name = str(params.get("sample"))
    if "sample_seed" not in params:
        # a stored plan's params are the full validated model, seed included;
        # guessing one would rebuild another structure than the one inspected
        raise MaintenanceError("plan_id", f"plan {source.id}'s params name no sample_seed")
    seed = int(params["sample_seed"])
    if name not in SCAN_SAMPLES:
        raise MaintenanceError("plan_id", f"plan {source.id}'s sample {name!r} is unknown here")
    pts = np.asarray(SCAN_SAMPLES[name](seed), dtype=float)
    rec = store.add_cloud(
        f"sample {name} seed {seed} (scan of {source.id})", "sample", pts, 0, actor
    )
    return rec.id


def blast_params(
    store: Store, f: Finding, actor: str, *, patch_m: float, overrides: dict[str, Any]
) -> dict[str, Any]:
    """``blast`` params for finding ``f`` (see the module docstring)."""
    if f.type not in BLASTABLE:
        raise MaintenanceError(
            "kind", f"a {f.type} finding is not blasted; blast plans treat {', '.join(BLASTABLE)}"
        )
    source = _inspect_plan(store, f)
    face = _face(source.result or {}, f)
    params: dict[str, Any] = {
        "polygon": blast_surface(face, f, patch_m),
        "obstacles": [],
        "obstacle_cloud_id": scan_cloud_id(store, source, actor),
        "base_search": {},
    }
    params.update(overrides)
    return params


def inspect_params(
    store: Store, f: Finding, actor: str, *, start: int | None, overrides: dict[str, Any]
) -> dict[str, Any]:
    """``ara.inspect`` params: the source plan's scan and model settings, the
    route driving from ``start`` to the finding's member (close inspection)."""
    source = _inspect_plan(store, f)
    if f.member_id is None:
        raise MaintenanceError("member_id", "a close inspection needs the finding's member")
    keep = {k: v for k, v in source.params.items() if k not in ("start", "end", "close_member")}
    keep.update({"start": start, "end": None, "close_member": f.member_id})
    keep.update(overrides)
    return keep


def _inspect_plan(store: Store, f: Finding) -> Any:
    source = store.get_plan(f.plan_id)
    if source.kind != "ara.inspect":
        raise MaintenanceError(
            "plan_id",
            f"maintenance plans are made from findings on an ara.inspect structure model; "
            f"plan {source.id} is {source.kind}",
        )
    if not source.result:
        raise MaintenanceError(
            "plan_id", f"plan {source.id} has no structure model ({source.state})"
        )
    return source


def maintenance_view(store: Store, finding_id: str) -> tuple[list[dict[str, Any]], bool]:
    """The finding's maintenance plans as REST and reports show them — each
    with the plan's current state (``None`` once deleted; the link stays as
    history) and its run's outcome — and whether a new condition state is
    awaited."""
    links = MaintenanceStore(store.db).of_finding(finding_id)
    plans = []
    for link in links:
        try:
            state: str | None = store.get_plan(link.plan_id, result=False, program=False).state
        except NotFoundError:
            state = None
        plans.append(
            {
                "plan_id": link.plan_id,
                "kind": link.kind,
                "state": state,
                "created_by": link.created_by,
                "created_at": link.created_at,
                "execution_id": link.execution_id,
                "outcome": link.outcome,
                "coverage_pct": link.coverage_pct,
                "spots_done": link.spots_done,
                "spots_planned": link.spots_planned,
                "review_requested_at": link.review_requested_at,
                "reviewed_at": link.reviewed_at,
            }
        )
    return plans, any(link.awaiting_review for link in links)


# ------------------------------------------------------------------ outcomes
def spots_acknowledged(
    program: list[dict[str, Any]], acked: list[int], spot: np.ndarray
) -> tuple[int, int]:
    """(spots whose way-point the robot acknowledged, spots planned) of a blast
    program: its ``joints`` commands are the way-points in order."""
    done: set[int] = set()
    acked_set = set(acked)
    k = 0
    for i, c in enumerate(program):
        if c.get("op") != "joints":
            continue
        if k < len(spot) and spot[k] >= 0 and i in acked_set:
            done.add(int(spot[k]))
        k += 1
    planned = {int(s) for s in spot if s >= 0}
    return len(done & planned), len(planned)


class OutcomeRecorder:
    """Writes each ended execution of a finding's maintenance plan onto its link.

    Bus listeners run on the publisher's thread (the dispatch engine's), so
    the work goes to one worker thread; :meth:`catch_up` records runs that
    ended while the service was down."""

    def __init__(self, store: Store, bus: EventBus) -> None:
        self.store = store
        self.bus = bus
        self.links = MaintenanceStore(store.db)
        self._pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="maintenance")
        self._lock = threading.Lock()

    def on_event(self, type_: str, data: dict[str, Any]) -> None:
        if type_ == "execution" and data.get("state") in ENDED and data.get("id"):
            self._pool.submit(self._safe_record, str(data["id"]))

    def catch_up(self) -> None:
        for _plan, eid in self.links.unrecorded():
            self._pool.submit(self._safe_record, eid)

    def stop(self) -> None:
        self._pool.shutdown(wait=True)

    def _safe_record(self, execution_id: str) -> None:
        try:
            self.record(execution_id)
        except Exception:  # a bad row must not stop later outcomes
            log.exception("recording the outcome of execution %s", execution_id)

    def record(self, execution_id: str) -> None:
        with self._lock:
            ex = self.store.get_execution(execution_id)
            link = self.links.of_plan(ex.plan_id)
            if link is None or ex.state not in ENDED:
                return
            if link.execution_id == ex.id and link.outcome == ex.state:
                return
            fields: dict[str, Any] = {"execution_id": ex.id, "outcome": ex.state}
            why = f"{link.kind} plan {ex.plan_id}: execution {ex.id} {ex.state}"
            if link.kind == "blast":
                plan = self.store.get_plan(ex.plan_id)
                done, planned = spots_acknowledged(
                    list(plan.program or []),
                    self.store.list_acks(ex.id),
                    plan.array("waypoint_spot"),
                )
                fields.update(spots_done=done, spots_planned=planned)
                why += f", {done} of {planned} spots blasted"
                if ex.state == "completed" and done == planned:
                    cov = float((plan.metrics or {}).get("coverage_pct", float("nan")))
                    if np.isfinite(cov):
                        fields["coverage_pct"] = round(cov, 3)
                        why += f", coverage {cov:.2f} %"
            if ex.state == "completed":
                fields["review_requested_at"] = ex.updated_at
                fields["reviewed_at"] = None
                why += "; new condition state requested"
            self.links.record_outcome(ex.plan_id, fields, link.finding_id, why)
        self.bus.publish(
            "finding",
            {
                "id": link.finding_id,
                "action": "review_requested" if ex.state == "completed" else "maintenance",
                "plan_id": ex.plan_id,
                "execution_id": ex.id,
                "outcome": ex.state,
                **{
                    k: fields[k]
                    for k in ("coverage_pct", "spots_done", "spots_planned")
                    if k in fields
                },
            },
        )
