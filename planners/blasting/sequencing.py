"""Sequencing of blasting spots (seed §3.3).

Objective (Eq. 3.3–3.4, 3.15): for a path p₁…p_N the cost is
``Σ (dᵢ + c·hitᵢ)(2 − cos θᵢ)`` where ``dᵢ = |pᵢ₊₁ − pᵢ|``, θᵢ is the heading
change at pᵢ (θ₁ = 0: the first move has no previous heading) and ``hitᵢ``
marks a move the collision check flagged (penalty ``c``, Eq. 3.15).

* :func:`sequence_ga` — the seed's genetic algorithm (§3.3.2, Table 4.1):
  integer (permutation) chromosomes, duplicates repaired by random
  replacement with the missing discs, rank-scaled roulette selection,
  one-point crossover with probability 0.9, single-gene mutation with
  probability 0.1, at most 300 generations, stop after 10 without
  improvement.  Part of the initial population comes from the greedy
  neighbour rule of §3.3.1 (the seed's "modified initialisation").
* :func:`sequence_default` — ours: serpentine rows over the hexagonal
  lattice in several directions, then 2-opt and Or-opt local search on the
  same objective with the turn term (moves restricted to near neighbours,
  evaluated in closed form, vectorised).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import minimum_spanning_tree
from scipy.spatial import Delaunay, QhullError, cKDTree
from scipy.spatial.distance import pdist, squareform

from planners.errors import InvalidInputError

TURN_THRESHOLD_DEG = 10.0  # a heading change above this counts as a turn (Table 4.2 style)


@dataclass
class SequenceStats:
    """Table 4.2-style figures of one order."""

    objective: float
    distance_m: float
    turns: int
    lower_bound_m: float  # (N − 1) × disc spacing (issue 5's reference)
    mst_m: float  # minimum spanning tree length: a true lower bound on the distance

    @property
    def ratio_to_lower_bound(self) -> float:
        return self.distance_m / self.lower_bound_m if self.lower_bound_m > 0 else 1.0


# -- objective ------------------------------------------------------------------
def _penalty_of(pen: np.ndarray | None, a: np.ndarray, b: np.ndarray) -> np.ndarray | float:
    return 0.0 if pen is None else pen[a, b]


def path_cost(
    points: np.ndarray,
    order: np.ndarray,
    penalty: np.ndarray | None = None,
    c: float = 0.0,
    turn_weight: float = 1.0,
) -> np.ndarray:
    """Objective of Eq. 3.4 (+ Eq. 3.15) for one order (N,) or a population
    (P,N); ``penalty`` is an (N,N) 0/1 matrix of flagged moves.
    ``turn_weight`` w gives d(1 + w(1 − cos θ)): w = 1 is Eq. 3.4, w = 0 the
    distance-only objective of Table 4.2's first row."""
    order = np.asarray(order)
    single = order.ndim == 1
    ords = order.reshape(-1, order.shape[-1])
    X = points[ords]  # (P,N,D)
    seg = np.diff(X, axis=1)
    d = np.linalg.norm(seg, axis=2)
    d_eff = d + c * penalty[ords[:, :-1], ords[:, 1:]] if penalty is not None and c else d
    f = np.ones_like(d)
    if d.shape[1] > 1:
        num = np.einsum("pkd,pkd->pk", seg[:, :-1], seg[:, 1:])
        den = d[:, :-1] * d[:, 1:]
        cos = np.where(den > 1e-15, num / np.where(den > 1e-15, den, 1.0), 1.0)
        f[:, 1:] = 1.0 + turn_weight * (1.0 - cos)
    cost = (d_eff * f).sum(axis=1)
    return cost[0] if single else cost


def count_turns(
    points: np.ndarray, order: np.ndarray, threshold_deg: float = TURN_THRESHOLD_DEG
) -> int:
    """Heading changes above ``threshold_deg`` along the path."""
    X = points[np.asarray(order)]
    seg = np.diff(X, axis=0)
    d = np.linalg.norm(seg, axis=1)
    seg, d = seg[d > 1e-12], d[d > 1e-12]
    if len(seg) < 2:
        return 0
    cos = np.einsum("kd,kd->k", seg[:-1], seg[1:]) / (d[:-1] * d[1:])
    return int(np.count_nonzero(cos < np.cos(np.deg2rad(threshold_deg))))


