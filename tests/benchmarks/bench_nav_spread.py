"""Navigation path stage on resamplings of one cloud ("time spread
across resamplings of one cloud within 2×, peak temporary memory < 100 MB").

Run on demand::

    .venv/bin/python tests/benchmarks/bench_nav_spread.py [--shapes cross,warren] [--n 8]

For each sample structure (the ``ara.navigate`` kind's generator, seed 0) the
cloud is resampled ``--n`` times — a random 70 % of its points, a different
draw each time, as another scan of the same steel would give — and planned
with the kind's defaults.  Printed per resampling: the path stage's time
(``paths_s``), the whole plan's time, edges planned, and the peak memory
traced during the plan (tracemalloc; numpy buffers included).  Then per
structure: the spread max/min of the path stage against the 2× target, and
the largest peak against 100 MB.  The baseline is the issue's figure
measured on the earlier code (0.7–6.9 s, ~10×; ~192 MB); no earlier code is
patched in here.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
import tracemalloc
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from planners.navigation import NavigationParams, plan_navigation
from planners.navigation.synthetic import SAMPLES

TARGET_SPREAD = 2.0
TARGET_PEAK_MB = 100.0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--shapes", default="cross,warren", help="sample structures")
    ap.add_argument("--n", type=int, default=8, help="resamplings per structure")
    ap.add_argument("--keep", type=float, default=0.7, help="fraction of points kept")
    args = ap.parse_args()
    for shape in args.shapes.split(","):
        cloud = SAMPLES[shape](0)
        print(f"== {shape}: {len(cloud)} points, {args.n} resamplings of {args.keep:.0%} ==")
        print(f"{'draw':>4} {'paths s':>8} {'plan s':>8} {'edges':>6} {'peak MB':>8}")
        paths, peaks = [], []
        for k in range(args.n):
            rng = np.random.default_rng(1000 + k)
            pts = cloud[rng.random(len(cloud)) < args.keep]
            tracemalloc.start()
            t = time.perf_counter()
            res = plan_navigation(pts, params=NavigationParams())
            dt = time.perf_counter() - t
            peak = tracemalloc.get_traced_memory()[1] / 2**20
            tracemalloc.stop()
            ps = float(res.timings_s.get("paths_s", float("nan")))
            paths.append(ps)
            peaks.append(peak)
            print(f"{k:4d} {ps:8.2f} {dt:8.2f} {len(res.edge_paths):6d} {peak:8.1f}", flush=True)
        lo, hi = min(paths), max(paths)
        print(
            f"  path stage: min {lo:.2f} s, median {statistics.median(paths):.2f} s, max {hi:.2f} s; "
            f"spread {hi / lo:.2f}× (target < {TARGET_SPREAD:.0f}×: {'met' if hi / lo < TARGET_SPREAD else 'MISSED'}); "
            f"largest peak {max(peaks):.0f} MB (target < {TARGET_PEAK_MB:.0f}: "
            f"{'met' if max(peaks) < TARGET_PEAK_MB else 'MISSED'})"
        )


if __name__ == "__main__":
    main()
