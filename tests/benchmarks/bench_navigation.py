"""On-demand benchmark of the ARA navigation chain (issue 3 "Done when").

Run: ``.venv/bin/python tests/benchmarks/bench_navigation.py [--seeds 20] [--shapes cross,t]``

Prints
1. segmentation success per shape over the generator seeds, default vs the
   seed's Alg. 3 ("thesis"): clusters ↔ ground truth one to one, and the
   route along ≥ 90 % of every bar's centre line (within w/2 + 3 cm); the
   default is run twice per cloud and must give identical output;
2. pipeline time per stage for a 50k-point cloud of every shape;
3. PIBC (Alg. 6): the vectorised check vs a per-point loop of Alg. 6 as
   printed (the baseline), timed on the same points in the same run, and
   the agreement of both variants with exact ray casting.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from planners.navigation import NavigationParams, plan_navigation
from planners.navigation.boundaries import cluster_geometry
from planners.navigation.evaluate import (
    bar_coverage,
    segmentation_correct,
    transfer_labels,
)
from planners.navigation.graph import build_graph, default_endpoints
from planners.navigation.pibc import BoundarySet, point_in_polygon
from planners.navigation.preprocess import preprocess
from planners.navigation.segmentation import borders, segment_thesis
from planners.navigation.synthetic import SHAPES, make_structure
from planners.vocpp import plan_route

CRAWLER = {"footprint_length_m": 0.08, "footprint_width_m": 0.025, "footprint_center_x_m": 0.0}
TRUSSES = ("warren", "pratt")


def _thesis_pipeline(st, p: NavigationParams, max_clusters: int) -> tuple[bool, bool, float]:
    """Alg. 3 as printed, then the same graph and route: (segmentation ok, route ok, seconds)."""
    t = time.perf_counter()
    pre = preprocess(
        st.points, voxel_m=p.voxel_m, ransac_threshold_m=p.ransac_threshold_m, seed=p.seed
    )
    uv = pre.points2d
    seg = segment_thesis(
        uv, n_clusters_min=2, n_clusters_max=max_clusters, lb_m=p.border_lb_m, eps_m=p.border_eps_m
    )
    dt = time.perf_counter() - t
    gt = transfer_labels(pre.points3d, st)
    seg_ok, _ = segmentation_correct(seg.labels, seg.kinds, gt, st.kinds)
    brs = borders(uv, seg.labels, eps_m=p.border_eps_m, lb_m=p.border_lb_m)
    clusters = cluster_geometry(uv, seg.labels, seg.kinds, brs, sliding_factor_m=p.sliding_factor_m)
    g = build_graph(clusters, brs, pre.frame.lift, dmin_m=p.dmin_m)
    try:
        s, e = default_endpoints(g)
        route = plan_route(g, s, e)
        route_ok = bool(bar_coverage(st, g, route.edges).min() >= 0.9)
    except ValueError:  # disconnected or empty graph: no route
        route_ok = False
    return seg_ok, route_ok, dt


def segmentation_table(shapes: list[str], seeds: int) -> dict[str, dict[str, object]]:
    p = NavigationParams(plan_paths=False)
    table: dict[str, dict[str, object]] = {}
    print(f"\n== Segmentation and route over {seeds} generator seeds (30k-point clouds) ==")
    print(
        f"{'shape':8s} {'default seg':>11s} {'route':>6s} {'determ.':>8s} {'t/cloud':>8s} |"
        f" {'thesis seg':>10s} {'route':>6s} {'t/cloud':>8s}  (thesis Ncmax)"
    )
    for shape in shapes:
        d_seg = d_route = d_det = th_seg = th_route = 0
        d_t = th_t = 0.0
        ncmax = 40 if shape in TRUSSES else 12
        failures = []
        for seed in range(seeds):
            st = make_structure(shape, seed)
            t = time.perf_counter()
            res = plan_navigation(st.points, params=p)
            d_t += time.perf_counter() - t
            again = plan_navigation(st.points.copy(), params=p)
            same = (
                np.array_equal(res.labels, again.labels)
                and res.route.edges == again.route.edges
                and sorted(res.graph.edges(data="weight"))
                == sorted(again.graph.edges(data="weight"))
            )
            gt = transfer_labels(res.points, st)
            ok, _ = segmentation_correct(res.labels, [c.kind for c in res.clusters], gt, st.kinds)
            cov = bar_coverage(st, res.graph, res.route.edges)
            d_seg += ok
            d_route += bool(cov.min() >= 0.9)
            d_det += same
            if not (ok and cov.min() >= 0.9 and same):
                failures.append(seed)
            s_ok, r_ok, dt = _thesis_pipeline(st, p, ncmax)
            th_seg += s_ok
            th_route += r_ok
            th_t += dt
        table[shape] = {
            "default_segmentation": d_seg,
            "default_route": d_route,
            "default_deterministic": d_det,
            "thesis_segmentation": th_seg,
            "thesis_route": th_route,
            "seeds": seeds,
            "default_failures": failures,
        }
        print(
            f"{shape:8s} {d_seg:>6d}/{seeds:<4d} {d_route:>3d}/{seeds:<2d} {d_det:>4d}/{seeds:<3d}"
            f" {d_t / seeds:>7.2f}s | {th_seg:>5d}/{seeds:<4d} {th_route:>3d}/{seeds:<2d}"
            f" {th_t / seeds:>7.2f}s  ({ncmax})"
        )
    return table


def timing_table(shapes: list[str]) -> dict[str, dict[str, float]]:
    print("\n== Pipeline time per stage, 50k-point cloud, seed 0 (small crawler footprint) ==")
    stages = ["preprocess_s", "segmentation_s", "boundaries_s", "graph_s", "route_s", "paths_s"]
    print(
        f"{'shape':8s} {'points':>7s} "
        + " ".join(f"{s[:-2]:>12s}" for s in stages)
        + f" {'total':>8s}  paths ok"
    )
    out = {}
    for shape in shapes:
        st = make_structure(shape, 0, n_points=50_000)
        t = time.perf_counter()
        res = plan_navigation(st.points, params=NavigationParams(**CRAWLER))
        total = time.perf_counter() - t
        ok = sum(e.ok for e in res.edge_paths)
        print(
            f"{shape:8s} {len(st.points):>7d} "
            + " ".join(f"{res.timings_s[s]:>11.3f}s" for s in stages)
            + f" {total:>7.2f}s  {ok}/{len(res.edge_paths)}"
        )
        out[shape] = {
            **res.timings_s,
            "total_s": total,
            "paths_ok": ok,
            "paths": len(res.edge_paths),
        }
    return out


def _pibc_per_point(points: np.ndarray, bset: BoundarySet, n: int, m: int) -> np.ndarray:
    """Alg. 6 as printed, one point at a time, every loop run to the end (the
    pseudo-code has no early exit) — the baseline of the "thesis" variant."""
    out = np.zeros(len(points), dtype=bool)
    for i, p in enumerate(points):  # line 5: for each projected point
        ds_all = np.linalg.norm(bset.centres - p, axis=1)  # line 6
        for k in np.argsort(ds_all)[:n]:  # lines 7-8: n closest centres
            star = bset.stars[k]
            d = np.linalg.norm(star.pts - p, axis=1)
            for j in np.argsort(d)[:m]:  # lines 9-10: m closest boundary points
                if ds_all[k] < np.linalg.norm(star.pts[j] - star.centre):  # line 12
                    out[i] = True  # line 13
    return out


def _angular_per_point(points: np.ndarray, bset: BoundarySet) -> np.ndarray:
    """The default ("angular") test one point and one cluster at a time — its baseline."""
    out = np.zeros(len(points), dtype=bool)
    for i, p in enumerate(points):
        for star in bset.stars:
            if len(star.pts) < 3:
                continue
            if not star.star:
                out[i] = bool(point_in_polygon(p[None], star.pts)[0])
            else:
                d = p - star.centre
                phi = np.arctan2(d[1], d[0])
                j = int(np.searchsorted(star.ang, phi, side="right")) % len(star.pts)
                a, b = star.pts[j - 1] - star.centre, star.pts[j] - star.centre
                r = float(np.hypot(*d))
                if r == 0.0:
                    out[i] = True
                else:
                    u = d / r
                    ca, cb = a[0] * u[1] - a[1] * u[0], b[0] * u[1] - b[1] * u[0]
                    t = ca / (ca - cb) if abs(ca - cb) > 1e-15 else 0.5
                    hit = a + min(max(t, 0.0), 1.0) * (b - a)
                    out[i] = r < float(hit @ u)
            if out[i]:
                break
    return out


def pibc_table() -> dict[str, float]:
    print(
        "\n== PIBC (Alg. 6): vectorised vs per-point baseline, and agreement with exact ray casting =="
    )
    st = make_structure("pratt", 0, n_points=50_000)
    res = plan_navigation(st.points, params=NavigationParams(plan_paths=False))
    polys = [c.boundary for c in res.clusters]
    bset = BoundarySet([c.centre for c in res.clusters], polys)
    rng = np.random.default_rng(0)
    lo, hi = res.points2d.min(axis=0), res.points2d.max(axis=0)
    # Half near the steel (processed points jittered by up to 3 cm), half uniform.
    near = res.points2d[rng.integers(len(res.points2d), size=10_000)] + rng.normal(
        0, 0.02, (10_000, 2)
    )
    pts = np.vstack([near, rng.uniform(lo, hi, (10_000, 2))])
    exact = np.any([point_in_polygon(pts, pg) for pg in polys], axis=0)
    n, m = 3, 3
    out: dict[str, float] = {"points": float(len(pts)), "clusters": float(len(polys))}
    for method in ("angular", "thesis"):
        t = time.perf_counter()
        got = bset.contains(
            pts, method=method, n_centres=len(bset) if method == "angular" else n, m_closest=m
        )
        dt = time.perf_counter() - t
        agree = float(np.mean(got == exact))
        out[f"{method}_s"] = dt
        out[f"{method}_agreement"] = agree
        print(
            f"  {method:8s} vectorised: {dt * 1e3:8.1f} ms for {len(pts)} points; agreement with ray casting {agree:.4%}"
        )
    sub = pts[:2000]
    for name, base_fn, kw in (
        ("thesis", lambda q: _pibc_per_point(q, bset, n, m), {"n_centres": n, "m_closest": m}),
        ("angular", lambda q: _angular_per_point(q, bset), {"n_centres": len(bset)}),
    ):
        t = time.perf_counter()
        base = base_fn(sub)
        t_base = time.perf_counter() - t
        t = time.perf_counter()
        vec = bset.contains(sub, method=name, **kw)
        t_vec = time.perf_counter() - t
        same = float(np.mean(base == vec))
        out.update(
            {
                f"{name}_loop_s": t_base,
                f"{name}_vectorised_2000_s": t_vec,
                f"{name}_speedup": t_base / t_vec,
                f"{name}_loop_same": same,
            }
        )
        print(
            f"  {name:8s} per-point loop {t_base * 1e3:8.1f} ms vs vectorised {t_vec * 1e3:6.1f} ms"
            f" on the same {len(sub)} points → {t_base / t_vec:5.0f}× faster; identical answers {same:.2%}"
        )
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--shapes", default=",".join(SHAPES))
    ap.add_argument("--skip", default="", help="comma list of sections to skip: seg,time,pibc")
    ap.add_argument("--json", help="also write the numbers to this file")
    args = ap.parse_args()
    shapes = args.shapes.split(",")
    skip = set(filter(None, args.skip.split(",")))
    out: dict[str, object] = {}
    if "seg" not in skip:
        out["segmentation"] = segmentation_table(shapes, args.seeds)
    if "time" not in skip:
        out["timing"] = timing_table(shapes)
    if "pibc" not in skip:
        out["pibc"] = pibc_table()
    if args.json:
        Path(args.json).write_text(json.dumps(out, indent=2, default=float))


if __name__ == "__main__":
    main()