#: above this many points the spanning tree is taken on the Delaunay edges
MST_DENSE_MAX = 1500


def mst_length(points: np.ndarray) -> float:
    """Length of the Euclidean minimum spanning tree (coincident points joined
    by 1e-12 m edges).  Up to :data:`MST_DENSE_MAX` points on the complete
    graph; above, on the Delaunay edges of the distinct points (the Euclidean
    MST is a subgraph of the Delaunay triangulation), falling back to the
    complete graph when Qhull drops or cannot triangulate points — O(N log N)
    instead of O(N²) time and memory."""
    points = np.asarray(points, dtype=float)
    n = len(points)
    if n < 2:
        return 0.0
    if n > MST_DENSE_MAX:
        uniq = np.unique(points, axis=0)
        try:
            tri = Delaunay(uniq)
        except QhullError:
            tri = None
        if tri is not None and len(tri.coplanar) == 0:
            s = tri.simplices
            e = np.concatenate([s[:, [0, 1]], s[:, [1, 2]], s[:, [0, 2]]])
            e = np.unique(np.sort(e, axis=1), axis=0)
            w = np.linalg.norm(uniq[e[:, 0]] - uniq[e[:, 1]], axis=1)
            G = coo_matrix((w, (e[:, 0], e[:, 1])), shape=(len(uniq), len(uniq)))
            return float(minimum_spanning_tree(G).sum()) + (n - len(uniq)) * 1e-12
    D = squareform(pdist(points))
    D[D == 0] = 1e-12  # coincident spots still need an edge
    np.fill_diagonal(D, 0.0)
    return float(minimum_spanning_tree(D).sum())


def stats(
    points: np.ndarray,
    order: np.ndarray,
    spacing: float,
    penalty: np.ndarray | None = None,
    c: float = 0.0,
    turn_weight: float = 1.0,
) -> SequenceStats:
    """Objective, distance, turns and the two reference lengths."""
    X = points[np.asarray(order)]
    dist = float(np.linalg.norm(np.diff(X, axis=0), axis=1).sum())
    n = len(points)
    mst = mst_length(points)
    return SequenceStats(
        objective=float(path_cost(points, order, penalty, c, turn_weight)),
        distance_m=dist,
        turns=count_turns(points, order),
        lower_bound_m=(n - 1) * spacing,
        mst_m=mst,
    )


def brute_force(
    points: np.ndarray, penalty: np.ndarray | None = None, c: float = 0.0, turn_weight: float = 1.0
) -> tuple[np.ndarray, float]:
    """Exact optimum by enumerating all orders (for ≤ 9 spots; tests)."""
    n = len(points)
    if n > 9:
        raise InvalidInputError(f"brute force is for at most 9 spots, got {n}")
    perms = np.array(list(itertools.permutations(range(n))))
    costs = path_cost(points, perms, penalty, c, turn_weight)
    k = int(np.argmin(costs))
    return perms[k], float(costs[k])


# -- greedy (§3.3.1) ---------------------------------------------------------------
def greedy_order(
    points: np.ndarray,
    start: int,
    penalty: np.ndarray | None = None,
    c: float = 0.0,
    candidates: int = 6,
    turn_weight: float = 1.0,
) -> np.ndarray:
    """The seed's greedy rule (§3.3.1): from the current spot go to the one of
    the ``candidates`` nearest unvisited spots with the least d(2 − cos θ)."""
    n = len(points)
    visited = np.zeros(n, dtype=bool)
    order = [start]
    visited[start] = True
    heading = None
    cur = start
    for _ in range(n - 1):
        rest = np.nonzero(~visited)[0]
        v = points[rest] - points[cur]
        d = np.linalg.norm(v, axis=1)
        near = np.argsort(d, kind="stable")[:candidates]
        dn = d[near]
        cost = dn + (c * penalty[cur, rest[near]] if penalty is not None else 0.0)
        if heading is not None:
            cos = (v[near] @ heading) / np.maximum(dn, 1e-15)
            cost = cost * (1.0 + turn_weight * (1.0 - cos))
        k = rest[near[int(np.argmin(cost))]]
        step = points[k] - points[cur]
        if np.linalg.norm(step) > 1e-15:
            heading = step / np.linalg.norm(step)
        order.append(k)
        visited[k] = True
        cur = k
    return np.asarray(order)


