"""Planning jobs in worker processes: progress, cancel, planner errors, crashes."""

from __future__ import annotations

import contextlib
import gc
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import httpx
import pytest

from server.kinds import registry
from tests.support.procstat import proc_stat


@pytest.fixture
def papi(make_api, monkeypatch):
    monkeypatch.setenv("STEELPATH_EXTRA_KINDS", "tests.support.kinds")
    registry.cache_clear()
    yield make_api(job_mode="process", job_workers=2)
    registry.cache_clear()


def _tick(plan: dict) -> int:
    """The job's own progress counter from its stage ("tick N"), 0 before the first."""
    stage = plan["stage"]
    return int(stage.split()[1]) if stage.startswith("tick ") else 0


def _poll(papi, pid: str, ok, timeout: float = 30.0) -> dict:
    """Re-read the plan (pausing between reads) until ``ok(plan)``."""
    deadline = time.monotonic() + timeout
    while True:
        plan = papi.get(f"/api/v1/plans/{pid}").json()
        if ok(plan):
            return plan
        assert time.monotonic() < deadline, f"plan never satisfied the condition: {plan}"
        time.sleep(0.05)


def test_process_jobs_progress_and_cancel(papi) -> None:
    pid = papi.submit("test.job", {"seconds": 60})["id"]
    papi.wait(pid, until=("planning",), timeout=60)
    # Progress advances while the job runs in another process: two reads
    # see two different ticks of the worker's counter.
    first = _poll(papi, pid, lambda p: _tick(p) >= 1)
    later = _poll(papi, pid, lambda p: _tick(p) > _tick(first))
    assert 0 <= first["progress"] <= later["progress"] < 1
    # The HTTP server stays responsive while a job burns a worker: health is
    # answered, and only then is the (60 s) job seen still running — had the
    # request waited for the worker, the job would have finished first.
    assert papi.get("/api/v1/health").status_code == 200
    during = papi.get(f"/api/v1/plans/{pid}").json()
    assert during["state"] == "planning" and during["progress"] < 1, during
    r = papi.post(f"/api/v1/plans/{pid}/cancel")
    assert r.status_code == 200
    done = papi.wait(pid, timeout=30)
    assert done["state"] == "cancelled"
    assert any(a["action"] == "cancel" for a in done["audit"])


def test_process_planner_exception_fails_plan(papi) -> None:
    plan = papi.wait(papi.submit("test.job", {"mode": "raise"})["id"], timeout=60)
    assert plan["state"] == "failed"
    assert plan["error"] == "RuntimeError: planner blew up on purpose"
    assert papi.wait(papi.submit("demo.route")["id"], timeout=60)["state"] == "planned"


def test_worker_crash_fails_plan_and_pool_recovers(papi) -> None:
    plan = papi.wait(papi.submit("test.job", {"mode": "crash"})["id"], timeout=60)
    assert plan["state"] == "failed" and "crashed" in plan["error"]
    assert papi.wait(papi.submit("demo.route")["id"], timeout=60)["state"] == "planned"


def test_unstorable_result_fails_cleanly(papi) -> None:
    plan = papi.wait(papi.submit("test.job", {"mode": "nan"})["id"], timeout=60)
    assert plan["state"] == "failed" and "could not be stored" in plan["error"]


# ------------------------------------------------------- workers
def _cmdline(pid: int) -> str:
    try:
        return Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode()
    except OSError:
        return ""


def _children(ppid: int) -> list[int]:
    out = []
    for name in os.listdir("/proc"):
        if name.isdigit():
            st = proc_stat(int(name))
            if st is not None and st.ppid == ppid and st.state != "Z":
                out.append(int(name))
    return out


def _alive(pid: int) -> bool:
    st = proc_stat(pid)
    return st is not None and st.state != "Z"  # a zombie has exited (its reaper is just slow)


