"""Drawing helpers shared by the per-kind scene drawers."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from server.scene.context import current_scene_client

if TYPE_CHECKING:
    from server.scene.context import DrawContext

#: Qualitative palette (Tableau 10) for clusters, planes and sequences.
PALETTE = np.array(
    [
        [31, 119, 180], [255, 127, 14], [44, 160, 44], [214, 39, 40], [148, 103, 189],
        [140, 86, 75], [227, 119, 194], [127, 127, 127], [188, 189, 34], [23, 190, 207],
    ],
    dtype=np.uint8,
)  # fmt: skip

PASS_RGB = (40, 170, 70)
FAIL_RGB = (220, 50, 50)
STEEL_RGB = (150, 160, 175)
ROUTE_RGB = (255, 140, 0)
VERTEX_RGB = (90, 200, 255)


def label_colors(labels: np.ndarray) -> np.ndarray:
    """(N,3) uint8 colour per integer label; negative labels (noise) grey."""
    labels = np.asarray(labels, dtype=int)
    out = PALETTE[np.mod(labels, len(PALETTE))].copy()
    out[labels < 0] = (90, 90, 90)
    return out


def ramp_colors(n: int) -> np.ndarray:
    """(n,3) uint8 blue→yellow ramp, for order along a sequence."""
    t = np.linspace(0.0, 1.0, max(n, 1))[:, None]
    a = np.array([40, 60, 200], float)
    b = np.array([250, 220, 30], float)
    return (a + t * (b - a)).astype(np.uint8)


def icosphere(subdivisions: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """Unit icosphere (vertices, faces) for batched sphere instances."""
    t = (1.0 + 5**0.5) / 2.0
    v = np.array(
        [[-1, t, 0], [1, t, 0], [-1, -t, 0], [1, -t, 0], [0, -1, t], [0, 1, t],
         [0, -1, -t], [0, 1, -t], [t, 0, -1], [t, 0, 1], [-t, 0, -1], [-t, 0, 1]],
        dtype=float,
    )  # fmt: skip
    f = np.array(
        [[0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11], [1, 5, 9], [5, 11, 4],
         [11, 10, 2], [10, 7, 6], [7, 1, 8], [3, 9, 4], [3, 4, 2], [3, 2, 6], [3, 6, 8],
         [3, 8, 9], [4, 9, 5], [2, 4, 11], [6, 2, 10], [8, 6, 7], [9, 8, 1]],
        dtype=np.uint32,
    )  # fmt: skip
    verts = list(v / np.linalg.norm(v, axis=1, keepdims=True))
    faces = f
    for _ in range(subdivisions):
        cache: dict[tuple[int, int], int] = {}
        new = []
        for a, b, c in faces:
            ab, bc, ca = (_midpoint(verts, cache, x, y) for x, y in ((a, b), (b, c), (c, a)))
            new += [[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]
        faces = np.array(new, dtype=np.uint32)
    return np.array(verts, dtype=np.float32), faces


def _midpoint(verts: list[np.ndarray], cache: dict[tuple[int, int], int], a: int, b: int) -> int:
    """Index of the unit-sphere midpoint of edge (a, b), shared between faces."""
    key = (min(a, b), max(a, b))
    if key not in cache:
        m = (verts[a] + verts[b]) / 2.0
        verts.append(m / np.linalg.norm(m))
        cache[key] = len(verts) - 1
    return cache[key]


def disc_mesh(segments: int = 24) -> tuple[np.ndarray, np.ndarray]:
    """Unit disc in the xy plane (vertices, faces), for blast discs."""
    ang = np.linspace(0, 2 * np.pi, segments, endpoint=False)
    verts = np.vstack([[0, 0, 0], np.c_[np.cos(ang), np.sin(ang), np.zeros(segments)]])
    faces = np.array([[0, 1 + i, 1 + (i + 1) % segments] for i in range(segments)], dtype=np.uint32)
    return verts.astype(np.float32), faces


def add_spheres(
    scene: Any,
    name: str,
    positions: np.ndarray,
    *,
    radius: float,
    colors: np.ndarray | tuple[int, int, int] = (90, 200, 255),
    on_click: Callable[[int], None] | None = None,
) -> Any:
    """Many spheres as one batched mesh; ``on_click(index)`` on a click."""
    positions = np.asarray(positions, dtype=np.float32).reshape(-1, 3)
    verts, faces = icosphere(1)
    n = len(positions)
    cols = np.broadcast_to(np.asarray(colors, dtype=np.uint8), (n, 3)).copy()
    handle = scene.add_batched_meshes_simple(
        name,
        vertices=verts * radius,
        faces=faces,
        batched_wxyzs=np.tile(np.array([1.0, 0, 0, 0], np.float32), (n, 1)),
        batched_positions=positions,
        batched_colors=cols,
        lod="off",
    )
    if on_click is not None:

        @handle.on_click
        def _(event: Any) -> None:
            idx = getattr(event, "instance_index", None)
            if idx is not None:
                # Tag the call with the clicking client for per-client rate limits.
                token = current_scene_client.set(getattr(event, "client_id", None))
                try:
                    on_click(int(idx))
                finally:
                    current_scene_client.reset(token)

    return handle


def add_start_end_picker(
    ctx: DrawContext,
    name: str,
    ids: Sequence[Any],
    positions: np.ndarray,
    *,
    chosen: dict[str, Any],
    radius: float,
    label_positions: np.ndarray,
) -> None:
    """Graph vertices as clickable spheres labelled with their ids, the
    plan's ``chosen`` start green and end red: the first click picks the
    start, the second the end, then a plan with both is proposed (the
    console confirms it, like every scene action)."""
    picks: list[Any] = []

    def clicked(i: int) -> None:
        with ctx.lock:
            picks.append(ids[i])
            if len(picks) == 2:
                ctx.propose({"start": picks[0], "end": picks[1]})
                picks.clear()

    colors = np.tile(np.array(VERTEX_RGB, np.uint8), (len(ids), 1))
    for role, rgb in (("start", PASS_RGB), ("end", FAIL_RGB)):
        if chosen.get(role) in ids:
            colors[list(ids).index(chosen[role])] = rgb
    add_spheres(
        ctx.scene, f"{name}/vertices", positions, radius=radius, colors=colors, on_click=clicked
    )
    for v, p in zip(ids, label_positions, strict=True):
        ctx.scene.add_label(
            f"{name}/vertex_ids/{v}", text=str(v), position=tuple(float(x) for x in p)
        )


def add_polyline(
    scene: Any,
    name: str,
    xyz: np.ndarray,
    color: tuple[int, int, int],
    width: float = 2.0,
    closed: bool = False,
) -> Any:
    xyz = np.asarray(xyz, dtype=np.float32).reshape(-1, 3)
    if closed and len(xyz) > 2:
        xyz = np.vstack([xyz, xyz[:1]])
    segs = np.stack([xyz[:-1], xyz[1:]], axis=1)
    return scene.add_line_segments(
        name, points=segs, colors=color, thickness=width, thickness_units="screen"
    )


def rotation_to_wxyz(R: np.ndarray) -> tuple[float, float, float, float]:
    """A rotation matrix as the (w, x, y, z) quaternion viser expects
    (scipy's ``as_quat`` is scalar-last, hence the reorder)."""
    from scipy.spatial.transform import Rotation

    x, y, z, w = Rotation.from_matrix(np.asarray(R, dtype=float)[:3, :3]).as_quat()
    return float(w), float(x), float(y), float(z)


def pose_to_wxyz_position(T: np.ndarray) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """A 4×4 pose as ((w, x, y, z), (x, y, z))."""
    return rotation_to_wxyz(T), tuple(float(v) for v in np.asarray(T)[:3, 3])
