"""E-stop on a crowded machine: quiet vs soak vs upload, in one run.

Run on demand::

    .venv/bin/python tests/benchmarks/bench_estop_load.py \\
        [--trials 40] [--phase-s 300] [--writers 18] [--streams 2] [--upload-mb 121] [--pollers 50] [--plans 8]

One real ``steelpath serve`` subprocess on loopback (its own data directory,
built-in emulators), set up as ``bench_busy.py`` does (every dispatchable
kind planned and approved; one ``demo.route`` per E-stop trial).  Three
phases, each with the same E-stop trial (``bench_busy.estop_trials``: an
ARA route executing, ``POST /api/v1/estop``; the *stop* latency is the
emulator's own motion-stop instant minus the instant the request was sent,
the *response* latency the request's round trip):

1. **quiet** — nothing else running;
2. **soak** — ``--writers`` operators, each mixing reads, plan submits
   (``demo.route``), approvals, E-stop clears and dispatches of prepared
   plans to the other robots, plus ``--streams`` event-stream followers
   (``_load.mixed_clients``);
3. **upload** — a ``--upload-mb`` XYZ cloud uploaded in a loop,
   ``--pollers`` read pollers and ``--plans`` heavy plans kept in flight.

Prints p50 / p95 of the response and of the stop for each phase with the
ratio to quiet.  Target: p95 < 100 ms, response and stop, under soak and
upload.  Exit status 0 when met, 1 when missed, 2 when the run failed.
"""

from __future__ import annotations

import argparse
import math
import multiprocessing as mp
import random
import shutil
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

from tests.benchmarks._load import (  # noqa: E402
    mixed_clients,
    percentile,
    planning_load,
    read_clients,
    read_paths,
    upload_load,
    write_xyz,
)
from tests.benchmarks.bench_busy import (  # noqa: E402
    CLIENTS_PER_PROCESS,
    ESTOP_ROBOT,
    HEAVY_KINDS,
    MAX_SKIPS,
    Api,
    BenchError,
    EstopRun,
    LogTail,
    Server,
    clear_all,
    estop_trials,
    load_processes,
    log,
    prepare,
    start_server,
    stop_server,
    wait_for,
    wait_ready,
)

TARGET_P95_MS = 100.0


def stats(run: EstopRun) -> dict[str, float]:
    stop = [t.latency_ms for t in run.trials]
    resp = [t.http_ms for t in run.trials]
    inside = [sum(t.server_ms.values()) for t in run.trials if t.server_ms]
    record = [t.server_ms.get("record", math.nan) for t in run.trials if t.server_ms]
    return {
        "server_p95": percentile(inside, 95),
        "record_p95": percentile(record, 95),
        "n": float(len(run.trials)),
        "response_p50": percentile(resp, 50),
        "response_p95": percentile(resp, 95),
        "stop_p50": percentile(stop, 50),
        "stop_p95": percentile(stop, 95),
    }


def fmt(v: float) -> str:
    return "—" if math.isnan(v) else f"{v:7.1f}"


def ratio(a: float, b: float) -> str:
    return "—" if math.isnan(a) or math.isnan(b) or b <= 0 else f"{a / b:5.1f}×"