@pytest.mark.slow  # starts a whole server process (~1 min on a loaded 2-core machine)
@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")
def test_workers_are_niced_and_die_with_a_killed_server(tmp_path) -> None:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    token_file = tmp_path / "admin.token"
    env = {
        **os.environ,
        "STEELPATH_DATA": str(tmp_path / "var"),
        "STEELPATH_PORT": str(port),
        "STEELPATH_SCENE_PORT": "0",
        "STEELPATH_EMULATORS": "false",
        "STEELPATH_JOB_MODE": "process",
        "STEELPATH_JOB_WORKERS": "2",
        "STEELPATH_TOKEN_FILE": str(token_file),
    }
    exe = Path(sys.executable).with_name("steelpath")
    server = subprocess.Popen(
        [str(exe), "serve"], env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL
    )
    spawned: list[int] = []
    try:
        base = f"http://127.0.0.1:{port}/api/v1"
        deadline = time.monotonic() + 90
        while True:
            assert server.poll() is None, "the server exited during start-up"
            try:
                if httpx.get(f"{base}/health", timeout=2).status_code == 200:
                    break
            except httpx.HTTPError:
                pass
            assert time.monotonic() < deadline, "server did not start"
            time.sleep(0.2)
        auth = {"Authorization": f"Bearer {token_file.read_text().strip()}"}
        r = httpx.post(f"{base}/plans", json={"kind": "demo.route"}, headers=auth, timeout=30)
        assert r.status_code == 202, r.text
        plan_id = r.json()["id"]
        while httpx.get(f"{base}/plans/{plan_id}", headers=auth, timeout=30).json()["state"] in (
            "queued",
            "planning",
        ):
            assert time.monotonic() < deadline, "the plan did not finish"
            time.sleep(0.2)
        spawned = [p for p in _children(server.pid) if "multiprocessing" in _cmdline(p)]
        base_nice = os.getpriority(os.PRIO_PROCESS, 0)  # the server inherits ours
        assert proc_stat(server.pid)[2] == base_nice  # only the workers are niced
        nice = min(base_nice + 10, 19)
        workers = [p for p in spawned if (proc_stat(p) or ("", 0, 0))[2] == nice]
        assert len(workers) == 2, [(p, proc_stat(p), _cmdline(p)) for p in spawned]
        server.kill()  # SIGKILL: no shutdown code runs
        server.wait(10)
        deadline = time.monotonic() + 10
        while any(_alive(p) for p in spawned) and time.monotonic() < deadline:
            time.sleep(0.1)
        left = [(p, _cmdline(p)) for p in spawned if _alive(p)]
        assert not left, f"processes outlived the killed server: {left}"
    finally:
        if server.poll() is None:
            server.kill()
            server.wait(10)
        for p in spawned:  # never leave a process behind, even when the test fails
            if _alive(p):
                with contextlib.suppress(ProcessLookupError):
                    os.kill(p, signal.SIGKILL)


@pytest.mark.parametrize("preload", [True, False])
def test_workers_preload_every_kind_before_their_first_plan(preload: bool) -> None:
    """With ``preload`` (the default setting) a worker has imported every plan
    kind's module, and so its planners, before it runs anything; without it, a
    fresh worker has none of them."""
    from concurrent.futures import ProcessPoolExecutor
    from multiprocessing import get_context

    from server.jobs import _worker_init
    from server.kinds import KIND_MODULES
    from tests.support.procstat import loaded_modules

    with ProcessPoolExecutor(
        1,
        mp_context=get_context("spawn"),
        initializer=_worker_init,
        initargs=(os.getpid(), preload),
    ) as pool:
        loaded = pool.submit(loaded_modules, ("server.kinds.", "planners.")).result(timeout=120)
        frozen = pool.submit(gc.get_freeze_count).result(timeout=60)
    kinds = set(KIND_MODULES) & set(loaded)
    if preload:
        assert kinds == set(KIND_MODULES)
        assert "planners.switching.switch_result" in loaded
        # the preloaded objects are out of the cyclic GC's way
        assert frozen > 10_000
    else:
        assert kinds == set()
        assert frozen == 0


def test_workers_run_one_blas_thread() -> None:
    """A planning worker multiplies with one BLAS thread (a second one waits
    for a core that the server or the other worker holds)."""
    from concurrent.futures import ProcessPoolExecutor
    from multiprocessing import get_context

    from threadpoolctl import threadpool_info

    from server.jobs import WORKER_BLAS_THREADS, _worker_init

    with ProcessPoolExecutor(
        1, mp_context=get_context("spawn"), initializer=_worker_init, initargs=(os.getpid(), False)
    ) as pool:
        info = pool.submit(threadpool_info).result(timeout=60)
    blas = [i for i in info if i["user_api"] == "blas"]
    assert blas, info  # numpy's OpenBLAS is loaded in the worker
    assert all(i["num_threads"] == WORKER_BLAS_THREADS == 1 for i in blas)
