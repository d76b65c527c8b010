"""Structure model and inspection route on synthetic TLS scans.

Run on demand::

    .venv/bin/python tests/benchmarks/bench_structure.py
        [--kinds warren,pratt,frame,grillage,deck,frame_slabs]
        [--seeds 20] [--spacings 0.005,0.02,0.1] [--scaling] [--no-accuracy]

Accuracy: for every structure type, spacing and seed, a scan from
:func:`planners.structure.synthetic.make_scan` is modelled
(:func:`planners.structure.model_structure`) and routed
(:func:`planners.inspection.plan_inspection`).  Printed per type and
spacing: member recall over all true members and over the *visible* ones
(points on at least half of the member's length — a member no scanner saw
cannot be found), precision, the share of found members on a route (one per piece the
jumps cannot join), the share of found members whose profile is their
section's (I, channel, angle, tee, box, tube; each true member counted once)
and the share called ``"unknown"`` (a section under three spacings deep is
not classified), and the mean time per stage.  A member is found by the issue's criterion
(:func:`planners.structure.synthetic.match_members`: axis within
max(5 cm, 0.6 × depth) over ≥ 80 % of the length, within 5°).  Targets:
recall ≥ 95 %, precision ≥ 90 %.

``--first-pass-sections`` turns the final sections stage off: the same
members, with the faces and profiles of the first passes (the baseline of
the profile column).  ``--no-surfaces`` searches the whole cloud for members, deck soffits,
slabs, walls and ground included (:mod:`planners.structure.surfaces`;
the baseline of the surfaces stage).  ``deck`` and ``frame_slabs`` are
the scans with concrete (a deck on girders, a frame with floor slabs).
``--no-chains`` leaves members seen as collinear
pieces across occlusion shadows apart (:mod:`planners.structure.chains`;
the baseline of those joins).

Scaling (``--scaling``): one frame scan at 5 mm, thinned to 50k, 100k,
300k and 1M points, each modelled and routed in a fresh process so that
its peak RSS is its own.  Printed: time per stage, total, the ratio to the
50k run (the baseline measured in the same run) and to the targets
(300k < 10 s, 1M < 30 s, peak RSS < 2 GB).
"""

from __future__ import annotations

import argparse
import json
import resource
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

from planners.inspection import plan_inspection  # noqa: E402
from planners.structure import model_structure  # noqa: E402
from planners.structure.synthetic import SCAN_KINDS, make_scan, match_members  # noqa: E402

TARGET_RECALL = 0.95
TARGET_PRECISION = 0.90
TARGETS_S = {300_000: 10.0, 1_000_000: 30.0}
TARGET_RSS_GB = 2.0


def visible(scan, min_cover: float = 0.5, bins: int = 10) -> np.ndarray:
    """(T,) whether points lie along at least ``min_cover`` of each member."""
    out = np.zeros(len(scan.members), dtype=bool)
    pts = scan.points / scan.scale
    for m in scan.members:
        sel = scan.labels == m.id
        if sel.sum() < 5:
            continue
        d = m.axis[1] - m.axis[0]
        t = (pts[sel] - m.axis[0]) @ d / (d @ d)
        occ = np.unique(np.clip((t * bins).astype(int), 0, bins - 1))
        out[m.id] = len(occ) >= min_cover * bins
    return out


def run_one(kind: str, seed: int, spacing: float) -> dict:
    scan = make_scan(kind, seed, spacing_m=spacing)
    t = time.perf_counter()
    model = model_structure(scan.points / scan.scale)
    t_model = time.perf_counter() - t
    found = np.array([m.axis for m in model.members]) if model.members else np.zeros((0, 2, 3))
    mm = match_members(scan.true_axes(), scan.true_depths(), found)
    vis = visible(scan)
    # pairs are (true, found); recall over the visible members only
    true_ids = {t_ for t_, _ in mm.pairs}
    rec_vis = len(true_ids & set(np.flatnonzero(vis))) / max(int(vis.sum()), 1)
    # profile of each found true member (its first pair) against its section's
    first: dict[int, int] = {}
    for t_, f_ in mm.pairs:
        first.setdefault(t_, f_)
    said = [
        (scan.members[t_].section.profile, model.members[f_].profile) for t_, f_ in first.items()
    ]
    on_route = float("nan")
    t_route = 0.0
    if model.members:
        t = time.perf_counter()
        plan = plan_inspection(model)
        t_route = time.perf_counter() - t
        driven = {plan.graph.edges[e]["member"] for r in plan.routes for e in r.edges} - {None}
        on_route = len(driven) / len(model.members)
    return {
        "points": len(scan.points),
        "recall": mm.recall,
        "recall_visible": rec_vis,
        "precision": mm.precision,
        "on_route": on_route,
        "profile": float(np.mean([a == b for a, b in said])) if said else float("nan"),
        "unknown": float(np.mean([b == "unknown" for _, b in said])) if said else float("nan"),
        "stages": dict(model.timings_s),
        "model_s": t_model,
        "route_s": t_route,
    }


