"""Load generators for ``bench_busy.py``, each meant to run in a process of its own.

Every generator talks to a running SteelPath server over loopback HTTP only,
runs until the shared ``stop`` event is set, then writes what it measured as
one JSON object to ``out_path`` (so the measuring process never shares a GIL
or an event loop with the load):

- :func:`read_clients` — ``clients`` asyncio coroutines on one
  ``httpx.AsyncClient`` (one connection each), each polling a random read of
  the mix every ``interval_s`` (closed loop when 0) and recording
  ``(start monotonic, label, latency ms, status)`` per read; a read that
  raised (timeout, reset) is kept with its elapsed time and status ``-1``.
- :func:`planning_load` — keeps ``in_flight`` plans of the given kinds queued
  or planning, submitting the next kind (round robin) as one finishes.
- :func:`upload_load` — POSTs one file as multipart ``file`` to
  ``/api/v1/clouds`` in a loop (streamed from disk by httpx) and deletes each
  stored cloud so the disk does not fill.

Every entry point takes the stop event and its output path last.  ``busy`` flags (``multiprocessing.Value('i')``) tell the measuring process
what is in flight at any instant: the number of plans in flight, and 1
while an upload request is open.

:func:`write_xyz` makes the random XYZ text cloud the upload sends.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import math
import random
import re
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import httpx

TERMINAL_PLAN_STATES = frozenset({"planned", "rejected", "failed", "cancelled"})
#: A dispatch refused because a run (e.g. one an E-stop interrupted) holds the robot.
BUSY = re.compile(r"busy with execution (ex_[0-9a-z]+)")


def percentile(values: Sequence[float], q: float) -> float:
    """Nearest-rank percentile (``q`` in 0–100) of ``values``; NaN when empty."""
    if not values:
        return math.nan
    if not 0 <= q <= 100:
        raise ValueError(f"percentile q must be within 0..100, got {q}")
    ordered = sorted(values)
    rank = max(1, math.ceil(q / 100 * len(ordered)))
    return float(ordered[rank - 1])


def write_xyz(path: Path, target_mb: float, *, seed: int = 0, chunk_rows: int = 400_000) -> Path:
    """Write ``path`` as ``x y z`` text lines of uniform random points, about ``target_mb`` MiB.

    Points are in a 20 m × 5 m × 3 m box with millimetre-and-below digits,
    written chunk by chunk (``np.savetxt``) so memory stays at one chunk.
    """
    import numpy as np

    if target_mb <= 0:
        raise ValueError(f"upload size must be positive, got {target_mb} MiB")
    target = int(target_mb * 1024 * 1024)
    rng = np.random.default_rng(seed)
    scale = np.array([20.0, 5.0, 3.0])
    tmp = path.with_name(path.name + ".part")
    with tmp.open("wb") as fh:
        while fh.tell() < target:
            pts = rng.random((chunk_rows, 3)) * scale
            np.savetxt(fh, pts, fmt="%.5f")
        fh.truncate(target)  # cut the last chunk back to the asked size ...
    with tmp.open("rb+") as fh:  # ... at a line boundary, so every line parses
        fh.seek(max(0, target - 64))
        tail = fh.read()
        cut = tail.rfind(b"\n")
        fh.truncate(max(0, target - 64) + cut + 1)
    tmp.replace(path)
    return path


def _dump(out_path: str, payload: dict[str, Any]) -> None:
    tmp = Path(out_path + ".tmp")
    tmp.write_text(json.dumps(payload), encoding="utf-8")
    tmp.replace(out_path)


# --------------------------------------------------------------------- reads
def read_paths(plan_ids: Sequence[str]) -> list[tuple[str, str]]:
    """The read mix as ``(label, path)``: three lists, health and four plan details."""
    if not plan_ids:
        raise ValueError("the read mix needs at least one plan id for GET /plans/{id}")
    mix = [
        ("plans", "/api/v1/plans"),
        ("robots", "/api/v1/robots"),
        ("health", "/api/v1/health"),
        ("executions", "/api/v1/executions"),
    ]
    # Four detail slots, so a console's per-item reads weigh as much as its list reads.
    mix += [("plan", f"/api/v1/plans/{plan_ids[i % len(plan_ids)]}") for i in range(4)]
    return mix


async def _read_client(
    client: httpx.AsyncClient,
    mix: list[tuple[str, str]],
    interval_s: float,
    stop: Any,
    seed: int,
    out: list[tuple[float, str, float, int]],
    errors: list[str],
) -> None:
    rng = random.Random(seed)
    # Desynchronise the clients so they do not all poll in the same instant.
    await asyncio.sleep(rng.uniform(0, interval_s))
    while not stop.is_set():
        label, path = rng.choice(mix)
        t0 = time.monotonic()
        try:
            r = await client.get(path)
            code = r.status_code
        except httpx.HTTPError as exc:
            code = -1
            errors.append(f"{label} {type(exc).__name__}: {exc}")
        t1 = time.monotonic()
        out.append((t0, label, (t1 - t0) * 1e3, code))
        if interval_s > 0:
            await asyncio.sleep(max(0.0, interval_s - (t1 - t0)) * rng.uniform(0.8, 1.2))
        else:
            await asyncio.sleep(0)


async def _read_main(
    url: str,
    token: str,
    clients: int,
    mix: list[tuple[str, str]],
    interval_s: float,
    first_seed: int,
    stop: Any,
    errors: list[str],
) -> list[tuple[float, str, float, int]]:
    out: list[tuple[float, str, float, int]] = []
    limits = httpx.Limits(max_connections=clients, max_keepalive_connections=clients)
    async with httpx.AsyncClient(
        base_url=url,
        headers={"Authorization": f"Bearer {token}"},
        timeout=60.0,
        limits=limits,
    ) as client:
        tasks = [
            asyncio.create_task(
                _read_client(client, mix, interval_s, stop, first_seed + i, out, errors)
            )
            for i in range(clients)
        ]
        await asyncio.gather(*tasks)
    return out


def read_clients(
    url: str,
    token: str,
    clients: int,
    mix: list[tuple[str, str]],
    interval_s: float,
    first_seed: int,
    stop: Any,
    out_path: str,
) -> None:
    """Process entry: ``clients`` concurrent pollers until ``stop``; results to ``out_path``.

    Client ``i`` draws its reads with seed ``first_seed + i``.
    """
    if clients < 1:
        raise ValueError(f"clients must be >= 1, got {clients}")
    errors: list[str] = []
    samples = asyncio.run(
        _read_main(url, token, clients, mix, interval_s, first_seed, stop, errors)
    )
    _dump(out_path, {"samples": samples, "errors": errors})


# ------------------------------------------------------------------ planning
def planning_load(
    url: str,
    token: str,
    kinds: list[str],
    in_flight: int,
    busy: Any,
    stop: Any,
    out_path: str,
) -> None:
    """Process entry: keep ``in_flight`` plans of ``kinds`` queued/planning until ``stop``."""
    if not kinds or in_flight < 1:
        raise ValueError("planning load needs at least one kind and in_flight >= 1")
    finished: list[dict[str, Any]] = []
    errors: list[str] = []
    live: dict[str, tuple[str, float]] = {}
    nxt = 0
    with httpx.Client(
        base_url=url, headers={"Authorization": f"Bearer {token}"}, timeout=120.0
    ) as c:
        while not stop.is_set():
            while len(live) < in_flight and not stop.is_set():
                kind = kinds[nxt % len(kinds)]
                nxt += 1
                try:
                    r = c.post("/api/v1/plans", json={"kind": kind, "params": {}})
                except httpx.HTTPError as exc:
                    errors.append(f"submit {kind}: {exc!r}")
                    break
                if r.status_code != 202:
                    errors.append(f"submit {kind}: HTTP {r.status_code} {r.text[:200]}")
                    break
                live[r.json()["id"]] = (kind, time.monotonic())
            busy.value = len(live)
            stop.wait(1.0)
            for pid, (kind, t0) in list(live.items()):
                try:
                    r = c.get(f"/api/v1/plans/{pid}")
                    state = r.json().get("state") if r.status_code == 200 else None
                except (httpx.HTTPError, ValueError) as exc:
                    errors.append(f"poll {pid}: {exc!r}")
                    continue
                if state in TERMINAL_PLAN_STATES:
                    finished.append(
                        {"kind": kind, "state": state, "s": round(time.monotonic() - t0, 2)}
                    )
                    del live[pid]
            busy.value = len(live)
        # Leave nothing planning behind this load: cancel what is still in flight.
        for pid in live:
            with contextlib.suppress(httpx.HTTPError):
                c.post(f"/api/v1/plans/{pid}/cancel")
    busy.value = 0
    _dump(out_path, {"finished": finished, "errors": errors, "left_in_flight": len(live)})


# -------------------------------------------------------------------- upload
def upload_load(url: str, token: str, path: str, busy: Any, stop: Any, out_path: str) -> None:
    """Process entry: POST ``path`` to ``/api/v1/clouds`` in a loop until ``stop``."""
    uploads: list[dict[str, Any]] = []
    size = Path(path).stat().st_size
    with httpx.Client(
        base_url=url, headers={"Authorization": f"Bearer {token}"}, timeout=900.0
    ) as c:
        while not stop.is_set():
            t0 = time.monotonic()
            busy.value = 1
            rec: dict[str, Any] = {"bytes": size}
            try:
                with open(path, "rb") as fh:
                    r = c.post(
                        "/api/v1/clouds", files={"file": (Path(path).name, fh, "text/plain")}
                    )
                rec["status"] = r.status_code
                if r.status_code == 201 or r.status_code == 200:
                    body = r.json()
                    rec["n_points"] = body.get("n_points")
                    with contextlib.suppress(httpx.HTTPError):
                        c.delete(f"/api/v1/clouds/{body['id']}")
                else:
                    rec["error"] = r.text[:300]
            except httpx.HTTPError as exc:
                rec["status"] = -1
                rec["error"] = repr(exc)
            finally:
                busy.value = 0
            rec["s"] = round(time.monotonic() - t0, 2)
            uploads.append(rec)
            if rec["status"] not in (200, 201):
                stop.wait(2.0)  # a refused upload must not become a busy loop
    _dump(out_path, {"uploads": uploads})


# ------------------------------------------------------------- mixed writes
async def _writer(
    client: httpx.AsyncClient,
    mix: list[tuple[str, str]],
    dispatch: list[tuple[str, str]],
    interval_s: float,
    stop: Any,
    seed: int,
    out: list[tuple[float, str, float, int]],
    errors: list[str],
) -> None:
    """One console-like operator: reads, plans a small route, approves it,
    dispatches a prepared plan to its robot (clearing that robot's E-stop
    first when it is latched) and reads again, each request timed."""
    rng = random.Random(seed)
    await asyncio.sleep(rng.uniform(0, interval_s))

    async def call(label: str, method: str, path: str, body: Any = None) -> httpx.Response | None:
        t0 = time.monotonic()
        try:
            r = await client.request(method, path, json=body)
            code = r.status_code
        except httpx.HTTPError as exc:
            r, code = None, -1
            errors.append(f"{label} {type(exc).__name__}: {exc}")
        t1 = time.monotonic()
        out.append((t0, label, (t1 - t0) * 1e3, code))
        await asyncio.sleep(max(0.0, interval_s - (t1 - t0)) * rng.uniform(0.8, 1.2))
        return r

    n = 0
    while not stop.is_set():
        n += 1
        for _ in range(rng.randint(1, 3)):
            label, path = rng.choice(mix)
            await call(label, "GET", path)
        length = rng.uniform(1.0, 4.0)
        params = {
            "nodes": {"s": [0.0, 0.0, 0.0], "e": [length, 0.0, 0.0]},
            "edges": [["s", "e"]],
            "start": "s",
            "end": "e",
            "max_length_m": length + 1.0,
        }
        r = await call("submit", "POST", "/api/v1/plans", {"kind": "demo.route", "params": params})
        if r is not None and r.status_code == 202:
            pid = r.json()["id"]
            for _ in range(40):
                if stop.is_set():
                    break
                got = await call("plan", "GET", f"/api/v1/plans/{pid}")
                state = (
                    got.json().get("state") if got is not None and got.status_code == 200 else None
                )
                if state in TERMINAL_PLAN_STATES:
                    if state == "planned":
                        await call("approve", "POST", f"/api/v1/plans/{pid}/approve", {})
                    break
        if dispatch and not stop.is_set():
            plan_id, robot = dispatch[n % len(dispatch)]
            st = await call("robot", "GET", f"/api/v1/robots/{robot}/state")
            if st is not None and st.status_code == 200 and st.json().get("state") != "ready":
                await call("clear", "POST", f"/api/v1/robots/{robot}/clear-estop")
            r = await call(
                "dispatch", "POST", f"/api/v1/plans/{plan_id}/dispatch", {"robot": robot}
            )
            busy = BUSY.search(r.text) if r is not None and r.status_code == 409 else None
            if busy:  # a run an E-stop interrupted holds the robot: resume it, as an operator
                await call("resume", "POST", f"/api/v1/executions/{busy.group(1)}/resume", {})


async def _stream(
    client: httpx.AsyncClient, stop: Any, counts: list[int], errors: list[str]
) -> None:
    """An event-stream follower (the console's live updates): counts the lines
    read, reconnecting when the stream ends."""
    while not stop.is_set():
        try:
            async with client.stream("GET", "/api/v1/events", timeout=None) as r:
                async for _ in r.aiter_lines():
                    counts[0] += 1
                    if stop.is_set():
                        return
        except httpx.HTTPError as exc:
            errors.append(f"events {type(exc).__name__}: {exc}")
            await asyncio.sleep(1.0)


async def _mixed_main(
    url: str,
    token: str,
    writers: int,
    streams: int,
    mix: list[tuple[str, str]],
    dispatch: list[tuple[str, str]],
    interval_s: float,
    first_seed: int,
    stop: Any,
    errors: list[str],
    counts: list[int],
) -> list[tuple[float, str, float, int]]:
    out: list[tuple[float, str, float, int]] = []
    limits = httpx.Limits(max_connections=writers + streams, max_keepalive_connections=writers)
    async with httpx.AsyncClient(
        base_url=url, headers={"Authorization": f"Bearer {token}"}, timeout=60.0, limits=limits
    ) as client:
        tasks = [
            asyncio.create_task(
                _writer(client, mix, dispatch, interval_s, stop, first_seed + i, out, errors)
            )
            for i in range(writers)
        ]
        tasks += [
            asyncio.create_task(_stream(client, stop, counts, errors)) for _ in range(streams)
        ]
        await asyncio.gather(*tasks[:writers])
        for t in tasks[writers:]:
            t.cancel()
        await asyncio.gather(*tasks[writers:], return_exceptions=True)
    return out


def mixed_clients(
    url: str,
    token: str,
    writers: int,
    streams: int,
    mix: list[tuple[str, str]],
    dispatch: list[tuple[str, str]],
    interval_s: float,
    first_seed: int,
    stop: Any,
    out_path: str,
) -> None:
    """Process entry: ``writers`` operators mixing reads, plan submits,
    approvals, clears and dispatches (``dispatch``: ``(plan id, robot)``
    pairs of approved plans), and ``streams`` event-stream followers, until
    ``stop``; every request's ``(start, label, ms, status)`` to ``out_path``."""
    if writers < 1 or streams < 0:
        raise ValueError(
            f"mixed load needs writers >= 1 and streams >= 0, got {writers}, {streams}"
        )
    errors: list[str] = []
    counts = [0]
    samples = asyncio.run(
        _mixed_main(
            url,
            token,
            writers,
            streams,
            mix,
            dispatch,
            interval_s,
            first_seed,
            stop,
            errors,
            counts,
        )
    )
    _dump(out_path, {"samples": samples, "errors": errors[:200], "event_lines": counts[0]})
