"""Re-pairing a covering walk's passes through a joint so that its transitions
are ones the robot can make.

The route planner (:func:`planners.vocpp.plan_route`, seed 000 Alg. 5) picks
a walk that covers every span at least cost, blind to which member changes
are feasible (Eq. 3.1 per transition, :mod:`.transitions`).  A walk that
passes a vertex ``v`` twice, at positions ``i < j``, stays a walk from the
same start to the same end, over the same edges, when the part between them
is driven backwards: ``v … v`` reversed is again ``v … v``.  That changes
which edge-ends are paired at ``v`` (the transitions there) and the
direction of the transitions inside the part.  A local search over such
reversals (a 2-opt move on the walk) keeps one when it lowers the number of
infeasible transitions, then the number of jumps; length never changes.
Transitions are memoised by their geometry, so a candidate costs only the
transitions it has not seen yet.
"""

from __future__ import annotations

from collections.abc import Hashable
from dataclasses import replace
from typing import Any

from planners.inspection.transitions import Transition, TransitionContext, route_transitions
from planners.vocpp import Route

__all__ = ["repair_route", "transition_cost"]

#: Reversals tried at most per route (each one a transitions pass over the walk).
MAX_TRIES = 400


class _Memo:
    """``ctx.transition`` memoised on everything but the route position."""

    def __init__(self, ctx: TransitionContext) -> None:
        self.ctx = ctx
        self.seen: dict[tuple[Any, ...], Transition] = {}

    def __getattr__(self, name: str) -> Any:
        return getattr(self.ctx, name)

    def transition(
        self,
        route: int,
        index: int,
        v: Hashable,
        landing: Hashable,
        kind: str,
        a: int | None,
        b: int,
    ) -> Transition:
        key = (v, landing, kind, a, b)
        got = self.seen.get(key)
        if got is None:
            got = self.seen[key] = self.ctx.transition(route, index, v, landing, kind, a, b)
        return replace(got, route=route, index_in_route=index)


def transition_cost(transitions: list[Transition]) -> tuple[int, int]:
    bad = sum(not t.feasible for t in transitions)
    return bad, sum(t.mode == "inchworm" for t in transitions)


def _reversed(route: Route, i: int, j: int) -> Route:
    """``route`` with its part between vertex positions ``i`` and ``j`` driven backwards."""
    verts = route.vertices[:i] + route.vertices[i : j + 1][::-1] + route.vertices[j + 1 :]
    part = [(v, u, k) for u, v, k in reversed(route.edges[i:j])]
    return replace(route, vertices=verts, edges=route.edges[:i] + part + route.edges[j:])


def repair_route(
    ctx: TransitionContext, route: Route, route_index: int
) -> tuple[Route, list[Transition]]:
    """``route`` with passes re-paired (see the module doc) while that lowers
    (infeasible transitions, jumps), and its transitions.  First improvement,
    reversals at a failing transition's vertex tried first, at most
    :data:`MAX_TRIES` in all; deterministic (positions in order)."""
    memo = _Memo(ctx)
    trans = route_transitions(memo, route, route_index)  # type: ignore[arg-type]
    best = transition_cost(trans)
    tries = 0
    improved = True
    while improved and best[0] > 0 and tries < MAX_TRIES:
        improved = False
        visits: dict[Hashable, list[int]] = {}
        for pos, v in enumerate(route.vertices):
            visits.setdefault(v, []).append(pos)
        # Where a transition fails: the other passes through its vertex first;
        # then every other pair of passes (a reversed part flips the direction
        # of the member changes inside it, which can make them feasible).
        anchored = [
            (min(t.index_in_route, o), max(t.index_in_route, o))
            for t in trans
            if not t.feasible
            for o in visits.get(route.vertices[t.index_in_route], [])
            if o != t.index_in_route
        ]
        rest = [(i, j) for pos in visits.values() for n, i in enumerate(pos) for j in pos[n + 1 :]]
        for i, j in dict.fromkeys(anchored + rest):
            if tries >= MAX_TRIES:
                break
            tries += 1
            cand = _reversed(route, i, j)
            got = route_transitions(memo, cand, route_index)  # type: ignore[arg-type]
            cost = transition_cost(got)
            if cost < best:
                route, trans, best, improved = cand, got, cost, True
                break
    return route, trans
