"""Starting a finding from the scene ("click on the cloud or a
member/face to start a finding at that point, as a proposal the console
confirms").

The gesture is **Ctrl-click** (Cmd-click on a Mac; viser folds the two into
its ``"cmd/ctrl"`` modifier) while an ``ara.inspect`` plan is shown: plain
clicks stay the drawers' start/end pickers and shift-clicks the measuring
tool.  The click arrives as a ray (world frame); :meth:`FindingPicker.pick`
turns it into a place on the structure model:

1. the nearest face outline of any member the ray passes through (the ray
   meets the face's plane inside its polygon, within :data:`EDGE_M` of it);
2. otherwise the cloud point under the cursor (the measuring tool's
   :func:`~server.scene.measure.pick_on_ray`) when it belongs to a member
   and lies within :data:`NEAR_FACE_M` of one of that member's faces (and
   over it), snapped onto that face's plane.

A pick becomes a *finding proposal* in the scene's
:class:`~server.scene.proposals.ProposalBook` (``action="finding"``, patch
``{"member_id", "face_id", "point_m"}``); an operator accepts it over REST
with the finding's type, condition state and notes, which creates the
finding through the same code as ``POST /api/v1/findings``.  A click off
every face proposes nothing.

:func:`point_view` is the camera that frames a finding's location
(``POST /api/v1/scene/frame``).
"""

from __future__ import annotations

import logging
import threading
from dataclasses import dataclass
from typing import Any

import numpy as np

from server.scene.framing import _VIEW_DIR, View
from server.scene.measure import pick_on_ray

log = logging.getLogger(__name__)

#: The modifier of the gesture (viser: Cmd on a Mac, Ctrl elsewhere).
MODIFIER = "cmd/ctrl"
#: How far outside a face's outline a ray may meet its plane and still pick it (m).
EDGE_M = 0.02
#: How far a clicked cloud point may lie from its member's face plane (m).
NEAR_FACE_M = 0.08
#: Half-size of the region framed around a finding (m).
FRAME_RADIUS_M = 0.8


@dataclass(frozen=True)
class _Face:
    member_id: int
    face_id: int
    centre: np.ndarray
    normal: np.ndarray  # unit
    u: np.ndarray  # unit, in the plane
    v: np.ndarray  # unit, in the plane
    ring: np.ndarray  # (k, 2) outline in (u, v)

    def plane_uv(self, p: np.ndarray) -> tuple[float, np.ndarray]:
        """Signed distance of ``p`` from the plane and its (u, v) there."""
        r = p - self.centre
        return float(r @ self.normal), np.array([r @ self.u, r @ self.v])

    def covers(self, uv: np.ndarray, margin: float) -> bool:
        return _inside(uv, self.ring) or _edge_distance(uv, self.ring) <= margin


def _inside(p: np.ndarray, ring: np.ndarray) -> bool:
    """Even-odd rule: ``p`` (2,) inside the polygon ``ring`` (k, 2)."""
    x, y = float(p[0]), float(p[1])
    inside = False
    k = len(ring)
    for i in range(k):
        (x1, y1), (x2, y2) = ring[i], ring[(i + 1) % k]
        if (y1 > y) != (y2 > y) and x < x1 + (y - y1) * (x2 - x1) / (y2 - y1):
            inside = not inside
    return inside


def _edge_distance(p: np.ndarray, ring: np.ndarray) -> float:
    a, b = ring, np.roll(ring, -1, axis=0)
    ab = b - a
    den = np.maximum(np.einsum("ij,ij->i", ab, ab), 1e-18)
    t = np.clip(np.einsum("ij,ij->i", p - a, ab) / den, 0.0, 1.0)
    return float(np.min(np.linalg.norm(a + t[:, None] * ab - p, axis=1)))


def faces_of(result: dict[str, Any]) -> list[_Face]:
    """Every usable face of an ``ara.inspect`` result's members."""
    out = []
    for m in result.get("members") or []:
        for f in m.get("faces") or []:
            ring3 = np.asarray(f.get("outline") or [], dtype=float).reshape(-1, 3)
            n = np.asarray(f.get("normal") or [0, 0, 0], dtype=float)
            if len(ring3) < 3 or not np.isfinite(ring3).all() or np.linalg.norm(n) < 1e-9:
                continue
            n = n / np.linalg.norm(n)
            c = ring3.mean(axis=0)
            a = np.cross(n, [1.0, 0.0, 0.0] if abs(n[0]) < 0.9 else [0.0, 1.0, 0.0])
            u = a / np.linalg.norm(a)
            v = np.cross(n, u)
            ring = np.column_stack([(ring3 - c) @ u, (ring3 - c) @ v])
            out.append(_Face(int(m["id"]), int(f["id"]), c, n, u, v, ring))
    return out


