"""Planning on a Dask cluster: 40 plans submitted at once, time
until all are planned, with 1 and with 2 Dask workers.  Run on demand:

    .venv/bin/python tests/benchmarks/bench_dask.py [--plans 40] [--kind ara.navigate]

For each worker count it starts a real cluster on loopback with Dask's CLI
(``dask scheduler``, ``dask worker --nthreads 1 --preload server.dask_jobs``, the
workers configured by ``docker/dask/steelpath.yaml`` as deployed),
builds the app on a fresh data directory with ``dask_scheduler`` set, submits
``--plans`` plans of ``--kind`` (default params) through the API as fast as
it can, and polls until none is queued or planning.  The same is done with
the local process pool (``job_workers`` 1 and 2, the shipped default) as the
named baseline.  Printed: wall time, plans per second, the 2-vs-1 ratio of
each engine, and Dask's time relative to the local pool's.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[2]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from fastapi.testclient import TestClient  # noqa: E402

from server.app import create_app  # noqa: E402
from server.auth import create_token  # noqa: E402
from server.settings import Settings  # noqa: E402
from tests.support.dask_cluster import dask_cluster  # noqa: E402


def run_batch(data: Path, n: int, kind: str, **settings: Any) -> tuple[float, dict[str, int]]:
    """Seconds from the first submit until all ``n`` plans ended, and their states."""
    app = create_app(
        Settings(data=data, scene_port=0, emulators=False, **settings), start_scene=False
    )
    with TestClient(app) as client:
        token = create_token(app.state.services.store, "bench", "operator", "bench")[1]
        h = {"Authorization": f"Bearer {token}"}
        t0 = time.perf_counter()
        ids = []
        for _ in range(n):
            r = client.post("/api/v1/plans", headers=h, json={"kind": kind, "params": {}})
            assert r.status_code == 202, r.text
            ids.append(r.json()["id"])
        while True:
            plans = client.get("/api/v1/plans", headers=h, params={"limit": n}).json()
            states = [p["state"] for p in plans]
            if len(states) == n and not {"queued", "planning"} & set(states):
                break
            time.sleep(0.05)
        wall = time.perf_counter() - t0
    counts: dict[str, int] = {}
    for s in states:
        counts[s] = counts.get(s, 0) + 1
    return wall, counts


def _load() -> str:
    """The 1-minute load average: other work on the machine skews every figure."""
    return f"load {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--plans", type=int, default=40)
    ap.add_argument("--kind", default="ara.navigate")
    ap.add_argument("--no-local", action="store_true", help="skip the local-pool baseline")
    args = ap.parse_args()
    results: dict[tuple[str, int], float] = {}
    with tempfile.TemporaryDirectory(prefix="bench-dask-") as tmp_s:
        tmp = Path(tmp_s)
        for workers in (1, 2):
            with dask_cluster(tmp / f"cluster{workers}", workers=workers) as cluster:
                wall, counts = run_batch(
                    tmp / f"dask{workers}", args.plans, args.kind, dask_scheduler=cluster.address
                )
            results[("dask", workers)] = wall
            print(
                f"dask  {workers} worker(s): {args.plans} x {args.kind} in {wall:6.2f} s "
                f"({args.plans / wall:5.2f} plans/s) {counts} {_load()}",
                flush=True,
            )
        if not args.no_local:
            for workers in (1, 2):
                wall, counts = run_batch(
                    tmp / f"local{workers}",
                    args.plans,
                    args.kind,
                    job_mode="process",
                    job_workers=workers,
                )
                results[("local", workers)] = wall
                print(
                    f"local {workers} worker(s): {args.plans} x {args.kind} in {wall:6.2f} s "
                    f"({args.plans / wall:5.2f} plans/s) {counts} {_load()}",
                    flush=True,
                )
    for engine in ("dask", "local"):
        if (engine, 2) in results:
            ratio = results[(engine, 1)] / results[(engine, 2)]
            print(f"{engine}: 1-worker time / 2-worker time = {ratio:.2f}")
    if ("local", 2) in results:
        for w in (1, 2):
            rel = results[("dask", w)] / results[("local", w)]
            print(f"dask / local pool with {w} worker(s): {rel:.2f}")


if __name__ == "__main__":
    main()
