"""Synthetic planar steel-bar structures as the ARA's depth camera sees them.

The seed's navigation experiment (§5.2.3, Fig. 1.2 / 5.5) used Cross, T, L,
K and I shapes assembled from steel bars, seen by an RGB-D camera on the
robot ("the farther to the camera, the more degrading of sensory data
quality").  This module builds such scenes with ground truth, plus Warren
and Pratt truss panels (3–6 bays), for tests, samples and benchmarks:

* layout: nodes and bars (graph edges) in the structure plane, bars 0.5–2 m
  physical length, flanges 60–150 mm wide;
* camera model: points sampled uniformly on the steel, thinned with
  probability ∝ cos(incidence)/range² (density falls with range), depth
  noise along the viewing ray with σ(r) = σ0 + k·r² (Kinect-like growth),
  dropout holes (never wider than 0.6 × the flange, so no bar is severed),
  a few per cent of outliers off the plane;
* placement: the structure plane tilted 2–5° and offset from the robot
  frame origin.

Ground truth: a component label per point (bar ``b`` → ``b``; cross area
``j`` → ``n_bars + j``; outlier → −1), a bar/cross kind per component and
the skeleton graph (networkx: node ``pos`` xyz in the robot frame, edge
``bar`` id, ``width_m``, ``weight`` metres).  A point is in a cross area when
it lies on two or more bar rectangles (bars are extended past a junction
node by half the widest non-collinear bar there, so the overlap is the
physical crossing).  Everything is deterministic in ``seed``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import networkx as nx
import numpy as np

from planners.errors import InvalidInputError

SHAPES: tuple[str, ...] = ("cross", "t", "l", "k", "i", "warren", "pratt")


@dataclass(frozen=True)
class Layout:
    """Bars as straight strips between nodes in the structure plane (metres)."""

    nodes: np.ndarray  # (V, 2)
    bars: np.ndarray  # (B, 2) node indices
    widths: np.ndarray  # (B,) flange width per bar


@dataclass
class SyntheticStructure:
    """A synthetic cloud with its ground truth (see module docstring)."""

    name: str
    seed: int
    points: np.ndarray  # (N, 3) robot frame
    labels: np.ndarray  # (N,) component id, -1 outlier
    kinds: list[str]  # per component: "bar" | "cross"
    graph: nx.Graph  # true skeleton
    layout: Layout
    to_robot: np.ndarray  # 4x4: structure plane frame → robot frame
    camera_m: np.ndarray  # (3,) camera position in the robot frame
    junction_nodes: list[int] = field(default_factory=list)

    @property
    def n_bars(self) -> int:
        return len(self.layout.bars)

    def bar_centerline(self, bar: int, step_m: float = 0.01) -> np.ndarray:
        """(M, 3) samples of bar ``bar``'s centre line (node to node), robot frame."""
        a, b = self.layout.bars[bar]
        pa, pb = self.layout.nodes[a], self.layout.nodes[b]
        n = max(2, int(np.ceil(np.linalg.norm(pb - pa) / step_m)) + 1)
        t = np.linspace(0.0, 1.0, n)[:, None]
        return self.lift(pa + t * (pb - pa))

    def lift(self, uv: np.ndarray) -> np.ndarray:
        """Structure-plane (M, 2) coordinates → robot-frame (M, 3) points."""
        uv = np.asarray(uv, dtype=float).reshape(-1, 2)
        h = np.column_stack([uv, np.zeros(len(uv)), np.ones(len(uv))])
        return (h @ self.to_robot.T)[:, :3]


# --------------------------------------------------------------------- layouts
def _unit(angle: float) -> np.ndarray:
    return np.array([np.cos(angle), np.sin(angle)])


def _star(
    rng: np.random.Generator, angles: list[float], lengths: list[float], widths: list[float]
) -> Layout:
    nodes = [np.zeros(2)] + [ln * _unit(a) for a, ln in zip(angles, lengths, strict=True)]
    bars = [(0, k + 1) for k in range(len(angles))]
    return Layout(np.array(nodes), np.array(bars), np.array(widths, dtype=float))


def _w(rng: np.random.Generator, lo: float = 0.06, hi: float = 0.15) -> float:
    return float(rng.uniform(lo, hi))