# -- the seed's GA (§3.3.2) -----------------------------------------------------------
@dataclass
class GAResult:
    order: np.ndarray
    cost: float
    generations: int
    history: np.ndarray  # best cost per generation


def _repair(child: np.ndarray, n: int, rng: np.random.Generator) -> np.ndarray:
    """Replace repeated discs by the missing ones, at random (§3.3.2 step 1)."""
    seen = np.zeros(n, dtype=bool)
    dup = np.zeros(len(child), dtype=bool)
    # first occurrence kept, later repeats marked (vectorised via unique)
    _, first = np.unique(child, return_index=True)
    dup[:] = True
    dup[first] = False
    if dup.any():
        seen[child[~dup]] = True
        missing = np.nonzero(~seen)[0]
        child = child.copy()
        child[dup] = rng.permutation(missing)
    return child


def sequence_ga(
    points: np.ndarray,
    *,
    penalty: np.ndarray | None = None,
    c: float = 0.0,
    population: int | None = None,
    crossover: float = 0.9,
    mutation: float = 0.1,
    max_generations: int = 300,
    patience: int = 10,
    greedy_share: float = 0.2,
    turn_weight: float = 1.0,
    seed: int = 0,
) -> GAResult:
    """The seed's GA (§3.3.2, Table 4.1).  Population size is not given in
    the seed: ``clip(N, 40, 120)``; one elite survives each generation so that
    "no improvement for 10 generations" refers to a best that cannot be lost."""
    rng = np.random.default_rng(seed)
    n = len(points)
    if n <= 2:
        order = np.arange(n)
        return GAResult(
            order,
            float(path_cost(points, order, penalty, c, turn_weight)) if n else 0.0,
            0,
            np.zeros(0),
        )
    P = population or int(np.clip(n, 40, 120))
    pop = np.stack([rng.permutation(n) for _ in range(P)])
    n_greedy = round(greedy_share * P)
    for k, s in enumerate(rng.choice(n, size=min(n_greedy, n), replace=False)):
        pop[k] = greedy_order(points, int(s), penalty, c, turn_weight=turn_weight)
    cost = path_cost(points, pop, penalty, c, turn_weight)
    best_i = int(np.argmin(cost))
    best, best_cost = pop[best_i].copy(), float(cost[best_i])
    history = [best_cost]
    stale = 0
    generations = 0
    rank_w = np.arange(P, 0, -1, dtype=float)
    rank_w /= rank_w.sum()
    for _ in range(max_generations):
        generations += 1
        # roulette on rank-scaled fitness (sorted ascending, minimum preferred)
        ranked = np.argsort(cost, kind="stable")
        parents = pop[ranked[rng.choice(P, size=P, p=rank_w)]]
        children = parents.copy()
        for k in range(0, P - 1, 2):
            if rng.random() < crossover:
                cut = int(rng.integers(1, n))
                a, b = parents[k], parents[k + 1]
                children[k] = _repair(np.concatenate([a[:cut], b[cut:]]), n, rng)
                children[k + 1] = _repair(np.concatenate([b[:cut], a[cut:]]), n, rng)
        # mutation: one gene takes a random disc; the repeat is repaired by
        # giving its old place the gene's former disc (a swap)
        mut = np.nonzero(rng.random(P) < mutation)[0]
        for k in mut.tolist():
            i = int(rng.integers(n))
            v = int(rng.integers(n))
            j = int(np.nonzero(children[k] == v)[0][0])
            children[k, i], children[k, j] = v, children[k, i]
        children[0] = best  # elitism
        pop = children
        cost = path_cost(points, pop, penalty, c, turn_weight)
        i = int(np.argmin(cost))
        if cost[i] < best_cost - 1e-12:
            best, best_cost = pop[i].copy(), float(cost[i])
            stale = 0
        else:
            stale += 1
        history.append(best_cost)
        if stale >= patience:
            break
    return GAResult(best, best_cost, generations, np.asarray(history))


