"""VOCPP benchmark (run on demand: ``.venv/bin/python tests/benchmarks/bench_vocpp.py``).

Prints, all measured in this run:

1. ``plan_route`` on a ≥ 50,000-edge truss graph (float metre weights), open and closed,
   with the time per stage;
2. exact ``plan_route`` vs the networkx metric-closure baseline (Dijkstra from every odd
   vertex + ``nx.min_weight_matching`` on the complete graph + ``nx.eulerian_path``) on the
   same instance with exactly 200 and 400 odd vertices: times, ratio, agreement;
3. every CARP instance in ``../shared/data/carp`` and the postman CSVs: the exact optimum,
   agreement with the baseline, the seed's Algorithm 5 (``method="thesis"``) and how often
   and by how much the exact route is shorter;
4. ``plan_route`` on 200,000-edge truss graphs over several seeds, before (the
   former single-call solver ``tests/vocpp/_reference_tjoin.py`` patched in) and after,
   interleaved in the same run, with stage times; then the T-join alone at several
   power-of-two grids ``2^-p`` on the same instance (does the weight scale drive the
   decode time?).  ``--200k-only`` runs just this section; ``--seeds 1,2,3`` picks seeds.
"""

from __future__ import annotations

import itertools
import math
import statistics
import sys
import time
from collections import defaultdict
from collections.abc import Callable
from pathlib import Path
from unittest import mock

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

import networkx as nx  # noqa: E402
import numpy as np  # noqa: E402

from planners.postman.graph_arrays import edge_arrays, simple_edges  # noqa: E402
from planners.postman.tjoin import _pymatching_tjoin, min_t_join  # noqa: E402
from planners.vocpp import Route, plan_route  # noqa: E402
from tests.vocpp import _reference_tjoin  # noqa: E402
from tests.vocpp.checks import assert_valid_route  # noqa: E402
from tests.vocpp.generators import truss_graph, with_odd_count  # noqa: E402
from tests.vocpp.instances import (  # noqa: E402
    DATA,
    carp_paths,
    read_carp,
    read_postman_edgelist,
)
from tests.vocpp.reference import metric_closure_matching, terminals, total_weight  # noqa: E402


def timed(fn: Callable[[], object]) -> tuple[object, float]:
    t0 = time.perf_counter()
    out = fn()
    return out, time.perf_counter() - t0


def networkx_route(g: nx.Graph, s, t, weight: str = "weight") -> tuple[float, list]:
    """The baseline: metric closure of T, networkx blossom matching, networkx Euler path."""
    cost, _pairs, paths = metric_closure_matching(g, terminals(g, s, t), weight)
    h = nx.MultiGraph(g)
    for path in paths.values():
        for a, b in itertools.pairwise(path):
            # Duplicate the cheapest parallel edge a-b (the one Dijkstra used).
            data = g[a][b].values() if g.is_multigraph() else [g[a][b]]
            h.add_edge(a, b, **{weight: min(d[weight] for d in data)})
    if s == t:
        walk = list(nx.eulerian_circuit(h, source=s, keys=True))
    else:
        walk = list(nx.eulerian_path(h, source=s, keys=True))
    return total_weight(g, weight) + cost, walk