class FindingPicker:
    """The faces and member-labelled cloud of the ``ara.inspect`` plan shown;
    thread-safe (set on FastAPI's threads, picked on viser's)."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self.plan_id: str | None = None
        self._faces: list[_Face] = []
        self._points = np.zeros((0, 3))
        self._labels = np.zeros(0, dtype=int)

    def set_plan(self, plan: Any | None) -> None:
        """What is shown now: an ``ara.inspect`` plan record, or anything else (nothing to pick)."""
        faces: list[_Face] = []
        pts, labels = np.zeros((0, 3)), np.zeros(0, dtype=int)
        if plan is not None and plan.kind == "ara.inspect" and plan.result:
            faces = faces_of(plan.result)
            try:
                P = np.asarray(plan.array("points"), dtype=float).reshape(-1, 3)
                L = np.asarray(plan.array("labels"), dtype=int).reshape(-1)
                if len(P) == len(L):
                    keep = (L >= 0) & np.isfinite(P).all(axis=1)
                    pts, labels = P[keep], L[keep]
                    if len(pts) > 200_000:
                        step = int(np.ceil(len(pts) / 200_000))
                        pts, labels = pts[::step], labels[::step]
            except Exception:  # no stored cloud: faces only
                log.debug("plan %s has no labelled cloud to pick on", plan.id)
        with self._lock:
            self.plan_id = plan.id if faces and plan is not None else None
            self._faces = faces
            self._points, self._labels = pts, labels

    @property
    def active(self) -> bool:
        return self.plan_id is not None

    def pick(self, origin: Any, direction: Any) -> dict[str, Any] | None:
        """The place a click along the ray names (``member_id``, ``face_id``,
        ``point_m`` on the face's plane, ``via``), or ``None``."""
        o = np.asarray(origin, dtype=float).reshape(3)
        d = np.asarray(direction, dtype=float).reshape(3)
        if not (np.isfinite(o).all() and np.isfinite(d).all()) or np.linalg.norm(d) == 0:
            return None
        d = d / np.linalg.norm(d)
        with self._lock:
            faces, P, L, plan_id = self._faces, self._points, self._labels, self.plan_id
        if plan_id is None:
            return None
        best: tuple[float, _Face, np.ndarray] | None = None
        for f in faces:
            den = float(d @ f.normal)
            if abs(den) < 1e-9:
                continue
            t = float((f.centre - o) @ f.normal) / den
            if t <= 0 or (best is not None and t >= best[0]):
                continue
            p = o + t * d
            if f.covers(f.plane_uv(p)[1], EDGE_M):
                best = (t, f, p)
        if best is not None:
            return _place(plan_id, best[1], best[2], "face")
        if len(P) == 0:
            return None
        k = pick_on_ray(P, o, d)
        if k is None:
            return None
        q, member = P[k], int(L[k])
        near: tuple[float, _Face] | None = None
        for f in faces:
            if f.member_id != member:
                continue
            off, uv = f.plane_uv(q)
            fits = abs(off) <= NEAR_FACE_M and f.covers(uv, NEAR_FACE_M)
            if fits and (near is None or abs(off) < near[0]):
                near = (abs(off), f)
        if near is None:
            return None
        f = near[1]
        return _place(plan_id, f, q - f.plane_uv(q)[0] * f.normal, "cloud")


def _place(plan_id: str, f: _Face, p: np.ndarray, via: str) -> dict[str, Any]:
    return {
        "plan_id": plan_id,
        "member_id": f.member_id,
        "face_id": f.face_id,
        "point_m": [round(float(x), 4) for x in p],
        "via": via,
    }


def point_view(
    point: Any, fov_rad: float, normal: Any | None = None, radius: float = FRAME_RADIUS_M
) -> View:
    """A camera looking at ``point`` with ``radius`` metres around it in
    view: from the scene's usual direction, or — given the face's normal —
    from in front of that face (on the side nearer the usual view), raised a
    little so the member around it shows."""
    p = np.asarray(point, dtype=float).reshape(3)
    direction = _VIEW_DIR
    if normal is not None:
        n = np.asarray(normal, dtype=float).reshape(3)
        if np.isfinite(n).all() and np.linalg.norm(n) > 1e-9:
            n = n / np.linalg.norm(n)
            if n @ _VIEW_DIR < 0:
                n = -n
            tilted = n + 0.35 * _VIEW_DIR
            direction = tilted / np.linalg.norm(tilted)
    distance = 1.15 * radius / np.sin(max(fov_rad, 0.1) / 2.0)
    return View(p + direction * distance, p, radius)
