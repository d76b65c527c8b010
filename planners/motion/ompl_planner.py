"""Sampling-based joint-space planning through OMPL (Şucan, Moll & Kavraki 2012).

One wrapper, used as OMPL intends: a real-vector state space with the joint
bounds, the caller's state-validity callable and a motion validator injected
into the ``SpaceInformation`` (the planner knows nothing of the robot), a
planner from OMPL's geometric set (default RRT-Connect, Kuffner & LaValle
2000: two trees, extend one towards a uniform sample by at most ``range``,
connect the other greedily towards the new node), a termination condition
that is a time budget *and* an iteration budget, and OMPL's path simplifier
(random vertex reduction = shortcutting, then collapsing close vertices).

Validity callables keep the project's batched shape: ``valid(Q)`` maps (K, d)
configurations to (K,) bools.  The default motion validator checks a straight
joint segment at ``resolution`` (max joint step), coarse samples first (every
4th) so colliding segments are rejected cheaply, all in one batched call —
instead of OMPL's per-state discrete validator, which would call Python once
per configuration.

Determinism: OMPL seeds every RNG it creates from one process-global seed
generator (``ompl.util.RNG.setSeed``); each call re-seeds it with ``seed``
before building the planner and simplifier, so sequential calls in one
process with the same seed and inputs return the same path.

Optional ``weights`` plan in scaled coordinates ``y = w ⊙ q`` so OMPL's
Euclidean metric (nearest neighbours, ``range``) is the weighted one
``‖w ⊙ Δq‖₂``; validity is always evaluated on ``q``.

Optional ``periodic`` dimensions are angles on the circle (a mobile base's
yaw, a continuous joint): each is an OMPL ``SO2StateSpace`` (values in
[-π, π), interpolation and distance the short way round) in a compound
space after the real-vector part, weighted by its ``weights`` entry, so the
metric is ``‖w ⊙ Δq_lin‖₂ + Σ w_i |wrap(Δθ_i)|`` (OMPL's compound distance
is the weighted sum of its parts).  Without them the space is the plain
real-vector one, exactly as before.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
import ompl.base as ob
import ompl.geometric as og
import ompl.util as ou

from planners.errors import InvalidInputError

Valid = Callable[[np.ndarray], np.ndarray]  # (K, d) configurations → (K,) bool
MotionValid = Callable[[np.ndarray, np.ndarray], bool]  # straight segment a → b free?

# OMPL geometric planners offered by name (all take the same problem).
PLANNERS: dict[str, Callable[[ob.SpaceInformation], ob.Planner]] = {
    "rrt_connect": og.RRTConnect,
    "rrt": og.RRT,
    "rrt_star": og.RRTstar,
}

ou.setLogLevel(ou.LOG_WARN)  # OMPL's INFO lines would flood worker logs


@dataclass(frozen=True)
class MotionResult:
    """Outcome of :func:`plan_motion`.

    ``path`` is (P, d) from the start to one goal, both exact, or ``None``;
    ``status`` is ``"exact"`` on success, else ``"invalid_start"``,
    ``"invalid_goal"``, ``"timeout"`` (time or iteration budget spent) or
    OMPL's own status name; ``checks`` counts configurations passed to the
    validity callable (states and motion samples); ``goal_index`` is the
    goal the path ends at."""

    path: np.ndarray | None
    status: str
    checks: int
    planning_time_s: float
    iterations: int
    goal_index: int = -1
    vertices: int = 0  # states in the planner's trees (0 when no planner ran)

    @property
    def success(self) -> bool:
        return self.path is not None


def wrap_angle(a: np.ndarray | float) -> np.ndarray:
    """Angle(s) wrapped into [-π, π) (OMPL's SO2 range)."""
    return (np.asarray(a, dtype=float) + np.pi) % (2 * np.pi) - np.pi


def interpolate(
    a: np.ndarray, b: np.ndarray, resolution: float, periodic: Sequence[int] = ()
) -> np.ndarray:
    """Configurations from ``a`` (excluded) to ``b`` (included), max joint step
    ≤ resolution; ``periodic`` dimensions move the short way round and come
    out wrapped into [-π, π)."""
    if not len(periodic):
        n = max(1, int(np.ceil(np.max(np.abs(b - a)) / resolution)))
        s = np.arange(1, n + 1)[:, None] / n
        return a + s * (b - a)
    per = list(periodic)
    d = np.asarray(b, dtype=float) - a
    d[per] = wrap_angle(d[per])
    n = max(1, int(np.ceil(np.max(np.abs(d)) / resolution)))
    s = np.arange(1, n + 1)[:, None] / n
    out = a + s * d
    out[:, per] = wrap_angle(out[:, per])
    return out


def segment_validator(valid: Valid, resolution: float, periodic: Sequence[int] = ()) -> MotionValid:
    """A motion validator checking the straight segment every ``resolution``
    rad (both ends included), coarse pass first; ``periodic`` dimensions the
    short way round (:func:`interpolate`)."""

    def check(a: np.ndarray, b: np.ndarray) -> bool:
        cand = interpolate(a, b, resolution, periodic)
        coarse = np.zeros(len(cand), dtype=bool)
        coarse[3::4] = True
        if not np.all(valid(cand[coarse])):
            return False
        rest = cand[~coarse]  # the coarse samples are known valid now
        return bool(len(rest) == 0 or np.all(valid(rest)))

    return check


def _as_configs(x: np.ndarray | list, d: int | None, name: str) -> np.ndarray:
    try:
        a = np.atleast_2d(np.asarray(x, dtype=float))
    except (TypeError, ValueError) as exc:
        raise InvalidInputError(f"{name} must be numeric joint vectors ({exc})") from exc
    if a.ndim != 2 or a.shape[0] == 0 or (d is not None and a.shape[1] != d):
        raise InvalidInputError(
            f"{name} must have shape (K, {d if d is not None else 'd'}) with K ≥ 1, got {a.shape}"
        )
    if not np.all(np.isfinite(a)):
        raise InvalidInputError(f"{name} has non-finite values")
    return a


def plan_motion(
    start: np.ndarray,
    goals: np.ndarray,
    valid: Valid,
    *,
    lower: np.ndarray,
    upper: np.ndarray,
    seed: int,
    motion_valid: MotionValid | None = None,
    resolution: float = 0.02,
    planner: str = "rrt_connect",
    range_: float | None = None,
    max_time_s: float = 10.0,
    max_iterations: int | None = None,
    simplify: bool = True,
    simplify_steps: int = 100,
    try_direct: bool = True,
    weights: np.ndarray | None = None,
    periodic: Sequence[int] = (),
) -> MotionResult:
    """A collision-free joint path from ``start`` (d,) to one of ``goals`` (G, d).

    ``valid`` decides configurations; ``motion_valid(a, b)`` straight
    segments (default :func:`segment_validator` at ``resolution``).
    ``periodic`` names the dimensions that are angles (OMPL SO2, see the
    module docstring): their ``lower``/``upper`` entries are ignored, start
    and goals may hold any angle (the path's ends are exactly them), the
    inner states lie in [-π, π).  With
    ``try_direct`` the straight segment to each goal is tried first.  The
    search stops after ``max_time_s`` or ``max_iterations`` planner
    iterations, whichever comes first; ``simplify_steps`` bounds OMPL's
    vertex reduction.  Raises :class:`InvalidInputError` on malformed input;
    an unsolvable or over-budget problem returns ``path=None``."""
    lo = _as_configs(lower, None, "lower")[0]
    d = lo.size
    hi = _as_configs(upper, d, "upper")[0]
    q0 = _as_configs(start, d, "start")
    if len(q0) != 1:
        raise InvalidInputError(f"start must be one configuration, got {len(q0)}")
    q0 = q0[0]
    G = _as_configs(goals, d, "goals")
    lin = np.ones(d, dtype=bool)
    lin[[int(i) for i in periodic if 0 <= int(i) < d]] = False
    if not np.all(hi[lin] > lo[lin]):
        raise InvalidInputError("upper must exceed lower in every joint")
    for name, Q in (("start", q0[None]), ("goals", G)):
        if np.any(lo[lin] - 1e-9 > Q[:, lin]) or np.any(hi[lin] + 1e-9 < Q[:, lin]):
            raise InvalidInputError(f"{name} outside the joint bounds [lower, upper]")
    if planner not in PLANNERS:
        raise InvalidInputError(f"planner must be one of {', '.join(PLANNERS)}, got {planner!r}")
    if not (max_time_s > 0 and np.isfinite(max_time_s)):
        raise InvalidInputError(f"max_time_s must be a positive number, got {max_time_s}")
    if max_iterations is not None and max_iterations < 1:
        raise InvalidInputError(f"max_iterations must be ≥ 1, got {max_iterations}")
    if not resolution > 0:
        raise InvalidInputError(f"resolution must be positive, got {resolution}")
    w = np.ones(d) if weights is None else _as_configs(weights, d, "weights")[0]
    if not np.all(w > 0):
        raise InvalidInputError("weights must be positive")
    per = sorted({int(i) for i in periodic})
    if any(i < 0 or i >= d for i in per) or len(per) != len(periodic):
        raise InvalidInputError(
            f"periodic must list distinct dimensions in 0..{d - 1}, got {list(periodic)}"
        )

    t0 = time.perf_counter()
    checks = 0

    def counted(Q: np.ndarray) -> np.ndarray:
        nonlocal checks
        checks += len(Q)
        return np.asarray(valid(Q), dtype=bool)

    seg = motion_valid or segment_validator(counted, resolution, per)

    def done(
        path: np.ndarray | None, status: str, its: int, gi: int = -1, nv: int = 0
    ) -> MotionResult:
        return MotionResult(path, status, checks, time.perf_counter() - t0, its, gi, nv)

    if not counted(q0[None])[0]:
        return done(None, "invalid_start", 0)
    goal_ok = counted(G)
    if not goal_ok.any():
        return done(None, "invalid_goal", 0)
    G = G[goal_ok]
    goal_ids = np.nonzero(goal_ok)[0]
    if try_direct:  # frequent for short moves, and cheaper than building a planner
        for k, g in enumerate(G):
            if seg(q0, g):
                return done(np.vstack([q0, g]), "exact", 0, int(goal_ids[k]))

    # --- OMPL problem in scaled coordinates y = w ⊙ q
    space, to_q, set_q = _state_space(lo, hi, w, per)
    si = ob.SpaceInformation(space)

    si.setStateValidityChecker(lambda s: bool(counted(to_q(s)[None])[0]))

    class _Motion(ob.MotionValidator):
        """The injected motion validator: the caller's segment check."""

        def checkMotion(self, s1: ob.State, s2: ob.State) -> bool:  # OMPL's name
            return bool(seg(to_q(s1), to_q(s2)))

    mv = _Motion(si)
    si.setMotionValidator(mv)
    si.setup()

    def state(q: np.ndarray) -> ob.State:
        s = si.allocState()
        set_q(s, q)
        return s

    # Re-seed OMPL's global seed generator so the planner's and simplifier's
    # RNGs (created below) are deterministic; silence its "already started"
    # note, which concerns RNGs created earlier (none we use).
    ou.noOutputHandler()
    ou.RNG.setSeed(int(seed) % (2**32 - 1) + 1)
    ou.restorePreviousOutputHandler()

    pdef = ob.ProblemDefinition(si)
    pdef.addStartState(state(q0))
    goal = ob.GoalStates(si)
    for g in G:
        goal.addState(state(g))
    pdef.setGoal(goal)
    pl = PLANNERS[planner](si)
    if range_ is not None and hasattr(pl, "setRange"):
        pl.setRange(float(range_))
    pl.setProblemDefinition(pdef)
    pl.setup()

    its = 0
    deadline = t0 + float(max_time_s)
    cap = int(max_iterations) if max_iterations is not None else None

    def stop() -> bool:
        # Evaluated once per planner iteration: the iteration budget is exact.
        nonlocal its
        its += 1
        return (cap is not None and its > cap) or time.perf_counter() > deadline

    st = pl.solve(ob.PlannerTerminationCondition(stop))
    its = min(its, cap) if cap is not None else its
    data = ob.PlannerData(si)
    pl.getPlannerData(data)
    nv = int(data.numVertices())
    if not pdef.hasExactSolution():
        name = str(st.getStatus()).split(".")[-1].lower()
        status = "timeout" if name in ("timeout", "approximate_solution") else name
        return done(None, status, its, nv=nv)
    path = pdef.getSolutionPath()
    if simplify:
        ps = og.PathSimplifier(si)
        ps.reduceVertices(path, int(simplify_steps))
        ps.collapseCloseVertices(path)
    P = np.array([to_q(s) for s in path.getStates()])
    # Exact ends: OMPL copies states, but undo the scaling round-off.
    diff = G - P[-1]
    diff[:, per] = wrap_angle(diff[:, per])
    gi = int(np.argmin(np.abs(diff).max(axis=1)))
    P[0], P[-1] = q0, G[gi]
    return done(P, "exact", its, int(goal_ids[gi]), nv)


def _state_space(
    lo: np.ndarray, hi: np.ndarray, w: np.ndarray, per: list[int]
) -> tuple[ob.StateSpace, Callable[[ob.State], np.ndarray], Callable[[ob.State, np.ndarray], None]]:
    """OMPL's state space for bounds ``lo``/``hi`` in scaled coordinates
    ``w ⊙ q``, and the conversions state → q and q → state.

    No ``per``: a ``RealVectorStateSpace``.  Else a ``CompoundStateSpace``:
    the real-vector part (the other dimensions, if any, weight 1) then one
    ``SO2StateSpace`` per periodic dimension, weighted by its ``w``."""
    d = len(lo)

    def bounded(idx: list[int]) -> ob.RealVectorStateSpace:
        space = ob.RealVectorStateSpace(len(idx))
        bounds = ob.RealVectorBounds(len(idx))
        bounds.low = (lo[idx] * w[idx]).tolist()
        bounds.high = (hi[idx] * w[idx]).tolist()
        space.setBounds(bounds)
        return space

    if not per:
        space = bounded(list(range(d)))

        def to_q(s: ob.State) -> np.ndarray:
            return np.asarray(s[0:d], dtype=float) / w

        def set_q(s: ob.State, q: np.ndarray) -> None:
            s[0:d] = (q * w).tolist()

        return space, to_q, set_q

    lin = [i for i in range(d) if i not in per]
    compound = ob.CompoundStateSpace()
    if lin:
        compound.addSubspace(bounded(lin), 1.0)
    for i in per:
        compound.addSubspace(ob.SO2StateSpace(), float(w[i]))
    k0 = 1 if lin else 0  # index of the first SO2 component
    n_lin = len(lin)

    def to_q_c(s: ob.State) -> np.ndarray:
        q = np.empty(d)
        if lin:
            q[lin] = np.asarray(s[0][0:n_lin], dtype=float) / w[lin]
        for k, i in enumerate(per):
            q[i] = s[k0 + k].value
        return q

    def set_q_c(s: ob.State, q: np.ndarray) -> None:
        if lin:
            s[0][0:n_lin] = (q[lin] * w[lin]).tolist()
        for k, i in enumerate(per):
            s[k0 + k].value = float(wrap_angle(q[i]))

    return compound, to_q_c, set_q_c
