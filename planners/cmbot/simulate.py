"""The simulation gate: every CMBOT motion is replayed at fine time steps
before it may be approved (seed §4: "the movement must be checked by the
simulation system before the robot starts to work").

The planned joint trajectory is interpolated (monotone cubic, no overshoot)
at ``substeps`` points per planning step and re-evaluated from scratch:
joint limits, joint speeds, foothold placement, the flip moment against the
magnet's holding moment (Eq. 9), clearance of the arm's covering spheres to
the environment and to its own links, tool tracking against Eq. 21–26 and the
static joint torques with the payload.  Every failed check lists where and
when it failed.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.interpolate import CubicSpline, PchipInterpolator

from planners.cmbot.arm import ArmKinematics
from planners.cmbot.balance import arm_mass_points_at, climber_mass_points_at, flip_moment, merge
from planners.cmbot.distance import (
    Cuboid,
    boxes_arrays,
    point_box_closed_form,
    sphere_box_exact,
    sphere_box_pairs,
)
from planners.cmbot.experiment import ClearanceFilter, Section4Trajectory
from planners.cmbot.gait import GaitTrajectory
from planners.cmbot.guardrail import Guardrail
from planners.cmbot.scene import climber_box_layout
from planners.motion.lipschitz import interiors


@dataclass(frozen=True)
class Violation:
    """One failed sample: check name, time [s], measured value, limit, where."""

    check: str
    t_s: float
    value: float
    limit: float
    where: str


@dataclass(frozen=True)
class GateCheck:
    """Outcome of one check over the whole motion (worst value vs limit)."""

    name: str
    passed: bool
    value: float
    limit: float
    message: str


@dataclass
class GateReport:
    """All checks of one simulated motion and the first violations of each."""

    checks: list[GateCheck] = field(default_factory=list)
    violations: list[Violation] = field(default_factory=list)
    dt_s: float = 0.0
    samples: int = 0
    #: Samples each clearance check evaluated exactly (coarse-then-fine gates only).
    clearance_samples: dict[str, int] = field(default_factory=dict)

    @property
    def passed(self) -> bool:
        return all(c.passed for c in self.checks)

    def failed(self) -> list[GateCheck]:
        return [c for c in self.checks if not c.passed]

    def summary(self) -> str:
        if self.passed:
            return f"all {len(self.checks)} checks passed over {self.samples} samples at {self.dt_s * 1e3:.1f} ms"
        return "; ".join(c.message for c in self.failed())


def _record(
    report: GateReport,
    name: str,
    values: np.ndarray,
    limit: float,
    times: np.ndarray,
    where: Callable[[int], str],
    what: str,
    unit: str,
    upper: bool = True,
    max_list: int = 5,
) -> None:
    """Add a check ``values ≤ limit`` (``upper``) or ``values ≥ limit`` with its
    violations; ``where(k)`` describes sample k (called only for reported samples)."""
    values = np.asarray(values, dtype=float)
    bad = values > limit if upper else values < limit
    worst = (
        float(np.nanmax(values) if upper else np.nanmin(values)) if values.size else float("nan")
    )
    k = int(np.nanargmax(values) if upper else np.nanargmin(values)) if values.size else 0
    passed = not bool(np.any(bad))
    bound = "at most" if upper else "at least"

    def q(v: float) -> str:
        return f"{v:.4g}" + (f" {unit}" if unit else "")

    # a rounding tolerance on a zero limit reads as 0
    lim = q(0.0 if abs(limit) < 1e-5 else limit)
    if passed:
        msg = f"{what} stays {bound} {lim}: the worst is {q(worst)}"
    else:
        msg = (
            f"{what} must stay {bound} {lim} but reaches {q(worst)} "
            f"at t = {times[k]:.3f} s ({where(k)})"
        )
    report.checks.append(GateCheck(name, passed, worst, float(limit), msg))
    for i in np.flatnonzero(bad)[:max_list]:
        report.violations.append(
            Violation(name, float(times[i]), float(values[i]), float(limit), where(int(i)))
        )


def _resample(
    times: np.ndarray,
    values: np.ndarray,
    substeps: int,
    smooth: bool = False,
    breaks: tuple[float, ...] = (),
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Cubic resampling: fine times, values, derivatives.  Monotone (PCHIP, no
    overshoot at the holds of a gait) or, with ``smooth``, C² cubic splines
    fitted separately between ``breaks`` (times where the commanded velocity
    jumps, so a spline must not ring across them)."""
    t = np.asarray(times, dtype=float)
    keep = np.concatenate([[True], np.diff(t) > 1e-12])
    t, v = t[keep], np.asarray(values, dtype=float)[keep]
    if len(t) < 2:
        return t, v, np.zeros_like(v)
    cuts = [0, *[int(np.searchsorted(t, b)) for b in breaks if t[0] < b < t[-1]], len(t) - 1]
    T_out, V_out, D_out = [], [], []
    for i, (a, b) in enumerate(itertools.pairwise(cuts)):
        ts, vs = t[a : b + 1], v[a : b + 1]
        # np.linspace(x, y, substeps, endpoint=False) for every interval at once
        # (same arithmetic: k·((y − x)/substeps) + x, so the same floats).
        step = (ts[1:] - ts[:-1]) / substeps
        fine = (np.arange(substeps)[None, :] * step[:, None] + ts[:-1, None]).ravel()
        if i == len(cuts) - 2:
            fine = np.concatenate([fine, ts[-1:]])
        f: CubicSpline | PchipInterpolator
        if smooth and len(ts) >= 4:
            f = CubicSpline(ts, vs, axis=0)
        else:
            f = PchipInterpolator(ts, vs, axis=0)
        T_out.append(fine)
        V_out.append(f(fine))
        D_out.append(f.derivative()(fine))
    return np.concatenate(T_out), np.concatenate(V_out), np.concatenate(D_out)