def _layout_cross(rng: np.random.Generator) -> Layout:
    # Two straight bars crossing at 90° ± 10°.
    second = np.pi / 2 + np.deg2rad(rng.uniform(-10, 10))
    angles = [0.0, second, np.pi, second + np.pi]
    w1, w2 = _w(rng), _w(rng)
    return _star(rng, angles, list(rng.uniform(0.5, 1.1, 4)), [w1, w2, w1, w2])


def _layout_t(rng: np.random.Generator) -> Layout:
    stem = np.pi / 2 + np.deg2rad(rng.uniform(-8, 8))
    wc, ws = _w(rng), _w(rng)
    lengths = [rng.uniform(0.45, 1.0), rng.uniform(0.45, 1.0), rng.uniform(0.6, 1.5)]
    return _star(rng, [0.0, np.pi, stem], lengths, [wc, wc, ws])


def _layout_l(rng: np.random.Generator) -> Layout:
    second = np.pi / 2 + np.deg2rad(rng.uniform(-12, 12))
    return _star(rng, [0.0, second], list(rng.uniform(0.6, 1.6, 2)), [_w(rng), _w(rng)])


def _layout_k(rng: np.random.Generator) -> Layout:
    phi1, phi2 = np.deg2rad(rng.uniform(35, 55, 2))
    wv, wd1, wd2 = _w(rng), _w(rng, 0.06, 0.12), _w(rng, 0.06, 0.12)
    angles = [np.pi / 2, -np.pi / 2, np.pi / 2 - phi1, -np.pi / 2 + phi2]
    lengths = [rng.uniform(0.5, 1.0), rng.uniform(0.5, 1.0), *rng.uniform(0.5, 1.2, 2)]
    return _star(rng, angles, lengths, [wv, wv, wd1, wd2])


def _layout_i(rng: np.random.Generator) -> Layout:
    length = rng.uniform(0.8, 1.6)
    wm, w1, w2 = _w(rng), _w(rng), _w(rng)
    j1, j2 = np.zeros(2), np.array([length, 0.0])
    nodes = [j1, j2]
    bars: list[tuple[int, int]] = [(0, 1)]
    widths = [wm]
    for jn, (node, wc) in enumerate(((j1, w1), (j2, w2))):
        perp = np.pi / 2 + np.deg2rad(rng.uniform(-6, 6))
        for sign in (1.0, -1.0):
            nodes.append(node + sign * rng.uniform(0.3, 0.7) * _unit(perp))
            bars.append((jn, len(nodes) - 1))
            widths.append(wc)
    return Layout(np.array(nodes), np.array(bars), np.array(widths))


def _layout_warren(rng: np.random.Generator) -> Layout:
    n = int(rng.integers(3, 7))
    bay = rng.uniform(0.6, min(1.0, 4.0 / n))
    height = 0.5 * bay * np.tan(np.deg2rad(rng.uniform(50, 65)))
    wc, wd = _w(rng, 0.10, 0.15), _w(rng, 0.06, 0.10)
    bottom = [np.array([i * bay, 0.0]) for i in range(n + 1)]
    top = [np.array([(i + 0.5) * bay, height]) for i in range(n)]
    nodes = bottom + top
    t0 = n + 1
    bars, widths = [], []
    for i in range(n):
        bars.append((i, i + 1))
        widths.append(wc)
    for i in range(n - 1):
        bars.append((t0 + i, t0 + i + 1))
        widths.append(wc)
    for i in range(n):
        bars += [(i, t0 + i), (t0 + i, i + 1)]
        widths += [wd, wd]
    return Layout(np.array(nodes), np.array(bars), np.array(widths))


def _layout_pratt(rng: np.random.Generator) -> Layout:
    n = int(rng.integers(3, 7))
    bay = rng.uniform(0.5, min(0.8, 4.0 / n))
    height = rng.uniform(0.5, 0.8)
    wc, wv, wd = _w(rng, 0.10, 0.15), _w(rng, 0.06, 0.10), _w(rng, 0.06, 0.10)
    bottom = [np.array([i * bay, 0.0]) for i in range(n + 1)]
    top = [np.array([i * bay, height]) for i in range(n + 1)]
    nodes = bottom + top
    t0 = n + 1
    bars, widths = [], []
    for i in range(n):
        bars += [(i, i + 1), (t0 + i, t0 + i + 1)]
        widths += [wc, wc]
    for i in range(n + 1):
        bars.append((i, t0 + i))
        widths.append(wv)
    for i in range(n):
        # Pratt diagonals slope down towards mid-span.
        bars.append((t0 + i, i + 1) if i < n / 2 else (i, t0 + i + 1))
        widths.append(wd)
    return Layout(np.array(nodes), np.array(bars), np.array(widths))