def section_50k() -> None:
    print("== 1. 50,000-edge truss graph (float metre weights) ==")
    g, t_gen = timed(lambda: truss_graph(100, 176, seed=1))
    n_odd = sum(1 for _, d in g.degree() if d % 2)
    print(
        f"truss 100x176: {g.number_of_nodes()} vertices, {g.number_of_edges()} edges, "
        f"{n_odd} odd vertices (generated in {t_gen:.2f} s)"
    )
    assert g.number_of_edges() >= 50_000
    for label, s, t in [
        ("open  (0,0)->(99,175)", (0, 0), (99, 175)),
        ("closed (0,0)", (0, 0), (0, 0)),
    ]:
        times, stages = [], []
        route: Route | None = None
        for _ in range(3):
            marks: list[tuple[str, float]] = []
            t0 = time.perf_counter()
            route = plan_route(
                g, s, t, progress=lambda f, st, m=marks: m.append((st, time.perf_counter()))
            )
            times.append(time.perf_counter() - t0)
            prev, parts = t0, []
            for st, tm in marks:
                parts.append(f"{st} {tm - prev:.3f}")
                prev = tm
            stages.append(", ".join(parts))
        assert route is not None
        assert_valid_route(g, route, s, t)  # walk, coverage and lengths (raises if wrong)
        print(
            f"{label}: {times[0]:.3f} s first, median of 3 {statistics.median(times):.3f} s "
            f"(walk checked); |T| = {len(terminals(g, s, t))}; "
            f"length {route.length:.3f} m = lower bound {route.lower_bound:.3f} + deadhead "
            f"{route.deadhead:.3f}; {len(route.added_edges)} repeated edges; weights "
            f"'{route.weight_scaling}', certified gap <= {route.optimality_gap:.2e} m"
        )
        print(f"    stages (last run, s): {stages[-1]}")


def _mm(g: nx.Graph) -> nx.Graph:
    """Weights rounded to millimetres (decimal 1e-3: the exact integer path of plan_route)."""
    g = g.copy()
    for *_, d in g.edges(data=True):
        d["weight"] = round(d["weight"], 3)
    return g


def section_baseline() -> None:
    print("\n== 2. exact vs networkx metric-closure baseline (same instance, same run) ==")
    base = truss_graph(20, 60, seed=7, drop=0.2)
    for k, kind in [(200, "mm"), (400, "mm"), (200, "float")]:
        g = with_odd_count(base, k, seed=k)
        if kind == "mm":
            g = _mm(g)
        s = next(v for v, d in g.degree() if d % 2 == 0)
        assert len(terminals(g, s, s)) == k
        ours_times = []
        for _ in range(5):
            route, dt = timed(lambda g=g, s=s: plan_route(g, s, s))
            ours_times.append(dt)
        (ref_len, walk), t_ref = timed(lambda g=g, s=s: networkx_route(g, s, s))
        ours = statistics.median(ours_times)
        agree = abs(route.length - ref_len) <= (route.optimality_gap or 0.0) + 1e-9 * ref_len
        print(
            f"{k} odd vertices ({kind} weights, {g.number_of_nodes()} vertices, "
            f"{g.number_of_edges()} edges): exact {ours * 1e3:.1f} ms (median of 5), "
            f"networkx {t_ref:.2f} s, ratio {t_ref / ours:.0f}x; lengths {route.length:.6f} "
            f"vs {ref_len:.6f} (diff {route.length - ref_len:+.2e}, certified gap "
            f"{route.optimality_gap:.1e}) -> {'agree' if agree else 'DISAGREE'}; "
            f"walks {len(route.edges)} / {len(walk)} edges"
        )


def _farthest(g: nx.Graph, source):
    d = nx.single_source_dijkstra_path_length(g, source, weight="weight")
    return max(d, key=lambda v: (d[v], -v))


def _signature(g: nx.Graph, weight: str) -> tuple:
    return tuple(sorted((min(a, b), max(a, b), d[weight]) for a, b, d in g.edges(data=True)))


