"""A real Dask cluster on loopback for the tests: Dask's own CLI, one process per part.

``dask scheduler`` and ``dask worker`` (each worker under its nanny, which
starts a fresh worker process when one dies, as in production) run from this
repository's venv, with this checkout importable and the test-only plan kinds
(``STEELPATH_EXTRA_KINDS=tests.support.kinds``) loaded.
"""

from __future__ import annotations

import contextlib
import os
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[2]
DASK = Path(sys.executable).with_name("dask")


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def worker_env(extra: dict[str, str] | None = None) -> dict[str, str]:
    """Environment of the scheduler and workers: this checkout on the path, test kinds."""
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(p for p in (str(ROOT), env.get("PYTHONPATH", "")) if p)
    env["PYTHONDONTWRITEBYTECODE"] = "1"
    env["STEELPATH_EXTRA_KINDS"] = "tests.support.kinds"
    # The workers' Dask configuration as deployed (docker/dask/steelpath.yaml:
    # no MALLOC_TRIM_THRESHOLD_, which made planning ~1.6x slower).
    env["DASK_CONFIG"] = str(ROOT / "docker" / "dask")
    env.update(extra or {})
    return env


@dataclass
class DaskCluster:
    """A scheduler and named workers started by :func:`dask_cluster`."""

    address: str
    logs: Path
    procs: dict[str, subprocess.Popen[bytes]] = field(default_factory=dict)
    _client: Any = None

    @property
    def client(self) -> Any:
        """A client of the test itself (to look workers up; plans go through the API)."""
        if self._client is None:
            from distributed import Client

            self._client = Client(self.address, timeout=30, set_as_default=False)
        return self._client

    def workers(self) -> dict[str, str]:
        """``{name: address}`` of the workers the scheduler has now."""
        info = self.client.scheduler_info(n_workers=-1)["workers"]
        return {str(w["name"]): addr for addr, w in info.items()}

    def wait_workers(self, n: int, timeout: float = 60.0) -> dict[str, str]:
        deadline = time.monotonic() + timeout
        while True:
            ws = self.workers()
            if len(ws) >= n:
                return ws
            assert time.monotonic() < deadline, f"only {len(ws)} Dask workers after {timeout}s"
            time.sleep(0.1)

    def worker_pid(self, address: str) -> int:
        """The pid of the worker process (not its nanny) at ``address``."""
        pids = self.client.run(os.getpid, workers=[address])
        return int(pids[address])

    def kill_worker(self, address: str) -> int:
        """SIGKILL the worker process at ``address`` (its nanny starts another)."""
        pid = self.worker_pid(address)
        os.kill(pid, signal.SIGKILL)
        return pid

    def close(self) -> None:
        if self._client is not None:
            with contextlib.suppress(Exception):
                self._client.close(timeout=5)
        for proc in reversed(list(self.procs.values())):
            _stop(proc)


def _stop(proc: subprocess.Popen[bytes]) -> None:
    """End a CLI process this fixture started, and the processes it started (its group)."""
    if proc.poll() is not None:
        return
    with contextlib.suppress(ProcessLookupError):
        os.killpg(proc.pid, signal.SIGTERM)
    try:
        proc.wait(timeout=10)
    except subprocess.TimeoutExpired:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(proc.pid, signal.SIGKILL)
        proc.wait(timeout=10)


def _spawn(args: list[str], log: Path, env: dict[str, str]) -> subprocess.Popen[bytes]:
    with open(log, "wb") as out:
        return subprocess.Popen(
            [str(DASK), *args],
            cwd=ROOT,
            env=env,
            stdout=out,
            stderr=subprocess.STDOUT,
            start_new_session=True,  # its own group: torn down with its nanny's children
        )


def _scheduler_args(port: int) -> list[str]:
    return ["scheduler", "--host", "127.0.0.1", "--port", str(port), "--no-dashboard"]


def _worker_args(address: str, name: str, logs: Path) -> list[str]:
    return [
        "worker",
        address,
        "--nworkers",
        "1",
        "--nthreads",
        "1",
        "--no-dashboard",
        "--name",
        name,
        "--host",
        "127.0.0.1",
        "--local-directory",
        str(logs / name),
        "--preload",
        "server.dask_jobs",  # imports the plan kinds (dask_setup)
    ]


def _wait_scheduler(cluster: DaskCluster, port: int, timeout: float) -> None:
    deadline = time.monotonic() + timeout
    while True:
        with contextlib.suppress(OSError, TimeoutError):
            socket.create_connection(("127.0.0.1", port), timeout=1).close()
            return
        dead = {n: p.returncode for n, p in cluster.procs.items() if p.poll() is not None}
        assert not dead, f"Dask processes exited: {dead} (logs in {cluster.logs})"
        assert time.monotonic() < deadline, f"no Dask scheduler after {timeout}s"
        time.sleep(0.1)


def kill_scheduler(cluster: DaskCluster) -> None:
    """Kill the scheduler (SIGKILL); its workers exit by themselves soon after."""
    with contextlib.suppress(ProcessLookupError):
        os.killpg(cluster.procs["scheduler"].pid, signal.SIGKILL)
    cluster.procs["scheduler"].wait(timeout=10)
    if cluster._client is not None:
        with contextlib.suppress(Exception):
            cluster._client.close(timeout=2)
        cluster._client = None


def start_scheduler_again(cluster: DaskCluster, timeout: float = 90.0) -> None:
    """What a supervisor (compose's ``restart: unless-stopped``, systemd) does
    after :func:`kill_scheduler`: start the scheduler again on its address, and
    the workers, which exit when their scheduler is gone."""
    port = int(cluster.address.rsplit(":", 1)[1])
    names = [n for n in cluster.procs if n != "scheduler"]
    for name in names:
        _stop(cluster.procs.pop(name))
    env = worker_env()
    cluster.procs["scheduler"] = _spawn(
        _scheduler_args(port), cluster.logs / "scheduler-2.log", env
    )
    _wait_scheduler(cluster, port, timeout)
    for name in names:
        cluster.procs[name] = _spawn(
            _worker_args(cluster.address, name, cluster.logs),
            cluster.logs / f"{name}-2.log",
            env,
        )
    cluster.wait_workers(len(names), timeout)


@contextlib.contextmanager
def dask_cluster(logs: Path, workers: int = 2, timeout: float = 90.0) -> Iterator[DaskCluster]:
    """A scheduler and ``workers`` single-threaded workers (``w1``, ``w2``…) on loopback."""
    logs.mkdir(parents=True, exist_ok=True)
    port = free_port()
    address = f"tcp://127.0.0.1:{port}"
    env = worker_env()
    cluster = DaskCluster(address, logs)
    try:
        cluster.procs["scheduler"] = _spawn(_scheduler_args(port), logs / "scheduler.log", env)
        for i in range(1, workers + 1):
            name = f"w{i}"
            cluster.procs[name] = _spawn(
                _worker_args(address, name, logs), logs / f"{name}.log", env
            )
        _wait_scheduler(cluster, port, timeout)
        cluster.wait_workers(workers, timeout)
        yield cluster
    finally:
        cluster.close()