_LAYOUTS: dict[str, Callable[[np.random.Generator], Layout]] = {
    "cross": _layout_cross,
    "t": _layout_t,
    "l": _layout_l,
    "k": _layout_k,
    "i": _layout_i,
    "warren": _layout_warren,
    "pratt": _layout_pratt,
}


# ----------------------------------------------------------------- geometry
def _bar_frames(layout: Layout) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Per bar: start point, unit axis, s-range (lo, hi) along the axis, half width.

    Bars are extended past a junction node by half the widest bar meeting
    them there at more than 10° (collinear continuations do not count), so the
    union of strips covers the whole crossing without gaps or stubs.
    """
    nodes, bars, widths = layout.nodes, layout.bars, layout.widths
    p0 = nodes[bars[:, 0]]
    vec = nodes[bars[:, 1]] - p0
    length = np.linalg.norm(vec, axis=1)
    axis = vec / length[:, None]
    lo = np.zeros(len(bars))
    hi = length.copy()
    for b in range(len(bars)):  # loops over bars (tens), not points
        for end, node in enumerate(bars[b]):
            others = [o for o in range(len(bars)) if o != b and node in bars[o]]
            ext = 0.0
            for o in others:
                if abs(float(axis[b] @ axis[o])) < np.cos(np.deg2rad(10.0)):
                    ext = max(ext, widths[o] / 2.0)
            if end == 0:
                lo[b] = -ext
            else:
                hi[b] = length[b] + ext
    return p0, axis, np.column_stack([lo, hi]), widths / 2.0


def _in_bars(uv: np.ndarray, frames: tuple[np.ndarray, ...]) -> np.ndarray:
    """(N, B) membership of points in each bar strip (vectorised)."""
    p0, axis, srange, half = frames
    d = uv[:, None, :] - p0[None, :, :]
    s = np.einsum("nbk,bk->nb", d, axis)
    t = d[..., 0] * axis[None, :, 1] - d[..., 1] * axis[None, :, 0]
    return (s >= srange[None, :, 0]) & (s <= srange[None, :, 1]) & (np.abs(t) <= half[None, :])


def _sample_steel(rng: np.random.Generator, n: int, frames: tuple[np.ndarray, ...]) -> np.ndarray:
    """``n`` points uniform over the union of bar strips (overlaps not doubled)."""
    p0, axis, srange, half = frames
    area = (srange[:, 1] - srange[:, 0]) * 2 * half
    out: list[np.ndarray] = []
    # Oversample each strip by its area share; a point drawn in strip b is kept
    # only if no earlier strip contains it, so the union is sampled uniformly.
    counts = rng.multinomial(int(n * 1.3) + 50, area / area.sum())
    for b, m in enumerate(counts):
        s = rng.uniform(srange[b, 0], srange[b, 1], m)
        t = rng.uniform(-half[b], half[b], m)
        perp = np.array([-axis[b, 1], axis[b, 0]])
        uv = p0[b] + s[:, None] * axis[b] + t[:, None] * perp
        if b:
            member = _in_bars(uv, tuple(f[:b] for f in frames))
            uv = uv[~member.any(axis=1)]
        out.append(uv)
    pts = np.concatenate(out)
    return pts[rng.permutation(len(pts))]


def _rot(axis: np.ndarray, angle: float) -> np.ndarray:
    axis = axis / np.linalg.norm(axis)
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * (k @ k)


# ---------------------------------------------------------------- generator
def make_structure(
    shape: str,
    seed: int = 0,
    *,
    n_points: int = 30_000,
    outlier_fraction: tuple[float, float] = (0.02, 0.05),
    noise_sigma0_m: float = 0.0005,
    noise_k_per_m: float = 0.001,
    camera_height_m: float = 1.0,
    holes_per_bar: float = 0.6,
    flange_m: tuple[float, float] = (0.06, 0.15),
    scale: float = 1.0,
) -> SyntheticStructure:
    """Generate ``shape`` (one of :data:`SHAPES`) with ground truth; deterministic in ``seed``.

    ``n_points`` is the approximate total (steel + outliers).  Depth noise has
    σ(r) = ``noise_sigma0_m`` + ``noise_k_per_m``·r² along the viewing ray.
    ``flange_m`` maps the drawn widths (60–150 mm) linearly onto another
    range and ``scale`` multiplies every length — for scenes sized for a
    bigger robot; the defaults are the issue's ranges.
    """
    if shape not in _LAYOUTS:
        raise InvalidInputError(f"unknown structure {shape!r}; known: {', '.join(SHAPES)}")
    if int(n_points) < 100:
        raise InvalidInputError(f"n_points must be >= 100, got {n_points}")
    rng = np.random.default_rng([int(seed), SHAPES.index(shape)])
    layout = _LAYOUTS[shape](rng)
    if flange_m != (0.06, 0.15) or scale != 1.0:
        lo, hi = (float(v) for v in flange_m)
        if not 0 < lo <= hi or scale <= 0:
            raise InvalidInputError(
                f"flange_m must be 0 < lo <= hi and scale > 0, got {flange_m}, {scale}"
            )
        widths = lo + (layout.widths - 0.06) * (hi - lo) / 0.09
        layout = Layout(layout.nodes * float(scale), layout.bars, widths)

    # Place the structure: random yaw (trusses broadside), the nearest steel
    # 0.35–0.6 m ahead of the robot, tilted 2–5° about a random horizontal axis.
    nodes = layout.nodes - layout.nodes.mean(axis=0)
    layout = Layout(nodes, layout.bars, layout.widths)
    frames = _bar_frames(layout)
    if shape in ("warren", "pratt"):
        yaw = np.pi / 2 + np.deg2rad(rng.uniform(-15, 15))
    else:
        yaw = rng.uniform(-np.pi, np.pi)
    rz = _rot(np.array([0.0, 0.0, 1.0]), yaw)
    rotated = nodes @ rz[:2, :2].T
    x_near = rng.uniform(0.35, 0.6)
    shift = np.array([x_near - rotated[:, 0].min(), rng.uniform(-0.2, 0.2) - rotated[:, 1].mean()])
    tilt_axis = np.array([*_unit(rng.uniform(0, 2 * np.pi)), 0.0])
    rt = _rot(tilt_axis, np.deg2rad(rng.uniform(2.0, 5.0)))
    to_robot = np.eye(4)
    to_robot[:3, :3] = rt @ rz
    to_robot[:3, 3] = rt @ np.array([*shift, 0.0]) + np.array([0.0, 0.0, rng.uniform(-0.04, 0.04)])
    normal = to_robot[:3, 2]
    camera = np.array([0.0, 0.0, camera_height_m])

    def to_robot_pts(uv: np.ndarray) -> np.ndarray:
        return uv @ to_robot[:3, :2].T + to_robot[:3, 3]

    # Density falls with range: thin uniform samples with p ∝ cos(inc)/r².
    frac_out = rng.uniform(*outlier_fraction)
    n_steel = round(n_points * (1.0 - frac_out))
    pilot = to_robot_pts(_sample_steel(rng, 4000, frames)) - camera
    r_p = np.linalg.norm(pilot, axis=1)
    w_p = np.abs(pilot @ normal) / r_p**3
    w_ref = float(w_p.max())
    accept = float(np.mean(w_p / w_ref))
    uv = _sample_steel(rng, int(n_steel / accept * 1.15) + 100, frames)
    xyz = to_robot_pts(uv)
    ray = xyz - camera
    r = np.linalg.norm(ray, axis=1)
    keep = rng.random(len(uv)) < np.minimum(1.0, np.abs(ray @ normal) / r**3 / w_ref)
    uv, xyz, ray, r = (
        uv[keep][:n_steel],
        xyz[keep][:n_steel],
        ray[keep][:n_steel],
        r[keep][:n_steel],
    )

    # Dropout holes (specular spots): discs ≤ 0.3 × flange radius on the steel.
    membership = _in_bars(uv, frames)
    hole_count = rng.poisson(holes_per_bar * len(layout.bars))
    drop = np.zeros(len(uv), dtype=bool)
    for _ in range(hole_count):
        c = uv[rng.integers(len(uv))]
        b = int(np.argmax(_in_bars(c[None], frames)[0]))
        radius = rng.uniform(0.01, 0.3 * layout.widths[b])
        drop |= np.linalg.norm(uv - c, axis=1) < radius
    uv, xyz, ray, r, membership = uv[~drop], xyz[~drop], ray[~drop], r[~drop], membership[~drop]

    # Depth noise along the viewing ray, growing with range².
    sigma = noise_sigma0_m + noise_k_per_m * r**2
    xyz = xyz + (ray / r[:, None]) * (rng.standard_normal(len(r)) * sigma)[:, None]

    # Ground-truth labels from the clean positions.
    n_bars = len(layout.bars)
    degree = np.bincount(layout.bars.ravel(), minlength=len(layout.nodes))
    junctions = [int(v) for v in np.nonzero(degree >= 2)[0]]
    count = membership.sum(axis=1)
    labels = np.argmax(membership, axis=1).astype(np.int64)
    in_cross = count >= 2
    if junctions and np.any(in_cross):
        jpos = layout.nodes[junctions]
        dj = np.linalg.norm(uv[in_cross][:, None, :] - jpos[None], axis=2)
        labels[in_cross] = n_bars + np.argmin(dj, axis=1)

    # Outliers off the plane: clutter 3–40 cm above/below, over the footprint.
    n_out = round(n_points * frac_out)
    lo, hi = nodes.min(axis=0) - 0.3, nodes.max(axis=0) + 0.3
    o_uv = rng.uniform(lo, hi, size=(n_out, 2))
    o_h = rng.choice([-1.0, 1.0], n_out, p=[0.3, 0.7]) * rng.uniform(0.03, 0.4, n_out)
    o_xyz = to_robot_pts(o_uv) + o_h[:, None] * normal

    points = np.concatenate([xyz, o_xyz])
    all_labels = np.concatenate([labels, -np.ones(n_out, dtype=np.int64)])
    order = rng.permutation(len(points))
    points, all_labels = points[order], all_labels[order]

    graph: nx.Graph[int] = nx.Graph()
    for v, uvn in enumerate(nodes):
        graph.add_node(
            v,
            pos=tuple(to_robot_pts(uvn[None])[0]),
            pos2d=tuple(uvn),
            kind="junction" if degree[v] >= 2 else "leaf",
        )
    for b, (a, c) in enumerate(layout.bars):
        graph.add_edge(
            int(a),
            int(c),
            bar=b,
            width_m=float(layout.widths[b]),
            weight=float(np.linalg.norm(nodes[a] - nodes[c])),
        )
    kinds = ["bar"] * n_bars + ["cross"] * len(junctions)
    return SyntheticStructure(
        name=shape,
        seed=int(seed),
        points=points,
        labels=all_labels,
        kinds=kinds,
        graph=graph,
        layout=layout,
        to_robot=to_robot,
        camera_m=camera,
        junction_nodes=junctions,
    )


def _structure_fn(shape: str) -> Callable[[int], SyntheticStructure]:
    def make(seed: int) -> SyntheticStructure:
        return make_structure(shape, seed)

    make.__doc__ = f"The synthetic {shape!r} structure with ground truth."
    return make


def _cloud_fn(shape: str) -> Callable[[int], np.ndarray]:
    def make(seed: int) -> np.ndarray:
        return make_structure(shape, seed).points

    make.__doc__ = f"(N, 3) robot-frame cloud of the synthetic {shape!r} structure."
    return make


#: name → seed → structure with ground truth.
STRUCTURES: dict[str, Callable[[int], SyntheticStructure]] = {s: _structure_fn(s) for s in SHAPES}
#: name → seed → (N, 3) cloud, for ``POST /clouds {"sample": name}``.
SAMPLES: dict[str, Callable[[int], np.ndarray]] = {s: _cloud_fn(s) for s in SHAPES}
