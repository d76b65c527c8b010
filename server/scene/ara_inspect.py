"""Scene drawer of ``ara.inspect``: the scan coloured by member (unlabelled
points grey), member axes labelled with their profile, face outlines, the
member-graph vertices (click: start, then end → a proposed plan), the
outlines of the large planes set apart from the members (deck soffits,
slabs, walls, ground; when the summary carries ``surfaces``), the routes
as numbered arrows, the transitions by mode (mobile / inch-worm, infeasible
ones red and larger) and the gaps between pieces of the structure.

Scans come in survey frames (x, y ≈ 10⁵–10⁶ m), where float32 — what the
browser draws with — resolves only decimetres: everything is drawn under a
frame placed at the cloud's centre, in float32 offsets from it (as the
scene's own cloud view does).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from server.planview import PlanView
from server.scene.common import (
    FAIL_RGB,
    ROUTE_RGB,
    add_spheres,
    add_start_end_picker,
    label_colors,
)
from server.scene.context import DrawContext

#: What this module draws (read by server.scene.drawers): kind → (function, robot shown live).
DRAWS = {"ara.inspect": ("draw", "ara")}

#: Transition colours by mode.
MOBILE_RGB = (40, 140, 255)
INCHWORM_RGB = (200, 60, 230)
#: Routes after the main one (the robot is carried to each).
OTHER_ROUTE_RGB = (250, 200, 60)
#: Large planes that are not members (deck soffits, slabs, walls, ground): muted.
SURFACE_RGB = (120, 125, 135)
#: Gap-jump edges of a route.
JUMP_RGB = (200, 60, 230)
GAP_RGB = FAIL_RGB


def _rgb(member: int) -> tuple[int, int, int]:
    c = label_colors(np.array([member]))[0]
    return int(c[0]), int(c[1]), int(c[2])


def _segments(name: str, ctx: DrawContext, segs: np.ndarray, colors: Any, width: float) -> None:
    """(M, 2, 3) segments (already local) as one line-segments node, if any."""
    if len(segs):
        ctx.scene.add_line_segments(
            name,
            points=np.asarray(segs, dtype=np.float32),
            colors=colors,
            thickness=width,
            thickness_units="screen",
        )


def draw(ctx: DrawContext, plan: PlanView) -> None:
    res = plan.result
    pts = np.asarray(plan.array("points"), dtype=np.float64).reshape(-1, 3)
    labels = np.asarray(plan.array("labels"), dtype=int).reshape(-1)
    centre = np.round(pts.mean(axis=0), 3) if len(pts) else np.zeros(3)
    root = f"{ctx.root}/local"
    ctx.scene.add_frame(root, show_axes=False, position=tuple(float(x) for x in centre))

    def local(xyz: Any) -> np.ndarray:
        return (np.asarray(xyz, dtype=np.float64) - centre).astype(np.float32)

    size = float(np.clip(res.get("spacing_m") or 0.01, 0.004, 0.05))
    colors = label_colors(labels)
    for k in np.unique(labels):  # one node per member, so each can be hidden
        sel = labels == k
        ctx.scene.add_point_cloud(
            f"{root}/cloud/{'unlabelled' if k < 0 else int(k)}",
            points=local(pts[sel]),
            colors=colors[sel],
            point_size=size,
            precision="float32",
        )

    _draw_surfaces(ctx, root, res, local)
    _draw_members(ctx, root, res, local)
    _draw_vertices(ctx, root, res, local)
    _draw_routes(ctx, root, res, local)
    _draw_transitions(ctx, root, res, local)
    _draw_gaps(ctx, root, res, local)


def _draw_members(ctx: DrawContext, root: str, res: dict[str, Any], local: Any) -> None:
    """Axes (member colour) with an id/profile label, and every face outline."""
    members = res["members"]
    if not members:
        return
    axes = np.stack([local(m["axis"]) for m in members])
    cols = np.stack([np.tile(np.array(_rgb(m["id"]), np.uint8), (2, 1)) for m in members])
    _segments(f"{root}/members", ctx, axes, cols, 4.0)
    for m, ax in zip(members, axes, strict=True):
        ctx.scene.add_label(
            f"{root}/member_labels/{m['id']}",
            text=f"{m['id']} {m['profile']}",
            position=tuple(float(x) for x in ax.mean(axis=0)),
        )
    segs, fcols = [], []
    for m in members:
        for f in m["faces"]:
            ring = local(f["outline"])
            if len(ring) < 2:
                continue
            closed = np.vstack([ring, ring[:1]])
            segs.append(np.stack([closed[:-1], closed[1:]], axis=1))
            # the driving face stands out: the route runs on it
            rgb = (255, 255, 255) if f["id"] == m["driving_face"] else _rgb(m["id"])
            fcols.append(np.tile(np.array(rgb, np.uint8), (len(ring), 2, 1)))
    if segs:
        _segments(f"{root}/faces", ctx, np.concatenate(segs), np.concatenate(fcols), 1.5)


def _draw_surfaces(ctx: DrawContext, root: str, res: dict[str, Any], local: Any) -> None:
    """The outline of every large plane the model set apart (deck soffits,
    slabs, walls, ground) as thin muted segments, labelled with its kind;
    nothing when the summary carries none."""
    surfaces = res.get("surfaces") or []
    segs = []
    for i, f in enumerate(surfaces):
        ring = local(f["outline"])
        if len(ring) < 2:
            continue
        closed = np.vstack([ring, ring[:1]])
        segs.append(np.stack([closed[:-1], closed[1:]], axis=1))
        ctx.scene.add_label(
            f"{root}/surface_labels/{i}",
            text=str(f.get("kind", "surface")),
            position=tuple(float(x) for x in ring.mean(axis=0)),
        )
    if segs:
        _segments(f"{root}/surfaces", ctx, np.concatenate(segs), SURFACE_RGB, 1.0)


def _draw_vertices(ctx: DrawContext, root: str, res: dict[str, Any], local: Any) -> None:
    """Joints and free ends as clickable spheres: the first click picks the
    start, the second the end, then a plan with both is proposed."""
    nodes = [n for n in res["graph"]["nodes"] if n["kind"] != "split"]
    if not nodes:
        return
    ids = [n["id"] for n in nodes]
    pos = local([n["pos"] for n in nodes])
    add_start_end_picker(
        ctx, root, ids, pos, chosen=res, radius=0.04, label_positions=np.asarray(pos) + 0.06
    )


def _draw_routes(ctx: DrawContext, root: str, res: dict[str, Any], local: Any) -> None:
    """Each route as arrows in driving order, numbered; jumps across gaps in
    the inch-worm colour; routes after the main one in their own colour."""
    where = {n["id"]: n["pos"] for n in res["graph"]["nodes"]}
    for i, route in enumerate(res["routes"]):
        edges = route["edges"]
        if not edges:
            continue
        a = local([where[u] for u, _, _ in edges])
        b = local([where[v] for _, v, _ in edges])
        base = ROUTE_RGB if i == 0 else OTHER_ROUTE_RGB
        cols = np.array([JUMP_RGB if k == "jump" else base for k in route["kinds"]], dtype=np.uint8)
        ctx.scene.add_arrows(
            f"{root}/routes/{i}",
            points=np.stack([a, b], axis=1),
            colors=cols,
            shaft_radius=0.01,
            head_radius=0.03,
            head_length=0.08,
        )
        for k, (p, q) in enumerate(zip(a, b, strict=True)):
            ctx.scene.add_label(
                f"{root}/route_order/{i}/{k}",
                text=f"{k + 1}" if i == 0 else f"{i}.{k + 1}",
                position=tuple(float(x) for x in (p + q) / 2),
            )


def _draw_transitions(ctx: DrawContext, root: str, res: dict[str, Any], local: Any) -> None:
    """A sphere per transition: mobile and inch-worm in their colours, an
    infeasible one larger and red (its reason is in the plan's checks)."""
    where = {n["id"]: n["pos"] for n in res["graph"]["nodes"]}
    trans = res["transitions"]
    ok = [t for t in trans if t["feasible"]]
    bad = [t for t in trans if not t["feasible"]]
    if ok:
        add_spheres(
            ctx.scene,
            f"{root}/transitions/feasible",
            local([where[t["vertex"]] for t in ok]),
            radius=0.055,
            colors=np.array(
                [MOBILE_RGB if t["mode"] == "mobile" else INCHWORM_RGB for t in ok], np.uint8
            ),
        )
    if bad:
        add_spheres(
            ctx.scene,
            f"{root}/transitions/infeasible",
            local([where[t["vertex"]] for t in bad]),
            radius=0.08,
            colors=FAIL_RGB,
        )


def _draw_gaps(ctx: DrawContext, root: str, res: dict[str, Any], local: Any) -> None:
    """Each gap's two closest points joined by a red segment, labelled with
    its width and whether a jump joins it."""
    gaps = res["gaps"]
    if not gaps:
        return
    segs = np.stack([local(g["points"]) for g in gaps])
    _segments(f"{root}/gaps", ctx, segs, GAP_RGB, 5.0)
    for i, (g, s) in enumerate(zip(gaps, segs, strict=True)):
        ctx.scene.add_label(
            f"{root}/gap_labels/{i}",
            text=f"gap {g['width_m']:.2f} m {'jump' if g['joined'] else 'open'}",
            position=tuple(float(x) for x in s.mean(axis=0)),
        )
