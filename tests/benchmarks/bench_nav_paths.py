"""On-demand benchmark of the navigation path stage (seed Alg. 6 + §2.3 RRT),
before/after a change of ``planners/navigation/rrt.py``.

Run one tree: ``PYTHONPATH=<tree> .venv/bin/python tests/benchmarks/bench_nav_paths.py
--label after [--shapes cross,t,l] [--seeds 0,1] [--models differential,holonomic]``.
Compare two trees in one run, interleaved per case (so machine load hits both
alike): ``... bench_nav_paths.py --compare <tree_before> <tree_after>``.

Per structure (30k points, crawler contact patch 0.08 × 0.025 m or ``--foot``), per motion
model: route edges planned on steel / total, driven distance (m), turning
(rad), RRT iterations, the path stage's wall time, the whole plan's CPU time
(steadier than wall time on a shared machine; the stages before the paths
are the same in both trees) and a hash of every edge's poses (equal hashes:
identical paths).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import subprocess
import sys
import time

import numpy as np


def run_case(shape: str, seed: int, model: str, foot: str = "") -> dict[str, object]:
    from planners.navigation import NavigationParams, plan_navigation
    from planners.navigation.synthetic import make_structure

    st = make_structure(shape, seed)
    length, width = map(float, foot.split("x")) if foot else (0.08, 0.025)
    params = NavigationParams(
        motion_model=model,
        footprint_length_m=length,
        footprint_width_m=width,
        footprint_center_x_m=0.0,
    )
    t, c = time.perf_counter(), time.process_time()
    res = plan_navigation(st.points, params=params)
    total, cpu = time.perf_counter() - t, time.process_time() - c
    h = hashlib.sha1()
    dist = turn = 0.0
    iters = 0
    for e in res.edge_paths:
        h.update(np.ascontiguousarray(e.poses).tobytes())
        iters += e.iterations
        if e.ok and len(e.poses) > 1:
            d = np.diff(e.poses, axis=0)
            dist += float(np.hypot(d[:, 0], d[:, 1]).sum())
            turn += float(np.abs((d[:, 2] + np.pi) % (2 * np.pi) - np.pi).sum())
    return {
        "shape": shape,
        "seed": seed,
        "model": model,
        "ok": sum(e.ok for e in res.edge_paths),
        "edges": len(res.edge_paths),
        "dist_m": round(dist, 4),
        "turn_rad": round(turn, 3),
        "iters": iters,
        "paths_s": round(res.timings_s["paths_s"], 3),
        "total_s": round(total, 3),
        "cpu_s": round(cpu, 3),
        "hash": h.hexdigest()[:10],
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--shapes", default="cross,t,l,k,i,warren")
    ap.add_argument("--seeds", default="0,1")
    ap.add_argument("--models", default="differential,holonomic")
    ap.add_argument("--label", default="")
    ap.add_argument(
        "--foot", default="", help="LxW footprint in metres (default: the contact patch)"
    )
    ap.add_argument("--compare", nargs=2, metavar=("BEFORE", "AFTER"))
    ap.add_argument("--one", help="shape:seed:model (internal: one case as JSON)")
    a = ap.parse_args()
    if a.one:
        shape, seed, model = a.one.split(":")
        print(json.dumps(run_case(shape, int(seed), model, a.foot)))
        return
    cases = [
        (s, int(k), m)
        for m in a.models.split(",")
        for s in a.shapes.split(",")
        for k in a.seeds.split(",")
    ]
    trees = a.compare if a.compare else [None]
    labels = ["before", "after"] if a.compare else [a.label or "run"]
    head = f"{'tree':7s} {'model':12s} {'case':10s} {'ok':>7s} {'dist m':>8s} {'turn':>7s} {'iters':>6s} {'paths s':>8s} {'cpu s':>6s}  hash"
    print(head)
    for shape, seed, model in cases:
        for tree, label in zip(trees, labels, strict=True):
            if tree is None:
                r = run_case(shape, seed, model, a.foot)
            else:
                env = dict(os.environ, PYTHONPATH=tree)
                out = subprocess.run(
                    [
                        sys.executable,
                        __file__,
                        "--one",
                        f"{shape}:{seed}:{model}",
                        "--foot",
                        a.foot,
                    ],
                    env=env,
                    capture_output=True,
                    text=True,
                    check=True,
                    cwd=tree,
                )
                r = json.loads(out.stdout.strip().splitlines()[-1])
            print(
                f"{label:7s} {model:12s} {shape + ':' + str(seed):10s} {r['ok']:>3d}/{r['edges']:<3d}"
                f" {r['dist_m']:>8.3f} {r['turn_rad']:>7.2f} {r['iters']:>6d} {r['paths_s']:>8.2f} {r['cpu_s']:>6.2f}  {r['hash']}",
                flush=True,
            )


if __name__ == "__main__":
    main()