def accuracy(kinds: list[str], seeds: int, spacings: list[float]) -> None:
    print(f"{'type':>9} {'spacing':>7} {'seeds':>5} {'points':>8} {'recall':>7} {'rec vis':>7} "
          f"{'prec':>6} {'on rte':>6} {'profile':>7} {'unknown':>7} {'model s':>8} {'route s':>8}  stages (mean s)")  # fmt: skip
    for spacing in spacings:
        for kind in kinds:
            rows = []
            for seed in range(seeds):
                rows.append(run_one(kind, seed, spacing))
            mean = {k: float(np.nanmean([r[k] for r in rows])) for k in
                    ("points", "recall", "recall_visible", "precision", "on_route", "profile", "unknown",
                     "model_s", "route_s")}  # fmt: skip
            stages = {k: round(float(np.mean([r["stages"].get(k, 0.0) for r in rows])), 2)
                      for k in rows[0]["stages"]}  # fmt: skip
            flag = (
                "met"
                if mean["recall_visible"] >= TARGET_RECALL and mean["precision"] >= TARGET_PRECISION
                else "MISSED"
            )
            print(f"{kind:>9} {spacing:7.3f} {seeds:5d} {mean['points']:8.0f} {mean['recall']:7.3f} "
                  f"{mean['recall_visible']:7.3f} {mean['precision']:6.3f} {mean['on_route']:6.3f} "
                  f"{mean['profile']:7.3f} {mean['unknown']:7.3f} "
                  f"{mean['model_s']:8.2f} {mean['route_s']:8.2f}  {stages}  [{flag}]", flush=True)  # fmt: skip


CHILD = """
import json, resource, sys, time
sys.path.insert(0, {root!r})
import numpy as np
from planners.structure import model_structure
from planners.inspection import plan_inspection
pts = np.load({path!r})
t = time.perf_counter(); model = model_structure(pts); tm = time.perf_counter() - t
t = time.perf_counter(); plan = plan_inspection(model) if model.members else None; tr = time.perf_counter() - t
print(json.dumps({{"stages": model.timings_s, "model_s": tm, "route_s": tr, "members": len(model.members),
                  "rss_gb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20}}))
"""


def scaling(tmp: Path) -> None:
    scan = make_scan("frame", 1, spacing_m=0.005)
    pts = scan.points
    print(f"== scaling: frame seed 1 at 5 mm ({len(pts)} points), thinned uniformly ==")
    rng = np.random.default_rng(0)
    base = None
    for n in (50_000, 100_000, 300_000, 1_000_000):
        if n > len(pts):
            print(f"{n:>9}: the scan has only {len(pts)} points")
            continue
        sub = pts[rng.choice(len(pts), n, replace=False)]
        path = tmp / f"scan_{n}.npy"
        np.save(path, sub)
        out = subprocess.run([sys.executable, "-c", CHILD.format(root=str(ROOT), path=str(path))],
                             capture_output=True, text=True, check=True)  # fmt: skip
        r = json.loads(out.stdout.strip().splitlines()[-1])
        total = r["model_s"] + r["route_s"]
        base = base or total
        target = TARGETS_S.get(n)
        tgt = f"target < {target:.0f} s: {'met' if total < target else 'MISSED'}" if target else ""
        print(f"{n:>9}: total {total:6.2f} s ({total / base:5.2f}× the 50k run), route {r['route_s']:.2f} s, "
              f"members {r['members']}, peak RSS {r['rss_gb']:.2f} GB "
              f"({'met' if r['rss_gb'] < TARGET_RSS_GB else 'MISSED'} < {TARGET_RSS_GB:.0f} GB) {tgt}\n"
              f"           stages {r['stages']}", flush=True)  # fmt: skip
        path.unlink()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--kinds", default=",".join(SCAN_KINDS))
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--spacings", default="0.005,0.02,0.1")
    ap.add_argument("--scaling", action="store_true")
    ap.add_argument("--no-accuracy", action="store_true")
    ap.add_argument("--tmp", default="/tmp")
    ap.add_argument(
        "--first-pass-sections",
        action="store_true",
        help="report the faces and profiles of the first passes (the baseline of the "
        "sections stage: pipeline.SECTION_PASS off); members and axes are the same",
    )
    ap.add_argument(
        "--no-chains",
        action="store_true",
        help="leave the members seen in collinear pieces apart (the baseline of the "
        "chains: pipeline.CHAIN_PIECES off)",
    )
    ap.add_argument(
        "--no-surfaces",
        action="store_true",
        help="search the whole cloud for members, large planes included (the baseline "
        "of the surfaces stage: pipeline.SEPARATE_SURFACES off)",
    )
    args = ap.parse_args()
    from planners.structure import pipeline

    if args.no_surfaces:
        pipeline.SEPARATE_SURFACES = False

    if args.first_pass_sections:
        pipeline.SECTION_PASS = False
    if args.no_chains:
        pipeline.CHAIN_PIECES = False
    if not args.no_accuracy:
        accuracy(args.kinds.split(","), args.seeds, [float(s) for s in args.spacings.split(",")])
    if args.scaling:
        scaling(Path(args.tmp))
    print(f"process peak RSS {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20:.2f} GB")


if __name__ == "__main__":
    main()