def min_clearance(
    centers: np.ndarray,
    radii: np.ndarray,
    boxes: tuple[np.ndarray, np.ndarray, np.ndarray],
    *,
    mask: np.ndarray | None = None,
    cap: float = 1.0,
    chunk: int = 500,
    window: int = 48,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per time step: the smallest sphere–box distance (capped at ``cap``), and
    which sphere and box give it.  ``boxes`` centres/rotations may carry the
    time axis.

    Static boxes: the samples go in windows of ``window``; within one, each
    sphere stays in a ball (centre m_i, radius ρ_i) and, the signed distance to
    a box being 1-Lipschitz, every sample's d_ij lies in D_ij(m_i) − r_i ± ρ_i.
    U = min over pairs of the upper ends bounds every sample's minimum, so only
    the pairs whose lower end is ≤ min(U, cap) are evaluated exactly — the
    minimum (below the cap) is never among the pairs left out.  Moving boxes:
    boxes whose bounding-sphere lower bound exceeds ``cap`` over a whole chunk
    are skipped.
    """
    bc, bh, bR = boxes
    T = len(centers)
    out = np.full(T, cap)
    sph = np.zeros(T, dtype=int)
    box = np.zeros(T, dtype=int)
    if bc.ndim == 2:
        _min_clearance_static(centers, radii, boxes, mask, cap, window, out, sph, box)
        return out, sph, box
    circum = np.linalg.norm(bh, axis=-1)
    for a in range(0, T, chunk):
        b = min(a + chunk, T)
        C = centers[a:b]
        bcc = bc[a:b]
        lb = (
            np.linalg.norm(C[:, :, None, :] - bcc[:, None, :, :], axis=-1)
            - radii[None, :, None]
            - circum
        )
        if mask is not None:
            lb = np.where(mask[None], lb, np.inf)
        near = np.flatnonzero(lb.min(axis=(0, 1)) <= cap)
        if not len(near):
            continue
        d, _ = sphere_box_exact(
            C, radii, (bcc[:, near], bh[near], bR[a:b][:, near]), directions=False
        )
        if mask is not None:
            d = np.where(mask[None][:, :, near], d, np.inf)
        flat = d.reshape(b - a, -1)
        kk = flat.argmin(axis=1)
        out[a:b] = np.minimum(flat[np.arange(b - a), kk], cap)
        sph[a:b] = kk // len(near)
        box[a:b] = near[kk % len(near)]
    return out, sph, box


def _min_clearance_static(
    centers: np.ndarray,
    radii: np.ndarray,
    boxes: tuple[np.ndarray, np.ndarray, np.ndarray],
    mask: np.ndarray | None,
    cap: float,
    window: int,
    out: np.ndarray,
    sph: np.ndarray,
    box: np.ndarray,
) -> None:
    """:func:`min_clearance` against static boxes, windowed with Lipschitz bounds."""
    r = np.asarray(radii, dtype=float)
    for a in range(0, len(centers), window):
        b = min(a + window, len(centers))
        C = centers[a:b]
        mid = 0.5 * (C.max(axis=0) + C.min(axis=0))  # (N,3)
        rho = np.sqrt(((C - mid) ** 2).sum(axis=-1)).max(axis=0)  # (N,)
        dm, _ = sphere_box_exact(mid, r, boxes, directions=False)  # (N,M)
        lo = dm - rho[:, None]
        hi = dm + rho[:, None]
        if mask is not None:
            lo = np.where(mask, lo, np.inf)
            hi = np.where(mask, hi, np.inf)
        bound = min(float(hi.min()), cap)
        si, bi = np.nonzero(lo <= bound)
        if not len(si):
            continue  # every pair stays beyond the cap here
        d = sphere_box_pairs(C, r, boxes, si, bi)  # (t,P)
        kk = d.argmin(axis=1)
        out[a:b] = np.minimum(d[np.arange(b - a), kk], cap)
        sph[a:b] = si[kk]
        box[a:b] = bi[kk]


def min_pair_clearance(
    centers: np.ndarray, radii: np.ndarray, pairs: np.ndarray, *, window: int = 48
) -> tuple[np.ndarray, np.ndarray]:
    """Per sample, the smallest sphere–sphere distance over ``pairs`` (P,2) of
    ``centers`` (T,N,3) and which pair gives it (first on ties).

    Windowed like :func:`min_clearance`: within a window, sphere i stays in a
    ball (m_i, ρ_i), so each pair's distance lies in ‖m_i − m_j‖ − r_i − r_j
    ± (ρ_i + ρ_j); only the pairs whose lower end can reach the smallest upper
    end are evaluated.  Every array is (window × pairs) at most.
    """
    r = np.asarray(radii, dtype=float)
    i, j = pairs[:, 0], pairs[:, 1]
    T = len(centers)
    out = np.full(T, np.inf)
    which = np.zeros(T, dtype=int)
    if not len(pairs):
        return out, which
    for a in range(0, T, window):
        b = min(a + window, T)
        C = centers[a:b]
        mid = 0.5 * (C.max(axis=0) + C.min(axis=0))
        rho = np.sqrt(((C - mid) ** 2).sum(axis=-1)).max(axis=0)
        dm = np.sqrt(((mid[i] - mid[j]) ** 2).sum(axis=-1)) - r[i] - r[j]
        spread = rho[i] + rho[j]
        keep = np.flatnonzero(dm - spread <= (dm + spread).min())
        diff = C[:, i[keep]] - C[:, j[keep]]
        d = np.sqrt((diff**2).sum(axis=-1)) - r[i[keep]] - r[j[keep]]
        kk = d.argmin(axis=1)
        out[a:b] = d[np.arange(b - a), kk]
        which[a:b] = keep[kk]
    return out, which


_Clearance = tuple[np.ndarray, np.ndarray, np.ndarray]
_GroupClearance = tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]

#: Coarse clearance stride [samples] of :func:`simulate_climb` (0.16 s at the default 10 ms).
COARSE_STRIDE = 16

#: Samples per FK/clearance chunk of :func:`simulate_climb` (bounds every per-sample array).
GATE_CHUNK = 2048

#: Slack on the coarse-then-fine lower bound against rounding (metres; far below any margin).
_BOUND_SLACK_M = 1e-9


class CoarseFineClearance:
    """Exact minimum clearance per sample without evaluating every sample.

    Samples come in chunks (:meth:`add`), each with ``steps[j]`` ≥ how far
    the clearance can change between its samples j and j+1 — the largest
    displacement of any sphere centre between them, in the frame of every box
    it is checked against (the distance to a fixed box is 1-Lipschitz in the
    centre).  Along a path of length P between samples a < b,
    ``d_j ≥ max(d_a − P(a, j), d_b − P(j, b)) ≥ (d_a + d_b − P(a, b)) / 2``.

    Every ``stride``-th sample (and each chunk's last) is evaluated exactly
    (coarse); the samples between two coarse ones are evaluated too (fine)
    only when that lower bound is within reach of the threshold
    ``max(limit, smallest clearance seen so far)``.  A sample left out is
    therefore strictly above the limit and strictly above the motion's
    minimum: the violations, the minimum and where it is are those of the
    dense check.  Left-out samples hold their lower bound in :attr:`value`.
    """

    def __init__(self, n: int, limit: float, stride: int) -> None:
        self.limit = float(limit)
        self.stride = max(1, int(stride))
        self.value = np.full(n, np.inf)
        self.sphere = np.zeros(n, dtype=int)
        self.box = np.zeros(n, dtype=int)
        self.evaluated = 0
        self._seen = np.inf

    def add(
        self,
        start: int,
        steps: np.ndarray,
        evaluate: Callable[[np.ndarray], _Clearance],
        groups: Callable[[np.ndarray], _GroupClearance] | None = None,
    ) -> None:
        """Samples ``start … start + len(steps)``; ``evaluate(local indices)``
        returns their exact (clearance, sphere, box).  With ``groups`` the
        clearance is the minimum over groups of boxes, each with its own step
        bound: ``steps`` (n−1, G), and ``groups(indices)`` evaluates the coarse
        samples: ``evaluate``'s triple plus (k, G) the exact clearance to each
        group (capped like ``evaluate``'s); the window bound
        is the smallest of the groups' bounds (tighter when the groups move
        differently, e.g. the climber's links)."""
        steps = np.asarray(steps, dtype=float)
        steps = steps.reshape(len(steps), int(np.prod(steps.shape[1:])))
        n = len(steps) + 1
        coarse = np.unique(np.concatenate([np.arange(0, n, self.stride), [n - 1]]))
        if groups is None:
            self._store(start, coarse, evaluate(coarse))
            d = self.value[start + coarse][:, None]
        else:
            dmin, sph, box, d = groups(coarse)
            self._store(start, coarse, (dmin, sph, box))
        thr = max(self.limit, self._seen) + _BOUND_SLACK_M
        a, b = coarse[:-1], coarse[1:]
        # P(a, b) per coarse interval: its steps summed (a[i+1] = b[i], so the
        # reduceat segments are exactly the intervals' steps)
        path = np.add.reduceat(steps, a, axis=0) if len(a) else np.zeros((0, steps.shape[1]))
        lb = ((d[:-1] + d[1:] - path) / 2.0).min(axis=1)
        gaps = b - a - 1
        refine = (lb <= thr) & (gaps > 0)
        fine = interiors(a[refine], b[refine])
        if len(fine):
            self._store(start, fine, evaluate(fine))
        skip = ~refine & (gaps > 0)
        left = interiors(a[skip], b[skip])
        self.value[start + left] = np.repeat(lb[skip], gaps[skip])

    def _store(
        self, start: int, idx: np.ndarray, res: tuple[np.ndarray, np.ndarray, np.ndarray]
    ) -> None:
        d, s, b = res
        self.value[start + idx] = d
        self.sphere[start + idx] = s
        self.box[start + idx] = b
        self.evaluated += len(idx)
        if len(d):
            self._seen = min(self._seen, float(np.min(d)))


#: Window [evaluated samples] of :func:`culled_clearance` for the fine samples.
CULL_WINDOW = 48

#: Window of :func:`culled_clearance` for the coarse samples (``COARSE_STRIDE`` apart).
CULL_WINDOW_COARSE = 24

#: Slack on the culling comparison [m]: the bounds come from the groups' own
#: frames, the exact distances from the world frame (rounding apart, equal).
_CULL_SLACK_M = 1e-9

#: Exact distances (t, P) of the pairs (spheres ``si``, boxes ``bi``) at samples ``rows``.
_PairDistances = Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray]


def culled_clearance(
    local: np.ndarray,
    radii: np.ndarray,
    boxes: tuple[np.ndarray, np.ndarray, np.ndarray],
    group: np.ndarray,
    exact: _PairDistances,
    *,
    cap: float,
    window: int,
    per_group: bool,
    per_group_local: bool = False,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray | None]:
    """Windowed Lipschitz culling of sphere–box clearances (boxes in groups, each
    group fixed in its own frame).

    ``local`` (T,G,S,3): the sphere centres in each group's frame; ``boxes``
    (centres, half extents, rotations) in their group's frame, ``group`` (M,)
    the group of each box.  Within a window of ``window`` samples sphere i
    stays, in group g's frame, in a ball (m_gi, ρ_gi); the signed distance to
    a box being 1-Lipschitz (rigid frames keep distances), every sample's
    d_ij lies in D_ij(m) − r_i ± ρ (the seed's closed form, §3.2 Fig. 13).
    A pair whose lower end exceeds min(smallest upper end, cap) can be neither
    the minimum below the cap nor tie with it, so only the others go to
    ``exact(rows, si, bi)`` (t,P).  ``per_group`` takes the smallest upper end
    per (group, sphere), which also gives each group's minimum per sphere.
    With ``per_group_local`` those per-group minima come from the groups' own
    frames (boxes static there: no per-sample box transforms), less the
    slack — lower bounds within ``_CULL_SLACK_M`` of the exact minima — and
    only the pairs that can hold the overall minimum go to ``exact``.

    Returns, per sample, the clearance capped at ``cap``, its sphere and box
    (the dense check's first pair on ties: pairs stay sphere-major) and, with
    ``per_group``, the capped minimum per group and sphere (T, G·S).
    """
    T, G, S = local.shape[:3]
    bc, bh, bR = boxes
    r = np.asarray(radii, dtype=float)
    out = np.full(T, cap)
    sph = np.zeros(T, dtype=int)
    box = np.zeros(T, dtype=int)
    per = np.full((T, G * S), cap) if per_group else None
    if not len(bh) or not T:
        return out, sph, box, per
    order = np.argsort(group, kind="stable")
    starts = np.flatnonzero(np.r_[True, np.diff(group[order]) != 0])
    first = group[order][starts]
    for a in range(0, T, window):
        b = min(a + window, T)
        C = local[a:b]
        mid = 0.5 * (C.max(axis=0) + C.min(axis=0))  # (G,S,3)
        dx = C - mid
        rho = np.sqrt(dx[..., 0] ** 2 + dx[..., 1] ** 2 + dx[..., 2] ** 2).max(axis=0)  # (G,S)
        rel = np.swapaxes(mid[group], 0, 1) - bc  # (S,M,3): sphere i in box j's frame
        dm, _ = point_box_closed_form(rel, bh, bR, directions=False)
        spread = rho[group].T  # (S,M)
        lo = dm - r[:, None] - spread
        hi = dm - r[:, None] + spread
        if per_group:
            # smallest upper end over each (group, sphere), spread back over its boxes
            hmin = np.minimum.reduceat(hi[:, order], starts, axis=1)  # (S, groups present)
            slot = np.searchsorted(first, group)
            bound = np.minimum(hmin[:, slot], cap)
        else:
            bound = np.full_like(hi, min(float(hi.min()), cap))
        keep = lo <= bound + _CULL_SLACK_M
        si, bi = np.nonzero(keep)
        if not len(si):
            continue  # every pair stays beyond the cap here
        rows = np.arange(a, b)
        if per is not None and per_group_local:
            # per-group values from the groups' frames; world-frame distances
            # only for the pairs that can hold the overall minimum
            dl, _ = point_box_closed_form(
                C[:, group[bi], si] - bc[bi], bh[bi], bR[bi], directions=False
            )
            dper = dl - r[si] - _CULL_SLACK_M
            ti, tb = np.nonzero(keep & (lo <= min(float(hi.min()), cap) + _CULL_SLACK_M))
            d = exact(rows, ti, tb)
        else:
            ti, tb = si, bi
            d = dper = exact(rows, si, bi)  # (t,P)
        kk = d.argmin(axis=1)
        out[a:b] = np.minimum(d[np.arange(b - a), kk], cap)
        sph[a:b] = ti[kk]
        box[a:b] = tb[kk]
        if per is not None:
            key = group[bi] * S + si
            o = np.argsort(key, kind="stable")
            ks = key[o]
            cut = np.flatnonzero(np.r_[True, ks[1:] != ks[:-1]])
            per[a:b, ks[cut]] = np.minimum(np.minimum.reduceat(dper[:, o], cut, axis=1), cap)
    return out, sph, box, per


def _limit_checks(
    report: GateReport,
    names: list[str],
    t: np.ndarray,
    q: np.ndarray,
    qd: np.ndarray,
    limits: np.ndarray,
    vmax: np.ndarray,
) -> None:
    over = np.maximum(limits[:, 0] - q, q - limits[:, 1])  # > 0 outside
    j = np.argmax(over, axis=1)
    _record(
        report,
        "joint_limits",
        np.degrees(over.max(axis=1)),
        1e-6,
        t,
        lambda k: f"{names[j[k]]} at {np.degrees(q[k, j[k]]):.2f}°",
        "a joint's excursion past its limit (negative: inside it)",
        "deg",
    )
    ratio = np.abs(qd) / vmax
    js = np.argmax(ratio, axis=1)
    _record(
        report,
        "joint_speeds",
        ratio.max(axis=1),
        1.0 + 1e-6,
        t,
        lambda k: (
            f"{names[js[k]]} at {np.degrees(abs(qd[k, js[k]])):.1f}°/s of {np.degrees(vmax[js[k]]):.0f}°/s"
        ),
        "joint speed / limit",
        "",
    )


def _world_sphere_centers(arm: ArmKinematics, W: np.ndarray) -> np.ndarray:
    """World centres (T,S,3) of the arm's spheres from its world frames ``W``
    (T,9,4,4) = ``T_wk · frames(q)``: per frame and component, c_k = Σ_j R_kj·l_j
    + t_k on (T, spheres of the frame) arrays (no per-sample 3×3 products, no
    length-3 trailing axis in the arithmetic), equal to rounding."""
    s = arm.spheres
    out = np.empty((3, len(W), len(s.frame)))
    for f in np.unique(s.frame):
        idx = np.flatnonzero(s.frame == f)
        R = W[:, f, :3, :3]
        loc = s.local[idx]
        for k in range(3):
            out[k][:, idx] = (
                R[:, k, 0:1] * loc[:, 0]
                + R[:, k, 1:2] * loc[:, 1]
                + R[:, k, 2:3] * loc[:, 2]
                + W[:, f, k, 3:4]
            )
    return np.ascontiguousarray(np.moveaxis(out, 0, -1))


def _norm3(v: np.ndarray) -> np.ndarray:
    """Euclidean norm over the last (length-3) axis, written per axis (a
    reduction over a length-3 axis costs far more than the arithmetic)."""
    return np.sqrt(v[..., 0] * v[..., 0] + v[..., 1] * v[..., 1] + v[..., 2] * v[..., 2])


def simulate_climb(
    model: Any,
    guardrail: Guardrail,
    traj: GaitTrajectory,
    *,
    substeps: int = 2,
    arm_clearance_m: float = 0.05,
    coarse_stride: int = COARSE_STRIDE,
    chunk: int = GATE_CHUNK,
) -> GateReport:
    """Replay a climbing trajectory finely and check it (seed §4 simulation system).

    Checks: joint limits and speeds (J1…J12), holding soles on valid
    footholds and on the bar, swing sole never below the bar top, flip
    moment about the holding sole ≤ the magnet's holding moment (single
    support), folded-arm spheres clear of the guardrail and of the climbing
    mechanism.

    The two clearances are checked coarse-then-fine (:class:`CoarseFineClearance`,
    every ``coarse_stride``-th sample, windows refined where the motion bound
    reaches the limit or the minimum): the same verdicts, worst values and
    violations as evaluating every sample (tested against the dense gate in
    ``tests/cmbot/_reference_gate.py``).  FK, distances and flip moments run
    in chunks of ``chunk`` samples, so memory does not grow with the motion.
    """
    c = model.params["climber"]
    rep = GateReport()
    t, q, qd = _resample(traj.times, traj.q, substeps)
    _, rear, _ = _resample(traj.times, traj.rear, substeps)
    _, front, _ = _resample(traj.times, traj.front, substeps)
    idx = np.clip(np.searchsorted(traj.times, t, side="right") - 1, 0, len(traj.times) - 1)
    sup = traj.support[idx]
    rep.dt_s = float(np.median(np.diff(t))) if len(t) > 1 else 0.0
    rep.samples = len(t)
    names = list(model.urdf_joint_names)
    limits = np.vstack([model.climber.joint_limits, model.joint_limits])
    vmax = np.concatenate([model.climber.max_speed, model.max_speed])
    _limit_checks(rep, names, t, q, qd, limits, vmax)
    # Footholds: a holding sole sits on the bar top (z = 0) on a valid foothold.
    L = c["foot_length_m"]
    hold_rear = sup != 2
    hold_front = sup != 1
    bad = np.zeros(len(t))
    where: dict[int, str] = {}  # only the samples with a violation
    for holds, pos, name in ((hold_rear, rear, "rear"), (hold_front, front, "front")):
        ok = guardrail.valid_foothold(pos[:, 0], L) & (np.abs(pos[:, 2]) < 1e-6)
        viol = holds & ~ok
        for k in np.flatnonzero(viol):
            bad[k] = 1.0
            where[int(k)] = (
                f"{name} sole at x = {pos[k, 0]:.3f} m: {guardrail.why_invalid(pos[k, 0], L) or 'off the bar top'}"
            )
    _record(
        rep,
        "foot_placement",
        bad,
        0.0,
        t,
        lambda k: where.get(k, ""),
        "holding soles off a valid foothold (count)",
        "",
    )
    swing_z = np.where(sup == 1, front[:, 2], np.where(sup == 2, rear[:, 2], 0.0))
    _record(
        rep,
        "swing_above_bar",
        swing_z,
        -1e-9,
        t,
        lambda k: f"swing sole z = {swing_z[k] * 1e3:.2f} mm",
        "swing sole height above the bar top",
        "m",
        upper=False,
    )
    arm = ArmKinematics.from_model(model)
    # Clearance of the folded arm: guardrail (≥ arm_clearance_m) and own climbing
    # links (≥ 0), coarse-then-fine (CoarseFineClearance) over bounded chunks.
    lo = float(min(rear[:, 0].min(), front[:, 0].min())) - 3.0
    hi = float(max(rear[:, 0].max(), front[:, 0].max())) + 3.0
    env = guardrail.boxes(lo, hi)
    env_arr = boxes_arrays(env)
    radii = arm.spheres.radius
    body = arm.spheres.body >= 1
    n = len(t)
    env_cf = CoarseFineClearance(n, arm_clearance_m, coarse_stride)
    self_cf = CoarseFineClearance(n, 0.0, coarse_stride)
    # The climber's boxes: link frame, origin in it, half extents, names.
    box_frame, box_origin, box_half, bnames = climber_box_layout(model)
    links, box_link = np.unique(box_frame, return_inverse=True)
    box_local = (box_origin[:, :3, 3], box_half, box_origin[:, :3, :3])
    radii_body = radii[body]
    env_group = np.zeros(len(env), dtype=int)
    step = max(1, chunk // env_cf.stride) * env_cf.stride
    # Eq. 9 with the step dt and arithmetic of gait.flip_moments (accelerations
    # are zero below three samples).
    dt = float(np.median(np.diff(t))) if n > 2 else 0.0
    M = np.zeros((n, 3))
    s = 0
    while n:
        e = min(s + step, n - 1)
        # FK once per chunk for the flip moment and both clearances, with two
        # samples of margin on each side: the accelerations are central
        # differences of central differences, so the chunk's own flip moments
        # equal those of one pass over the motion.
        lo, hi = max(0, s - 2), min(n, e + 3)
        # The climber's world frames T_wr·F with T_wr the rear sole's translation:
        # that product only adds the translation (its other terms are exact
        # zeros), so the frames are F shifted, the same floats without the
        # (T,7,4,4) product; then the arm base (6) and the arm's world frames.
        Fw = model.climber.link_frames(q[lo:hi, :5])
        Fw[..., :3, 3] += rear[lo:hi, None]
        T_wk = Fw[:, 2] @ model.arm_mount  # arm_base_pose's arithmetic
        W = T_wk[:, None] @ arm.frames(q[lo:hi, 5:])
        f_end = n if e >= n - 1 else e  # flip moments of s … e − 1 (… n − 1 at the end)
        pts = merge(climber_mass_points_at(model, Fw), arm_mass_points_at(arm, W))
        pivot = np.where((sup[lo:hi] == 2)[:, None], front[lo:hi], rear[lo:hi])
        M[s:f_end] = flip_moment(pts, pivot, dt if dt else None)[s - lo : f_end - lo]
        own = slice(s - lo, e + 1 - lo)  # the clearance chunk: samples s … e
        centers = _world_sphere_centers(arm, W[own])
        # Per sphere: its own displacement bounds its own clearance.
        moved = _norm3(np.diff(centers, axis=0))

        def env_min(k: np.ndarray, C: np.ndarray = centers) -> _Clearance:
            return min_clearance(C[k], radii, env_arr, cap=1.0)

        def env_groups(k: np.ndarray, C: np.ndarray = centers) -> _GroupClearance:
            Ck = C[k]

            def pairs(rows: np.ndarray, si: np.ndarray, bi: np.ndarray) -> np.ndarray:
                return sphere_box_pairs(Ck[rows], radii, env_arr, si, bi)

            res = culled_clearance(
                Ck[:, None], radii, env_arr, env_group, pairs,
                cap=1.0, window=CULL_WINDOW_COARSE, per_group=True,
            )  # fmt: skip
            assert res[3] is not None
            return res[0], res[1], res[2], res[3]

        env_cf.add(s, moved, env_min, env_groups)
        # Self clearance: the boxes ride on the climber's links, so the bound is
        # the spheres' displacement in every link frame.
        Fw = Fw[own]
        cb = centers[:, body]
        F = Fw[:, links]
        # x_local = Rᵀx − Rᵀo in every link at once: one (S,3)·(3,3L) product
        # per sample (bounds only: rounding is far within the slack).
        G = len(links)
        R = F[:, :, :3, :3]
        Rcat = np.swapaxes(R, 1, 2).reshape(len(F), 3, 3 * G)  # [R_0 … R_G−1]
        off = np.einsum("tlj,tljk->tlk", F[:, :, :3, 3], R).reshape(len(F), 1, 3 * G)
        flat = cb @ Rcat - off  # (T,S,3G)
        nb = cb.shape[1]
        local = flat.reshape(len(F), nb, G, 3).transpose(0, 2, 1, 3)  # (T,G,S,3) view
        dl = np.diff(flat, axis=0).reshape(e - s, nb, G, 3)
        moved_rel = np.swapaxes(_norm3(dl), 1, 2).reshape(e - s, G * nb)  # group-major (G·S)

        def self_eval(
            k: np.ndarray,
            window: int,
            per_group: bool,
            C: np.ndarray = cb,
            L: np.ndarray = local,
            Fw: np.ndarray = Fw,
        ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray | None]:
            # World boxes only at the samples evaluated (climber_box_arrays' arithmetic).
            Tb = Fw[k][:, box_frame] @ box_origin
            Ck, bc, bR = C[k], Tb[..., :3, 3], Tb[..., :3, :3]

            def pairs(rows: np.ndarray, si: np.ndarray, bi: np.ndarray) -> np.ndarray:
                rel = Ck[rows][:, si] - bc[rows][:, bi]
                d, _ = point_box_closed_form(rel, box_half[bi], bR[rows][:, bi], directions=False)
                return d - radii_body[si]

            return culled_clearance(
                L[k], radii_body, box_local, box_link, pairs,
                cap=1.0, window=window, per_group=per_group, per_group_local=True,
            )  # fmt: skip

        def self_min(k: np.ndarray, ev: Any = self_eval) -> _Clearance:
            out, sph, box, _ = ev(k, CULL_WINDOW, False)
            return out, sph, box

        def self_groups(k: np.ndarray, ev: Any = self_eval) -> _GroupClearance:
            out, sph, box, per = ev(k, CULL_WINDOW_COARSE, True)
            return out, sph, box, per

        self_cf.add(s, moved_rel, self_min, self_groups)
        if e >= n - 1:
            break
        s = e
    # Flip moment (Eq. 9) at the fine steps, single support only.
    hold = c["foot_length_m"] / 2 * model.params["magnet"]["holding_force_N"]
    My = np.where(sup > 0, np.abs(M[:, 1]), 0.0)
    _record(
        rep,
        "flip_torque",
        My,
        hold,
        t,
        lambda k: f"about the {'rear' if sup[k] == 1 else 'front'} sole",
        "|flip moment| about the holding sole",
        "N·m",
    )
    rep.clearance_samples = {"arm_env": env_cf.evaluated, "self": self_cf.evaluated}
    si, bi = env_cf.sphere, env_cf.box
    _record(
        rep,
        "arm_env_clearance",
        env_cf.value,
        arm_clearance_m,
        t,
        lambda k: f"arm sphere {si[k]} ↔ {env[bi[k]].name}",
        "folded-arm clearance to the guardrail",
        "m",
        upper=False,
    )
    kk = self_cf.box
    _record(
        rep,
        "self_clearance",
        self_cf.value,
        0.0,
        t,
        lambda k: f"arm ↔ {bnames[kk[k]]}",
        "folded arm to the climbing mechanism",
        "m",
        upper=False,
    )
    return rep


def simulate_arm(
    arm: ArmKinematics,
    boxes: list[Cuboid],
    traj: Section4Trajectory,
    times: np.ndarray,
    q: np.ndarray,
    *,
    gravity: np.ndarray,
    payload_kg: float = 0.0,
    torque_limit_Nm: float = 150.0,
    min_clearance_m: float = 0.05,
    self_clearance_m: float = 0.02,
    tracking_tol_m: float = 1e-3,
    orientation_tol_rad: float = np.radians(0.1),
    substeps: int = 4,
    check_payload: bool = True,
    pair_filter: ClearanceFilter | None = None,
    clearance_cap_m: float = 1.0,
) -> GateReport:
    """Replay an arm motion finely and check it against Eq. 21–26 and the scene."""
    rep = GateReport()
    t, qf, qd = _resample(times, q, substeps, smooth=True, breaks=(traj.switch_s,))
    rep.dt_s = float(np.median(np.diff(t))) if len(t) > 1 else 0.0
    rep.samples = len(t)
    names = [f"J{i}" for i in range(6, 13)]
    _limit_checks(rep, names, t, qf, qd, arm.limits, arm.max_speed)
    F = arm.frames(qf)
    pos_d, R_d = traj.poses(t)
    perr = np.linalg.norm(F[:, -1, :3, 3] - pos_d, axis=1)
    _record(
        rep,
        "tracking",
        perr * 1e3,
        tracking_tol_m * 1e3,
        t,
        lambda k: f"tool at {np.round(F[k, -1, :3, 3] * 1e3, 1).tolist()} mm in (6)",
        "tool position error",
        "mm",
    )
    E = R_d @ np.swapaxes(F[:, -1, :3, :3], -1, -2)
    rerr = np.arccos(np.clip((np.trace(E, axis1=1, axis2=2) - 1.0) / 2.0, -1.0, 1.0))
    _record(
        rep,
        "orientation",
        np.degrees(rerr),
        np.degrees(orientation_tol_rad),
        t,
        lambda k: "tool orientation",
        "tool orientation error",
        "deg",
    )
    centers = arm.sphere_centers(F)
    flt = pair_filter or ClearanceFilter()
    mask = flt.mask(arm.spheres.body, boxes)
    clear, si, bi = min_clearance(
        centers, arm.spheres.radius, boxes_arrays(boxes), mask=mask, cap=clearance_cap_m
    )
    _record(
        rep,
        "clearance",
        clear,
        min_clearance_m,
        t,
        lambda k: f"sphere {si[k]} on frame {arm.spheres.frame[si[k]]} ↔ {boxes[bi[k]].name}",
        "arm clearance to obstacles",
        "m",
        upper=False,
    )
    b = arm.spheres.body
    pairs = np.abs(b[:, None] - b[None, :]) >= 2
    iu = np.argwhere(np.triu(pairs))
    self_d, ks = min_pair_clearance(centers, arm.spheres.radius, iu)
    _record(
        rep,
        "self_clearance",
        self_d,
        self_clearance_m,
        t,
        lambda k: f"spheres {iu[ks[k], 0]} ↔ {iu[ks[k], 1]}",
        "arm self-clearance",
        "m",
        upper=False,
    )
    if check_payload:
        tau = np.abs(arm.gravity_torques(qf, gravity, payload_kg))
        jt = tau.argmax(axis=1)
        _record(
            rep,
            "joint_torque",
            tau.max(axis=1),
            torque_limit_Nm,
            t,
            lambda k: f"{names[jt[k]]} with {payload_kg:g} kg at the tool",
            "static joint torque",
            "N·m",
        )
    return rep