# -- default: serpentine + local search ---------------------------------------------------
def serpentine(points: np.ndarray, angle: float, row_pitch: float) -> np.ndarray:
    """Boustrophedon order: rows along ``angle`` at ``row_pitch`` apart,
    alternate rows reversed."""
    u = np.array([np.cos(angle), np.sin(angle)])
    v = np.array([-np.sin(angle), np.cos(angle)])
    along = points[:, :2] @ u
    across = points[:, :2] @ v
    row = np.round((across - across.min()) / row_pitch).astype(int)
    key = np.where(row % 2 == 0, along, -along)
    return np.lexsort((key, row))


class _LocalSearch:
    """2-opt and Or-opt on the open-path objective.  The cost is written as a
    sum over vertices of g(prev, v, next) = (d(v,next) + c·hit)(2 − cos θ_v)
    (first vertex: factor 1; last: 0), so a move's delta only involves the
    vertices whose neighbours change; a 2-opt reversal also swaps prev/next of
    the reversed inner vertices, summed with prefix sums."""

    def __init__(
        self,
        points: np.ndarray,
        penalty: np.ndarray | None,
        c: float,
        k: int,
        turn_weight: float = 1.0,
    ) -> None:
        self.w = turn_weight
        self.X = np.asarray(points, dtype=float)
        self.x = np.ascontiguousarray(self.X[:, 0])
        self.y = np.ascontiguousarray(self.X[:, 1])
        self.pen = penalty if (penalty is not None and c) else None
        self.c = c
        n = len(points)
        kk = min(k + 1, n)
        self.nbr = np.asarray(cKDTree(self.X).query(self.X, k=kk)[1])[:, 1:]  # (n,k)

    def g(self, a: np.ndarray, v: np.ndarray, b: np.ndarray) -> np.ndarray:
        """Per-vertex cost; a or b = −1 means none."""
        x, y = self.x, self.y
        has_a = a >= 0
        has_b = b >= 0
        aa = np.where(has_a, a, v)
        bb = np.where(has_b, b, v)
        xv, yv = x.take(v), y.take(v)  # gathered once (the hot path of the search)
        ox, oy = x.take(bb) - xv, y.take(bb) - yv
        ix, iy = xv - x.take(aa), yv - y.take(aa)
        dout = np.hypot(ox, oy)
        den = np.hypot(ix, iy) * dout
        ok = den > 1e-15
        cos = np.where(ok, (ix * ox + iy * oy) / np.where(ok, den, 1.0), 1.0)
        if self.pen is not None:
            dout = dout + self.c * self.pen[v, bb]
        return np.where(has_b, dout * (1.0 + self.w * (1.0 - cos)), 0.0)

    def run(self, order: np.ndarray, max_rounds: int = 10_000) -> np.ndarray:
        order = np.asarray(order).copy()
        n = len(order)
        if n < 4:
            return order
        for _ in range(max_rounds):
            pos = np.empty(n, dtype=np.int64)
            pos[order] = np.arange(n)
            cur = self._current(order)  # shared by both neighbourhoods
            moves = self._two_opt(order, pos, cur) + self._or_opt(order, pos, cur)
            if not moves:
                break
            moves.sort(key=lambda m: m[0])
            used = np.zeros(n + 2, dtype=bool)
            applied = 0
            for delta, lo, hi, fn in moves:
                if delta > -1e-12:
                    break
                if used[lo : hi + 1].any():
                    continue
                used[lo : hi + 1] = True
                order = fn(order)
                applied += 1
            if applied == 0:
                break
        return order

    def _prev_next(self, order: np.ndarray, i: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        n = len(order)
        prv = np.where(i > 0, order[np.maximum(i - 1, 0)], -1)
        nxt = np.where(i < n - 1, order[np.minimum(i + 1, n - 1)], -1)
        return prv, nxt

    def _current(self, order: np.ndarray) -> np.ndarray:
        """g of the vertex at each position with its current neighbours."""
        prv, nxt = self._prev_next(order, np.arange(len(order)))
        return self.g(prv, order, nxt)

    def _two_opt(self, order: np.ndarray, pos: np.ndarray, cur: np.ndarray | None = None) -> list:
        """Reverse order[i..j] (0 ≤ i < j ≤ n−1) where order[j] is a near
        neighbour of order[i−1] or order[j+1] of order[i].  ``cur``: g of
        the vertex at each position (the moves' old terms are gathered from
        it instead of evaluated per move)."""
        n = len(order)
        idx = np.arange(n)
        prv, nxt = self._prev_next(order, idx)
        if cur is None:
            cur = self._current(order)
        # inner swap gain prefix: s[v] = g(next, v, prev) − g(prev, v, next)
        swap = self.g(nxt, order, prv) - cur
        S = np.concatenate([[0.0], np.cumsum(swap)])
        cand_i, cand_j = [], []
        # new edge (order[i-1], order[j]): i = pos[a]+1, j = pos[nbr of a]
        a_pos = np.repeat(idx, self.nbr.shape[1])
        b_pos = pos[self.nbr[order].reshape(-1)]
        cand_i.append(a_pos + 1)
        cand_j.append(b_pos)
        # new edge (order[i], order[j+1]): j = pos[a]-1, i = pos[nbr]
        cand_i.append(b_pos)
        cand_j.append(a_pos - 1)
        i = np.concatenate(cand_i)
        j = np.concatenate(cand_j)
        ok = (i >= 0) & (j <= n - 1) & (j - i >= 1)
        i, j = i[ok], j[ok]
        if len(i) == 0:
            return []
        p_i, p_j = order[i], order[j]
        a = np.where(i > 0, order[np.maximum(i - 1, 0)], -1)
        aa = np.where(i > 1, order[np.maximum(i - 2, 0)], -1)
        b = np.where(j < n - 1, order[np.minimum(j + 1, n - 1)], -1)
        bb = np.where(j < n - 2, order[np.minimum(j + 2, n - 1)], -1)
        in_i = order[np.minimum(i + 1, n - 1)]  # neighbour of p_i inside the block
        in_j = order[np.maximum(j - 1, 0)]
        # the vertices at i−1, i, j, j+1 keep their current neighbours
        old = (
            np.where(a >= 0, cur[np.maximum(i - 1, 0)], 0.0)
            + cur[i]
            + cur[j]
            + np.where(b >= 0, cur[np.minimum(j + 1, n - 1)], 0.0)
        )
        new = (
            np.where(a >= 0, self.g(aa, np.maximum(a, 0), p_j), 0.0)
            + self.g(a, p_j, in_j)
            + self.g(in_i, p_i, b)
            + np.where(b >= 0, self.g(p_i, np.maximum(b, 0), bb), 0.0)
        )
        inner = S[j] - S[i + 1]  # vertices i+1 … j-1
        delta = new - old + inner
        good = np.nonzero(delta < -1e-12)[0]
        moves = []
        for k in good[np.argsort(delta[good])][:64]:
            ii, jj = int(i[k]), int(j[k])

            def fn(o: np.ndarray, ii: int = ii, jj: int = jj) -> np.ndarray:
                o = o.copy()
                o[ii : jj + 1] = o[ii : jj + 1][::-1]
                return o

            moves.append((float(delta[k]), max(ii - 2, 0), jj + 2, fn))
        return moves

    def _or_opt(self, order: np.ndarray, pos: np.ndarray, cur: np.ndarray | None = None) -> list:
        """Move order[i..i+L-1] (L = 1..3) between order[k] and order[k+1]
        (k = −1 puts it first), optionally reversed; k near a segment end.
        ``cur`` as in :meth:`_two_opt`."""
        n = len(order)
        if cur is None:
            cur = self._current(order)
        moves = []
        for L in (1, 2, 3):
            if n < L + 2:
                break
            i = np.arange(0, n - L + 1)
            first, last = order[i], order[i + L - 1]
            # terms that depend on the segment only, once per segment (the
            # moves below gather them): removal joins a–b; L = 3 reversed
            # swaps the middle vertex's neighbours
            Zi = lambda m, v: np.where(m >= 0, v, 0.0)  # noqa: E731
            a_i = np.where(i > 0, order[np.maximum(i - 1, 0)], -1)
            aa_i = np.where(i > 1, order[np.maximum(i - 2, 0)], -1)
            b_i = np.where(n > i + L, order[np.minimum(i + L, n - 1)], -1)
            bb_i = np.where(n > i + L + 1, order[np.minimum(i + L + 1, n - 1)], -1)
            new_ab_i = Zi(a_i, self.g(aa_i, np.maximum(a_i, 0), b_i)) + Zi(
                b_i, self.g(a_i, np.maximum(b_i, 0), bb_i)
            )
            if L == 3:
                mid_i = order[np.minimum(i + 1, n - 1)]
                mid_rev_i = self.g(last, mid_i, first)
                mid_fwd_i = self.g(first, mid_i, last)
            # insertion after a neighbour of first/last, or before one
            ko = min(self.nbr.shape[1], 5)
            nb = np.concatenate([self.nbr[first, :ko], self.nbr[last, :ko]], axis=1)
            kpos = pos[nb]
            kk = np.concatenate([kpos, kpos - 1], axis=1)
            Ix = np.repeat(i, kk.shape[1])
            K = kk.reshape(-1)
            ok = (K >= -1) & (n - 1 >= K) & ((Ix - 1 > K) | (Ix + L - 1 < K))
            Ix, K = Ix[ok], K[ok]
            if len(Ix) == 0:
                continue
            s0, s1 = order[Ix], order[Ix + L - 1]
            a = np.where(Ix > 0, order[np.maximum(Ix - 1, 0)], -1)
            b = np.where(n > Ix + L, order[np.minimum(Ix + L, n - 1)], -1)
            x = np.where(K >= 0, order[np.maximum(K, 0)], -1)
            xp = np.where(K >= 1, order[np.maximum(K - 1, 0)], -1)
            y = np.where(n > K + 1, order[np.minimum(K + 1, n - 1)], -1)
            yn = np.where(n > K + 2, order[np.minimum(K + 2, n - 1)], -1)
            s0n = order[np.minimum(Ix + 1, n - 1)] if L > 1 else b  # inner neighbour of s0
            s1p = order[np.maximum(Ix + L - 2, 0)] if L > 1 else a
            # When the segment sits right after y… the neighbours overlap; the
            # windows below are disjoint because K is outside [Ix-1, Ix+L-1].
            Z = lambda m, v: np.where(m >= 0, v, 0.0)  # noqa: E731
            # old terms: the vertices at Ix−1, Ix+L, K, K+1 and the segment's
            # ends with their current neighbours (gathered from cur)
            old_common = Z(a, cur[np.maximum(Ix - 1, 0)]) + Z(b, cur[np.minimum(Ix + L, n - 1)])
            old_common += Z(x, cur[np.maximum(K, 0)]) + Z(y, cur[np.minimum(K + 1, n - 1)])
            old_seg = cur[Ix] + (cur[Ix + L - 1] if L > 1 else 0.0)
            new_ab = new_ab_i[Ix]
            # overlap fix: if x == a (K == Ix−1) excluded; if y == a (K == Ix−2) the
            # removal changes a's prev/next and the insertion too: skip those.
            clash = (Ix - 2 == K) | (Ix + L == K)
            for rev in (False, True):
                h0, h1 = (s1, s0) if rev else (s0, s1)
                if L == 1:
                    seg_new = self.g(x, h0, y)
                else:  # the inner neighbours of the (reversed) segment's ends
                    h0n, h1p = (s1p, s0n) if rev else (s0n, s1p)
                    seg_new = self.g(x, h0, h0n) + self.g(h1p, h1, y)
                if L == 3 and rev:
                    seg_new = seg_new + mid_rev_i[Ix] - mid_fwd_i[Ix]
                ins = Z(x, self.g(xp, np.maximum(x, 0), h0)) + Z(
                    y, self.g(h1, np.maximum(y, 0), yn)
                )
                delta = (new_ab + ins + seg_new) - (old_common + old_seg)
                delta = np.where(clash, np.inf, delta)
                good = np.nonzero(delta < -1e-12)[0]
                for m in good[np.argsort(delta[good])][:32]:
                    ii, kk2 = int(Ix[m]), int(K[m])

                    def fn(
                        o: np.ndarray, ii: int = ii, kk2: int = kk2, L: int = L, rev: bool = rev
                    ) -> np.ndarray:
                        seg = o[ii : ii + L]
                        if rev:
                            seg = seg[::-1]
                        rest = np.concatenate([o[:ii], o[ii + L :]])
                        at = kk2 + 1 if kk2 < ii else kk2 + 1 - L
                        return np.concatenate([rest[:at], seg, rest[at:]])

                    lo = min(ii - 2, kk2 - 1)
                    hi = max(ii + L + 1, kk2 + 2)
                    moves.append((float(delta[m]), max(lo, 0), hi, fn))
        return moves


def sequence_default(
    points: np.ndarray,
    *,
    row_pitch: float,
    angles: tuple[float, ...] | None = None,
    penalty: np.ndarray | None = None,
    c: float = 0.0,
    neighbours: int = 8,
    polish: int | None = None,
    turn_weight: float = 1.0,
    kicks: int | None = None,
    seed: int = 0,
) -> np.ndarray:
    """Ours: serpentines over several row directions (the lattice directions
    0°, 60°, 120° from ``angles[0]`` and the principal axes) and, for ≤ 300
    spots, greedy tours from the extreme spots, each improved by 2-opt +
    Or-opt on the Eq. 3.4 objective; the cheapest is then kicked
    (double bridge) and re-polished a few times (iterated local search,
    ``seed`` fixes the kicks)."""
    X = np.asarray(points, dtype=float)
    n = len(X)
    if n <= 2:
        return np.arange(n)
    P2 = X[:, :2]
    base = 0.0 if angles is None else angles[0]
    dirs = [base, base + np.pi / 3, base + 2 * np.pi / 3]
    cov = np.cov((P2 - P2.mean(axis=0)).T)
    _w, V = np.linalg.eigh(cov)
    pa = float(np.arctan2(V[1, -1], V[0, -1]))
    dirs += [pa, pa + np.pi / 2]
    if angles is not None:
        dirs += list(angles[1:])
    ls = _LocalSearch(P2, penalty, c, neighbours, turn_weight)
    # rank the raw serpentines and polish the best few (polishing dominates
    # the time, so fewer for many spots); small sets also polish greedy
    # tours (§3.3.1 rule) started at the extreme spots
    raw = [serpentine(P2, a, row_pitch) for a in dirs]
    if n <= 300:
        ends = {
            int(np.argmin(P2[:, 0])),
            int(np.argmax(P2[:, 0])),
            int(np.argmin(P2[:, 1])),
            int(np.argmax(P2[:, 1])),
        }
        raw += [greedy_order(P2, e, penalty, c, turn_weight=turn_weight) for e in sorted(ends)]
    raw_cost = [float(path_cost(P2, o, penalty, c, turn_weight)) for o in raw]
    best, best_cost = None, np.inf
    k_polish = polish if polish else (3 if n <= 300 else 1)
    for k in np.argsort(raw_cost)[:k_polish]:
        o = ls.run(raw[k])
        cst = float(path_cost(P2, o, penalty, c, turn_weight))
        if cst < best_cost:
            best, best_cost = o, cst
    # every polished order has a finite cost, so the first one is taken
    assert best is not None
    # iterated local search on small sets (≤ 100 spots): double-bridge kicks
    # (A B C D → A C B D) followed by local search, kept when better
    rng = np.random.default_rng(seed)
    n_kicks = kicks if kicks is not None else (int(np.clip(600 // n, 0, 30)) if n <= 100 else 0)
    for _ in range(n_kicks):
        i, j, k = np.sort(rng.choice(np.arange(1, n), size=3, replace=False))
        cand = np.concatenate([best[:i], best[j:k], best[i:j], best[k:]])
        cand = ls.run(cand)
        cst = float(path_cost(P2, cand, penalty, c, turn_weight))
        if cst < best_cost - 1e-12:
            best, best_cost = cand, cst
    return best