def phase(
    label: str,
    specs: list[tuple[str, Callable[..., None], tuple[Any, ...]]],
    ready: Callable[[], bool],
    ctx: Any,
    tmp: Path,
    api: Api,
    plans: list[str],
    n: int,
    tail: LogTail,
    rng: random.Random,
    flags: tuple[Any, Any],
    budget_s: float,
    robots: list[str],
    phase_s: float,
) -> tuple[EstopRun, dict[str, Any]]:
    run = EstopRun(method="emulator log", probed=True)
    with load_processes(ctx, specs, tmp) as (_, procs):
        wait_for(f"the {label} load to be in flight", ready, 180, 0.1)
        time.sleep(3.0)
        # Spread over the phase, so the trials sample the whole soak rather
        # than its first seconds.
        log(f"{label}: {n} E-stop trials over {phase_s:.0f} s")
        t_end = time.monotonic() + phase_s
        for i in range(n):
            estop_trials(api, plans, 1, tail, run, rng, flags[0], flags[1], label, budget_s)
            left = t_end - time.monotonic()
            if left > 0 and i < n - 1:
                time.sleep(left / (n - 1 - i) * rng.uniform(0.5, 1.0))
    clear_all(api, robots)
    loads = {lp.name: lp.result() for lp in procs}
    samples = [s for r in loads.values() for s in r.get("samples", [])]
    by: dict[str, list[float]] = {}
    for s in samples:
        by.setdefault(s[1], []).append(s[2])
    codes: dict[str, int] = {}
    for s in samples:
        codes[str(s[3])] = codes.get(str(s[3]), 0) + 1
    load = {
        "requests": len(samples),
        "codes": codes,
        "p95_by": {k: percentile(v, 95) for k, v in sorted(by.items())},
        "event_lines": sum(int(r.get("event_lines", 0)) for r in loads.values()),
        "uploads": sum(len(r.get("uploads", [])) for r in loads.values()),
        "plans_finished": sum(len(r.get("finished", [])) for r in loads.values()),
    }
    return run, load


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--trials", type=int, default=40, help="E-stop trials per loaded phase")
    ap.add_argument("--phase-s", type=float, default=300.0, help="length of each loaded phase")
    ap.add_argument("--quiet-trials", type=int, default=20)
    ap.add_argument("--writers", type=int, default=18, help="soak: mixed read/write operators")
    ap.add_argument("--streams", type=int, default=2, help="soak: event-stream followers")
    ap.add_argument("--interval", type=float, default=0.5, help="s between an operator's requests")
    ap.add_argument("--upload-mb", type=float, default=121.0)
    ap.add_argument("--pollers", type=int, default=50, help="upload phase: read pollers")
    ap.add_argument("--plans", type=int, default=8, help="upload phase: heavy plans in flight")
    ap.add_argument("--time-scale", type=float, default=10.0)
    ap.add_argument("--emulator-nice", type=int, default=0)
    ap.add_argument("--job-workers", type=int, default=2)
    ap.add_argument("--log-level", default="warning")
    ap.add_argument("--estop-route-m", type=float, default=30.0)
    ap.add_argument("--trial-budget-s", type=float, default=420.0)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument(
        "--phases", default="soak,upload", help="loaded phases to run (quiet always runs)"
    )
    args = ap.parse_args()
    tmp = Path(tempfile.mkdtemp(prefix="bench_estop_load-"))
    servers: list[Server] = []
    try:
        return run(args, tmp, servers)
    except BenchError as exc:
        log(f"benchmark failed: {exc}")
        for srv in servers:
            log(f"server log tail:\n{srv.log_tail()}")
        return 2
    finally:
        for srv in servers:
            stop_server(srv)
        shutil.rmtree(tmp, ignore_errors=True)


