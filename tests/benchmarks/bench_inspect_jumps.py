"""ARA inspection program with every inch-worm jump planned (on demand).

    .venv/bin/python tests/benchmarks/bench_inspect_jumps.py [--big SAMPLE:SEED]

Runs the ``ara.inspect`` kind with ``plan_jumps`` (structure model, route,
every jump of the main route planned with the OMPL RRT-Connect jump planner,
one plan per distinct geometry, the program assembled and checked) on:

* the default plan (scan_warren, seed 2), target < 10 s;
* a structure of about 100 members (default ``scan_grillage:0``), target < 60 s.

Printed per case: wall time and its ratio to the target, members, jump
sites, distinct geometries (planner calls), jumps planned, the time in jump
planning, and the failed checks.  One BLAS thread, as the planning workers.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from threadpoolctl import threadpool_limits

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from server.kinds.ara_inspect import AraInspectParams, run


class _Ctx:
    def progress(self, fraction: float, stage: str) -> None:
        pass

    def load_cloud(self, cloud_id: str):  # pragma: no cover - samples only
        raise KeyError(cloud_id)


def case(name: str, params: AraInspectParams, target_s: float) -> None:
    t0 = time.perf_counter()
    out = run(params, _Ctx())
    wall = time.perf_counter() - t0
    m = out.metrics
    failed = [c.name for c in out.checks if not c.passed]
    print(
        f"{name:28s} {wall:7.2f} s  ratio to target {wall / target_s:5.2f} (target < {target_s:g} s)"
        f"  members {m.get('member_count', 0):.0f}  sites {m.get('jump_sites', 0):.0f}"
        f"  planner calls {m.get('jump_planner_calls', 0):.0f}"
        f"  planned {m.get('jumps_planned', 0):.0f}"
        f"  jump planning {m.get('jump_plan_time_s', 0.0):.2f} s"
        f"  failed checks {failed or 'none'}",
        flush=True,
    )


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--big", default="scan_grillage:0", help="SAMPLE:SEED of the ~100-member case")
    a = ap.parse_args()
    big, seed = a.big.split(":")
    with threadpool_limits(1):
        case("scan_warren:2 (default)", AraInspectParams(plan_jumps=True), 10.0)
        case(
            f"{big}:{seed}",
            AraInspectParams(sample=big, sample_seed=int(seed), plan_jumps=True),
            60.0,
        )


if __name__ == "__main__":
    main()