def section_instances() -> None:
    print("\n== 3. CARP (all instances) and postman instances ==")
    if DATA is None:
        print("shared data folder absent: skipped")
        return
    rows = []
    cache: dict[tuple, tuple[float, float]] = {}
    cases: list[tuple[str, str, nx.Graph, object, object, str]] = []
    for path in carp_paths():
        inst = read_carp(path)
        fam = (
            "gdb"
            if path.stem.startswith("gdb")
            else ("val" if path.stem[0].isdigit() else path.stem[:5])
        )
        d = inst.depot
        cases.append((path.stem, fam, inst.graph, d, d, "weight"))
        cases.append((path.stem, fam, inst.graph, d, _farthest(inst.graph, d), "weight"))
    pm = DATA / "postman"
    sg = read_postman_edgelist(pm / "edgelist_sleeping_giant.csv", required_only=True)
    sg_all = read_postman_edgelist(pm / "edgelist_sleeping_giant.csv")
    kb = read_postman_edgelist(pm / "edgelist_seven_bridges.csv")
    cases += [
        ("sleeping_giant(121 trails)", "postman", sg, "b_end_east", "b_end_east", "distance"),
        ("sleeping_giant(121 trails)", "postman", sg, "b_end_east", "b_end_west", "distance"),
        ("sleeping_giant(all 133 rows)", "postman", sg_all, "b_end_east", "b_end_east", "distance"),
        ("koenigsberg", "postman", kb, "A", "A", "distance"),
        ("koenigsberg", "postman", kb, "A", "D", "distance"),
    ]
    t_start = time.perf_counter()
    for name, fam, g, s, t, w in cases:
        ex, t_ex = timed(lambda g=g, s=s, t=t, w=w: plan_route(g, s, t, weight=w))
        th, t_th = timed(lambda g=g, s=s, t=t, w=w: plan_route(g, s, t, weight=w, method="thesis"))
        key = (_signature(g, w), s, t)
        cached = key in cache
        if not cached:
            (ref, _), t_ref = timed(lambda g=g, s=s, t=t, w=w: networkx_route(g, s, t, w))
            cache[key] = (ref, t_ref)
        ref, t_ref = cache[key]
        rows.append(
            dict(
                name=name,
                fam=fam,
                closed=s == t,
                exact=ex.length,
                ref=ref,
                thesis=th.length,
                t_ex=t_ex,
                t_th=t_th,
                t_ref=t_ref,
                cached=cached,
                odd=len(terminals(g, s, t)),
                agree=math.isclose(ex.length, ref, rel_tol=1e-12, abs_tol=1e-9),
                graph=key[0],
            )
        )
        r = rows[-1]
        print(
            f"{name:28s} {'closed' if s == t else 'open  '} |T|={r['odd']:3d} exact {ex.length:10.2f} "
            f"({t_ex * 1e3:5.1f} ms) networkx {ref:10.2f} ({t_ref:6.3f} s{', same graph' if cached else ''}) "
            f"thesis {th.length:10.2f} ({(th.length / ex.length - 1) * 100:+5.2f}%)"
            + ("" if r["agree"] else "  <-- DISAGREE")
        )
    print(f"(section 3 wall time {time.perf_counter() - t_start:.1f} s)")
    print("\nsummary (exact vs networkx baseline; thesis excess over exact):")
    groups: dict[str, list[dict]] = defaultdict(list)
    for r in rows:
        groups[r["fam"]].append(r)
    groups["ALL"] = rows
    for fam, rs in groups.items():
        for closed in (True, False):
            sub = [r for r in rs if r["closed"] == closed]
            if not sub:
                continue
            worse = [r for r in sub if r["thesis"] > r["exact"] + 1e-9]
            excess = [(r["thesis"] / r["exact"] - 1) * 100 for r in sub]
            print(
                f"  {fam:8s} {'closed' if closed else 'open  '} routes {len(sub):3d} "
                f"({len({r['graph'] for r in sub})} distinct graphs): agree "
                f"{sum(r['agree'] for r in sub)}/{len(sub)}; thesis never shorter: "
                f"{all(r['thesis'] >= r['exact'] - 1e-9 for r in sub)}; exact shorter in "
                f"{len(worse)}/{len(sub)}; thesis excess mean {statistics.mean(excess):.2f}% "
                f"max {max(excess):.2f}%; exact time median "
                f"{statistics.median(r['t_ex'] for r in sub) * 1e3:.1f} ms, max "
                f"{max(r['t_ex'] for r in sub) * 1e3:.1f} ms"
            )


def _staged(g: nx.Graph, s, t) -> tuple[Route, float, dict[str, float]]:
    marks: list[tuple[str, float]] = []
    t0 = time.perf_counter()
    route = plan_route(g, s, t, progress=lambda f, st: marks.append((st, time.perf_counter())))
    total = time.perf_counter() - t0
    stages, prev = {}, t0
    for st, tm in marks:
        stages[st] = tm - prev
        prev = tm
    return route, total, stages