def run(args: argparse.Namespace, tmp: Path, servers: list[Server]) -> int:
    rng = random.Random(args.seed)
    ctx = mp.get_context("spawn")
    upload_flag, plans_flag = ctx.Value("i", 0), ctx.Value("i", 0)
    cloud = write_xyz(tmp / "load.xyz", args.upload_mb, seed=args.seed)
    srv = start_server(tmp, args, servers)
    admin = Api(srv.url, srv.admin_token)
    operator = admin.post("/tokens", {"name": "bench operator", "role": "operator"}, (201,))
    viewer = admin.post("/tokens", {"name": "bench viewer", "role": "viewer"}, (201,))
    admin.close()
    api = Api(srv.url, operator["token"])
    robots = [r["name"] for r in api.get("/robots")]
    for r in robots:
        wait_ready(api, r, 120)
    n_estop = args.quiet_trials + 2 * args.trials + 1 + 2 * MAX_SKIPS
    prep = prepare(api, 8, n_estop, 60.0, 120.0, args.estop_route_m)
    mix = read_paths(list(prep.template_ids.values()))
    others = [(pid, robot) for _, robot, pid in prep.dispatch_jobs if robot != ESTOP_ROBOT]
    heavy = [k for k in HEAVY_KINDS if k in prep.template_ids] or sorted(prep.template_ids)
    tail = LogTail(srv.data / "emulators" / f"{ESTOP_ROBOT}.log.jsonl")
    tail.new()
    flags = (upload_flag, plans_flag)
    common = (ctx, tmp, api, prep.estop_plans)

    log(f"quiet: {args.quiet_trials} E-stop trials")
    quiet = EstopRun()
    estop_trials(api, prep.estop_plans, args.quiet_trials, tail, quiet, rng, *flags, "quiet")
    clear_all(api, robots)

    soak_specs: list[tuple[str, Callable[..., None], tuple[Any, ...]]] = []
    for k, first in enumerate(range(0, args.writers, CLIENTS_PER_PROCESS)):
        n = min(CLIENTS_PER_PROCESS, args.writers - first)
        streams = args.streams if k == 0 else 0
        soak_specs.append(
            (
                f"mixed-{k}",
                mixed_clients,
                (srv.url, operator["token"], n, streams, mix, others, args.interval, first),
            )
        )
    soak: EstopRun = EstopRun()
    soak_load: dict[str, Any] = {}
    if "soak" in args.phases:
        soak, soak_load = phase(
            "soak", soak_specs, lambda: True, *common, args.trials, tail, rng, flags,
            args.trial_budget_s, robots, args.phase_s,
        )  # fmt: skip

    up_specs: list[tuple[str, Callable[..., None], tuple[Any, ...]]] = [
        ("upload", upload_load, (srv.url, operator["token"], str(cloud), upload_flag)),
        ("planning", planning_load, (srv.url, operator["token"], heavy, args.plans, plans_flag)),
    ]
    for k, first in enumerate(range(0, args.pollers, CLIENTS_PER_PROCESS)):
        n = min(CLIENTS_PER_PROCESS, args.pollers - first)
        up_specs.append(
            (f"reads-{k}", read_clients, (srv.url, viewer["token"], n, mix, 0.5, first))
        )
    upload: EstopRun = EstopRun()
    up_load: dict[str, Any] = {}
    if "upload" in args.phases:
        upload, up_load = phase(
            "upload", up_specs, lambda: bool(upload_flag.value) and plans_flag.value >= args.plans,
            *common, args.trials, tail, rng, flags, args.trial_budget_s, robots, args.phase_s,
        )  # fmt: skip
    api.close()

    q = stats(quiet)
    rows = {"quiet": q, "soak": stats(soak), "upload": stats(upload)}
    during = EstopRun(trials=[t for t in upload.trials if t.upload_in_flight])
    if during.trials:
        rows["…upload body in flight"] = stats(during)
    print(f"\nE-stop on a crowded machine ({time.strftime('%Y-%m-%d %H:%M')}, this machine)")
    print(f"  soak: {args.writers} operators + {args.streams} event streams: {soak_load}")
    print(f"  upload: {args.upload_mb:.0f} MiB loop, {args.pollers} pollers, {args.plans} plans:")
    print(f"          {up_load}")
    print(
        f"{'phase':8} {'n':>4} {'resp p50':>9} {'resp p95':>9} {'×quiet':>7} "
        f"{'stop p50':>9} {'stop p95':>9} {'×quiet':>7} {'in server p95':>14} {'record p95':>11}"
    )
    met = True
    for name, s in rows.items():
        print(
            f"{name:8.22} {int(s['n']):4d} {fmt(s['response_p50'])}ms {fmt(s['response_p95'])}ms "
            f"{ratio(s['response_p95'], q['response_p95']):>7} {fmt(s['stop_p50'])}ms "
            f"{fmt(s['stop_p95'])}ms {ratio(s['stop_p95'], q['stop_p95']):>7} "
            f"{fmt(s['server_p95'])}ms {fmt(s['record_p95'])}ms"
        )
        if name in ("soak", "upload") and name in args.phases:
            met &= s["n"] > 0 and max(s["response_p95"], s["stop_p95"]) < TARGET_P95_MS
    print(f"target: p95 < {TARGET_P95_MS:.0f} ms (response and stop) under soak and upload: "
          f"{'met' if met else 'MISSED'}")  # fmt: skip
    return 0 if met else 1


if __name__ == "__main__":
    raise SystemExit(main())
