"""Every plan kind's default plan through the API ("< 3 s for each
default plan").  Run on demand:

    .venv/bin/python tests/benchmarks/bench_defaults.py [--repeats 3] [--kinds a,b]

Starts ``python -m server.cli serve`` on a free loopback port with a fresh
data directory (process job mode, the shipped default), submits each kind's
empty params one plan at a time, ``--repeats`` times, and prints per kind:
the median wall time from the submit to a terminal state (what an operator
waits for, polling every 20 ms), the median ``planning_time_s`` the planner
measured itself, the plan's state and failed checks, and the ratio of the
median wall time to the issue's 3 s target (the named baseline: no earlier
code is patched in here; the earlier code's figures are in the issue).
"""

from __future__ import annotations

import argparse
import os
import signal
import socket
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import httpx

ROOT = Path(__file__).resolve().parents[2]
TARGET_S = 3.0
TERMINAL = {"planned", "rejected", "failed", "cancelled"}


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def wait_for(pred: Any, timeout: float, what: str) -> Any:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        v = pred()
        if v:
            return v
        time.sleep(0.1)
    raise SystemExit(f"timed out waiting for {what}")


def start(tmp: Path) -> tuple[subprocess.Popen[bytes], str, str]:
    port = free_port()
    env = dict(os.environ)
    env.update(
        {
            "STEELPATH_DATA": str(tmp / "var"),
            "STEELPATH_HOST": "127.0.0.1",
            "STEELPATH_PORT": str(port),
            "STEELPATH_SCENE_PORT": "0",
            "STEELPATH_TOKEN_FILE": str(tmp / "admin.token"),
        }
    )
    log = (tmp / "server.log").open("wb")
    proc = subprocess.Popen(
        [sys.executable, "-m", "server.cli", "serve"],
        cwd=ROOT,
        env=env,
        stdout=log,
        stderr=subprocess.STDOUT,
        start_new_session=True,
    )
    url = f"http://127.0.0.1:{port}"

    def up() -> bool:
        if proc.poll() is not None:
            raise SystemExit(f"server exited with {proc.returncode}: see {tmp / 'server.log'}")
        try:
            return httpx.get(f"{url}/api/v1/health", timeout=2).status_code == 200
        except httpx.HTTPError:
            return False

    wait_for(up, 120, "the server's /health")
    token_file = tmp / "admin.token"
    wait_for(token_file.exists, 10, "the admin token file")
    return proc, url, token_file.read_text().strip().splitlines()[-1]


def plan_once(client: httpx.Client, kind: str, timeout_s: float) -> dict[str, Any]:
    t0 = time.perf_counter()
    r = client.post("/api/v1/plans", json={"kind": kind, "params": {}})
    r.raise_for_status()
    pid = r.json()["id"]
    end = t0 + timeout_s
    while True:
        plan = client.get(f"/api/v1/plans/{pid}").json()
        if plan["state"] in TERMINAL:
            break
        if time.perf_counter() > end:
            client.post(f"/api/v1/plans/{pid}/cancel")
            plan["state"] = f"timeout ({plan['state']})"
            break
        time.sleep(0.02)
    wall = time.perf_counter() - t0
    failed = [c["name"] for c in plan.get("checks") or [] if not c["passed"]]
    return {
        "wall_s": wall,
        "planning_time_s": (plan.get("metrics") or {}).get("planning_time_s"),
        "state": plan["state"],
        "failed": failed,
        "error": plan.get("error"),
    }


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--kinds", default="", help="comma-separated kinds (default: all)")
    ap.add_argument("--timeout", type=float, default=300.0, help="per plan, seconds")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory(prefix="bench_defaults_") as td:
        proc, url, token = start(Path(td))
        try:
            with httpx.Client(
                base_url=url, headers={"Authorization": f"Bearer {token}"}, timeout=30
            ) as client:
                kinds = (
                    args.kinds.split(",")
                    if args.kinds
                    else client.get("/api/v1/health").json()["kinds"]
                )
                print(
                    f"{'kind':18s} {'runs':>4s} {'wall med s':>10s} {'planner med s':>13s} "
                    f"{'vs 3 s':>7s}  state / failed checks"
                )
                for kind in kinds:
                    runs = [plan_once(client, kind, args.timeout) for _ in range(args.repeats)]
                    walls = [r["wall_s"] for r in runs]
                    pts = [r["planning_time_s"] for r in runs if r["planning_time_s"] is not None]
                    med = statistics.median(walls)
                    pmed = f"{statistics.median(pts):13.2f}" if pts else f"{'-':>13s}"
                    states = sorted({r["state"] for r in runs})
                    failed = sorted({c for r in runs for c in r["failed"]})
                    note = ", ".join(states) + (f"; failed: {', '.join(failed)}" if failed else "")
                    errors = {r["error"] for r in runs if r["error"]}
                    if errors:
                        note += f"; error: {sorted(errors)[0]}"
                    print(
                        f"{kind:18s} {len(runs):4d} {med:10.2f} {pmed} {med / TARGET_S:6.2f}x  {note}"
                    )
        finally:
            os.killpg(proc.pid, signal.SIGTERM)
            try:
                proc.wait(20)
            except subprocess.TimeoutExpired:
                os.killpg(proc.pid, signal.SIGKILL)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