def section_200k(seeds: list[int], grids: tuple[int, ...] = (16, 12, 8)) -> None:
    print("\n== 4. 200,000-edge truss graphs over seeds, before/after same run ==")
    print(
        "seed route | edges | |T| | before total (T-join) s | after total (T-join) s | ratio | "
        "lengths equal | gap after | scaling"
    )
    rows = []
    for seed, (s, t) in itertools.product(seeds, [((0, 0), (199, 351)), ((0, 0), (0, 0))]):
        if s != t:  # open first, then closed on the same graph
            g = truss_graph(200, 352, seed=seed)
        kind = "closed" if s == t else "open"
        with mock.patch("planners.vocpp.min_t_join", _reference_tjoin.min_t_join):
            rb, tb, sb = _staged(g, s, t)
        ra, ta, sa = _staged(g, s, t)
        assert_valid_route(g, ra, s, t)
        tj_b, tj_a = sb["repeated edges chosen"], sa["repeated edges chosen"]
        same = rb.length == ra.length
        rows.append((seed, tb, ta, tj_b, tj_a))
        print(
            f"{seed} {kind} | {g.number_of_edges()} | {len(terminals(g, s, t))} | {tb:.2f} ({tj_b:.2f}) | "
            f"{ta:.2f} ({tj_a:.2f}) | {tb / ta:.2f}x | {same} | {ra.optimality_gap:.1e} | "
            f"{ra.weight_scaling}",
            flush=True,
        )
        print("    after stages (s): " + ", ".join(f"{k} {v:.2f}" for k, v in sa.items()))
        if s != t:
            continue  # the grid experiment on the closed routes only (the slow ones)
        # The T-join alone at coarser grids: same instance, integer weights floor(w * 2**p).
        ea = edge_arrays(g, "weight")
        simple = simple_edges(ea)
        su, sv, sw = ea.u[simple], ea.v[simple], ea.w[simple]
        term = (ea.degrees() % 2).astype(bool)
        term[ea.index[s]] ^= True
        term[ea.index[t]] ^= True
        tj, dt = timed(
            lambda su=su, sv=sv, sw=sw, term=term, n=ea.n: min_t_join(n, su, sv, sw, term)
        )
        parts = [f"min_t_join {dt:.2f} s ({tj.scaling}, gap {tj.gap_bound:.1e})"]
        for p in grids:
            W = np.floor(np.ldexp(sw, p)).astype(np.int64)
            J, dt = timed(
                lambda W=W, su=su, sv=sv, term=term, n=ea.n: _pymatching_tjoin(n, su, sv, W, term)
            )
            gap = math.fsum((sw[J] - np.ldexp(W[J].astype(float), -p)).tolist())
            excess = math.fsum(sw[J].tolist()) - math.fsum(sw[tj.edges].tolist())
            parts.append(
                f"2^-{p}: {dt:.2f} s (gap bound {gap:.2g}, w(J) - w(J_exact) {excess:+.2g})"
            )
        print("    T-join alone: " + "; ".join(parts), flush=True)
    tb_all = [r[1] for r in rows]
    ta_all = [r[2] for r in rows]
    print(
        f"summary over {len(rows)} routes ({len(seeds)} seeds, open + closed): before total median {statistics.median(tb_all):.2f} s, "
        f"max {max(tb_all):.2f} s; after median {statistics.median(ta_all):.2f} s, max "
        f"{max(ta_all):.2f} s; routes under 5 s after: {sum(x < 5 for x in ta_all)}/{len(rows)}"
    )


def main() -> None:
    args = sys.argv[1:]
    seeds = [1, 2, 3, 4, 5, 6, 7]
    if "--seeds" in args:
        seeds = [int(x) for x in args[args.index("--seeds") + 1].split(",")]
    if "--200k-only" not in args:
        section_50k()
        section_baseline()
        section_instances()
    section_200k(seeds)


if __name__ == "__main__":
    main()
