"""Planning jobs, off the event loop, with progress and cancellation.

Jobs run in a pool of worker *processes* by default (``STEELPATH_JOB_MODE``):
planners are CPU-bound Python/numpy and must not starve the HTTP server, and
a planner that crashes its process takes only that job down.  Workers report
``(plan_id, fraction, stage)`` through a manager queue that a listener thread
turns into stored progress and events; cancellation is cooperative: the
worker's ``progress`` call raises :class:`planners.errors.CancelledError`
once the plan's flag is set, so planners stop at their next stage boundary.

Workers run at a lower OS priority (``os.nice(10)``) than the server and its
robot links, and die with the server: each sets ``PR_SET_PDEATHSIG`` and
watches its parent pid (:func:`server.lifetime.die_with_parent`).  The
kernel sends that signal when the *thread* that forked the child exits, so
pools (and the manager) are created and their workers started eagerly on
one long-lived spawner thread, never on a short-lived request thread.
"""

from __future__ import annotations

import atexit
import contextlib
import functools
import gc
import logging
import multiprocessing as mp
import os
import queue as queue_mod
import threading
import time
import traceback
from collections.abc import Callable
from concurrent.futures import Executor, Future, ProcessPoolExecutor, ThreadPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass
from multiprocessing.managers import SyncManager
from pathlib import Path
from typing import Any

import numpy as np
from threadpoolctl import threadpool_limits

from planners.errors import CancelledError, InvalidInputError
from server.diskspace import describe, is_disk_full
from server.events import EventBus
from server.lifecycle import IllegalTransitionError, PlanState
from server.lifetime import die_with_parent, exit_without_teardown, leave_interrupts_to_parent
from server.store import NotFoundError, Store
from server.store.ownership import OwnershipStore
from server.store.plan_owners import PlanOwnerStore

log = logging.getLogger(__name__)

_STOP = ("__stop__", 0.0, "")

#: Niceness added to planning worker processes (the server and links keep 0).
WORKER_NICE = 10
#: BLAS threads per planning worker.
WORKER_BLAS_THREADS = 1


def _worker_init(parent_pid: int, preload: bool = False) -> None:
    """Process-pool initializer: lower priority, exit when the server dies, and
    (``preload``) do the imports and robot loads of every kind now."""
    die_with_parent(parent_pid)
    leave_interrupts_to_parent()
    # After the pool let this worker go (its own shutdown is over): no teardown report.
    atexit.register(exit_without_teardown)
    with contextlib.suppress(OSError):
        os.nice(WORKER_NICE)
    # One BLAS thread per worker: planners multiply small matrices, and a
    # second thread waits for a core the server or the other worker holds
    # (default ara.switch plan with the other core busy: 3.26 s with two
    # threads, 2.88 s with one; 2026-12-03).  The pool's workers use the cores.
    threadpool_limits(WORKER_BLAS_THREADS, user_api="blas")
    if preload:
        try:
            preload_kinds()
        except Exception:  # an initializer error would break the pool: plan cold instead
            log.warning("preloading the plan kinds failed", exc_info=True)
        # The preloaded modules are ~140k objects the cyclic GC would walk at
        # every full collection, and planners make garbage fast: the default
        # ara.switch plan took 4.05 s with them tracked, 3.08 s frozen
        # (2026-12-03, same machine).  They live as long as the worker anyway.
        gc.freeze()


def preload_kinds() -> float:
    """Import every plan kind (and so its planners) and load every robot.

    A fresh worker's first plan of a kind otherwise spends ~1-2 s importing
    numpy/scipy/OMPL/pinocchio modules and parsing robot descriptions before
    planning (measured: ``ara.navigate`` 3.0 s cold, 1.0 s preloaded).  A
    kind or robot that fails here fails the same way when planned, with its
    error; this only logs it.  Returns the seconds spent.
    """
    from robots.registry import available_robots, load_robot
    from server.kinds import registry

    t0 = time.perf_counter()
    registry()
    for name in available_robots():
        try:
            load_robot(name)
        except Exception:
            log.warning("preloading robot %s failed", name, exc_info=True)
    return time.perf_counter() - t0


def _manager_init(parent_pid: int) -> None:
    """The progress/cancel manager process dies with the server too."""
    die_with_parent(parent_pid)


def _warm(seconds: float) -> None:
    """A no-op task that makes the pool start one worker per submission."""
    time.sleep(seconds)


class _Spawner:
    """Runs callables on one long-lived daemon thread (the parent of every worker)."""

    def __init__(self) -> None:
        self._q: queue_mod.Queue[tuple[Callable[[], Any], Future[Any]] | None] = queue_mod.Queue()
        self._thread = threading.Thread(target=self._run, name="job-spawner", daemon=True)
        self._thread.start()

    def call(self, fn: Callable[[], Any]) -> Any:
        if threading.current_thread() is self._thread:
            return fn()
        fut: Future[Any] = Future()
        self._q.put((fn, fut))
        return fut.result()

    def _run(self) -> None:
        while (item := self._q.get()) is not None:
            fn, fut = item
            try:
                fut.set_result(fn())
            except BaseException as exc:
                fut.set_exception(exc)

    def stop(self) -> None:
        self._q.put(None)
        self._thread.join(timeout=5)


class WorkerContext:
    """The :class:`server.kinds.base.JobContext` given to a kind's ``run``."""

    def __init__(self, plan_id: str, clouds_dir: Path, progress_q: Any, cancel_flags: Any) -> None:
        self.plan_id = plan_id
        self._clouds_dir = clouds_dir
        self._q = progress_q
        self._cancel = cancel_flags

    def cancelled(self) -> bool:
        try:
            return bool(self._cancel.get(self.plan_id, False))
        except (OSError, EOFError, BrokenPipeError):  # manager gone: server is stopping
            return True

    def progress(self, fraction: float, stage: str) -> None:
        if self.cancelled():
            raise CancelledError(f"plan {self.plan_id} was cancelled during {stage!r}")
        self._q.put((self.plan_id, float(min(max(fraction, 0.0), 1.0)), str(stage)))

    def load_cloud(self, cloud_id: str) -> np.ndarray:
        path = self._clouds_dir / f"{cloud_id}.npy"
        if "/" in cloud_id or not path.is_file():
            raise InvalidInputError(f"no stored cloud with id {cloud_id!r}")
        return np.load(path, allow_pickle=False)


#: What a job returns: result, arrays, checks, metrics, program, the program's check.
JobOutput = tuple[
    dict[str, Any],
    dict[str, np.ndarray],
    list[dict[str, Any]],
    dict[str, float],
    list[dict[str, Any]] | None,
    dict[str, Any] | None,
]


def execute_job(
    kind_name: str,
    params: dict[str, Any],
    plan_id: str,
    clouds_dir: str,
    progress_q: Any,
    cancel_flags: Any,
) -> JobOutput:
    """Run one plan and compile its robot program (in a worker).

    Module-level so process pools can pickle it.  Returns the result, arrays,
    checks, metrics, the program (or ``None``) and the program's check.
    """
    from server.kinds import get_kind

    get_kind(kind_name)  # an unknown kind fails before the plan is started
    ctx = WorkerContext(plan_id, Path(clouds_dir), progress_q, cancel_flags)
    progress_q.put((plan_id, 0.0, "start"))
    return run_kind(kind_name, params, plan_id, ctx)


def run_kind(kind_name: str, params: dict[str, Any], plan_id: str, ctx: Any) -> JobOutput:
    """The pure part of a job, the same in a pool process and on a Dask worker:
    the kind's ``run`` with ``ctx`` (progress, cancel, clouds), then the compile."""
    from server.kinds import get_kind
    from server.kinds.base import drop_unknown_keys

    kind = get_kind(kind_name)
    # Rows stored before params forbade unknown keys still run (the keys are ignored).
    params, _legacy = drop_unknown_keys(kind.params_model, params)
    model = kind.params_model.model_validate(params)
    t0 = time.perf_counter()
    out = kind.run(model, ctx)
    metrics = {k: float(v) for k, v in out.metrics.items()}
    metrics.setdefault("job_time_s", time.perf_counter() - t0)
    checks = [c.model_dump() for c in out.checks]
    arrays = {k: np.asarray(v) for k, v in out.arrays.items()}
    # Compiled here, in the worker, not in the server: a long program's
    # compile and limit check is 30-150 ms of Python the web server's event
    # loop and E-stop path would otherwise wait behind.
    program, check = compile_program(
        _PlanRef(plan_id, kind_name, params), out.result, arrays, checks, metrics
    )
    return out.result, arrays, checks, metrics, program, check


@dataclass(frozen=True)
class _PlanRef:
    """What :func:`compile_program` reads of a plan while it is still planning."""

    id: str
    kind: str
    params: dict[str, Any]


def make_job_runner(
    store: Store, events: EventBus, settings: Any, server_id: str | None = None
) -> JobRunner:
    """The app's runner: on the Dask cluster of ``settings.dask_scheduler`` when
    set (imported only then), else the local pool of ``settings.job_mode``.

    ``server_id`` names this server in ``plans.planner`` (servers sharing the
    store adopt only the plans of a server silent for ``orphan_plan_s``)."""
    owner = {"server_id": server_id, "orphan_after_s": settings.orphan_plan_s}
    if settings.dask_scheduler:
        from server.dask_jobs import DaskJobRunner

        return DaskJobRunner(
            store,
            events,
            scheduler=settings.dask_scheduler,
            data_dir=Path(settings.data),
            database_url=settings.database_url,
            stuck_s=settings.dask_stuck_s,
            **owner,
        )
    return JobRunner(
        store,
        events,
        mode=settings.job_mode,
        workers=settings.job_workers,
        preload=settings.job_preload,
        **owner,
    )


class JobRunner:
    """Owns the worker pool, the progress listener and the cancel flags.

    **Several servers on one store.**  Each plan's job belongs to the server
    that submitted it (``plans.planner``, :mod:`server.store.plan_owners`).
    At start, and then every ``sweep_s`` in a thread of its own, a runner
    adopts the queued or planning plans whose server is neither itself nor
    alive (no heartbeat in ``servers`` for ``orphan_after_s``) and plans them
    again — a plan left ``planning`` is re-queued first.  So a server starting
    beside others leaves their plans alone, and a server that dies has its
    plans finished by another within about ``orphan_after_s + sweep_s``.
    """

    def __init__(
        self,
        store: Store,
        events: EventBus,
        *,
        mode: str = "process",
        workers: int = 2,
        preload: bool = False,
        server_id: str | None = None,
        orphan_after_s: float = 10.0,
        sweep_s: float = 2.0,
    ) -> None:
        self.store = store
        self.events = events
        self.mode = mode
        self.workers = workers
        self.preload = preload
        self.server_id = server_id or f"srv_local_{os.getpid()}_{id(self):x}"
        self.orphan_after_s = orphan_after_s
        self.sweep_s = sweep_s
        self._owners = PlanOwnerStore(store.db)
        self._servers = OwnershipStore(store.db)
        self._sweeping = threading.Event()
        self._sweeper: threading.Thread | None = None
        self._lock = threading.RLock()
        self._futures: dict[str, Future[Any]] = {}
        self._last_progress: dict[str, float] = {}
        self._executor: Executor | None = None
        self._manager: Any = None
        self._queue: Any = None
        self._cancel: Any = None
        self._listener: threading.Thread | None = None
        self._spawner: _Spawner | None = None
        #: Called with the plan id whenever a job ends (scene redraw, etc.).
        self.on_finished: list[Any] = []
        #: Plans whose result could not be stored for a full disk: re-queued by the
        #: sweeper once ``has_room()`` (the app's disk gauge) says space is back.
        self._disk_waiting: dict[str, str] = {}
        self.has_room: Any = lambda: True

    # ---------------------------------------------------------------- control
    def start(self) -> None:
        if self.mode == "process":
            self._spawner = _Spawner()
            self._manager = self._spawner.call(self._start_manager)
            self._queue = self._manager.Queue()
            self._cancel = self._manager.dict()
        else:
            self._queue = queue_mod.Queue()
            self._cancel = {}
        self._executor = self._new_executor()
        self._listener = threading.Thread(target=self._listen, name="job-progress", daemon=True)
        self._listener.start()
        self._recover()
        self._start_sweeper()

    @staticmethod
    def _start_manager() -> SyncManager:
        manager = SyncManager(ctx=mp.get_context("spawn"))
        manager.start(_manager_init, (os.getpid(),))
        return manager

    def _new_executor(self) -> Executor:
        if self.mode == "process":
            assert self._spawner is not None
            return self._spawner.call(self._new_pool)
        return ThreadPoolExecutor(self.workers, thread_name_prefix="planner")

    def _new_pool(self) -> ProcessPoolExecutor:
        """A pool whose workers are all started now, from the spawner thread.

        A spawn-context pool starts a worker inside ``submit`` whenever none is
        idle; ``workers`` quick tasks submitted back to back (far faster than
        a worker can start) therefore start all of them here, and later
        submissions from request threads find the pool full.
        """
        pool = ProcessPoolExecutor(
            self.workers,
            mp_context=mp.get_context("spawn"),
            initializer=_worker_init,
            initargs=(os.getpid(), self.preload),
        )
        for _ in range(self.workers):
            pool.submit(_warm, 0.05)
        return pool

    def shutdown(self) -> None:
        self._stop_sweeper()
        with self._lock:
            for pid in list(self._futures):
                self._cancel[pid] = True
        if self._executor is not None:
            self._executor.shutdown(wait=True, cancel_futures=True)
        if self._queue is not None:
            with contextlib.suppress(OSError, EOFError, BrokenPipeError):
                self._queue.put(_STOP)
        if self._listener is not None:
            self._listener.join(timeout=5)
        if self._manager is not None:
            self._manager.shutdown()
        if self._spawner is not None:
            self._spawner.stop()

    def _recover(self) -> None:
        """At start: adopt the plans a previous process (or a dead server) left
        queued or planning."""
        self.adopt_orphans()

    # ------------------------------------------------- plans of dead servers
    def adopt_orphans(self) -> list[str]:
        """Adopt and plan again every active plan whose server is not alive.

        Returns the ids adopted.  A plan another server adopted first, or that
        ended meanwhile, is skipped (the adoption is a conditional UPDATE).
        """
        cutoff = time.time() - self.orphan_after_s
        live = [s.id for s in self._servers.servers() if s.heartbeat_at >= cutoff]
        adopted = []
        for plan in self._owners.orphans(self.server_id, live):
            if plan.id in self.running() or not self._owners.adopt(plan, self.server_id):
                continue
            try:
                if plan.state == PlanState.PLANNING:
                    why = (
                        "server restarted while planning"
                        if plan.planner is None
                        else f"server {plan.planner} stopped while planning; "
                        f"adopted by {self.server_id}"
                    )
                    self._requeue(plan.id, why)
                self.submit(plan.id)
                adopted.append(plan.id)
            except (IllegalTransitionError, NotFoundError) as exc:
                log.info("plan %s changed while being adopted: %s", plan.id, exc)
        if adopted:
            log.warning("adopted %d plan(s) of stopped servers: %s", len(adopted), adopted)
        return adopted

    def _requeue(self, plan_id: str, why: str) -> None:
        self.store.transition_plan(plan_id, "requeue", "system", why, expect=PlanState.PLANNING)

    def _start_sweeper(self) -> None:
        self._sweeping.clear()
        self._sweeper = threading.Thread(target=self._sweep, name="plan-orphans", daemon=True)
        self._sweeper.start()

    def _stop_sweeper(self) -> None:
        self._sweeping.set()
        if self._sweeper is not None:
            self._sweeper.join(timeout=5)

    def _sweep(self) -> None:
        while not self._sweeping.wait(self.sweep_s):
            try:
                self.adopt_orphans()
            except Exception:  # a store hiccup must not end the sweeping
                log.exception("adopting the plans of stopped servers failed")
            self.retry_disk_waiting()

    def disk_waiting(self) -> list[str]:
        with self._lock:
            return sorted(self._disk_waiting)

    def retry_disk_waiting(self) -> list[str]:
        """Plan again, once there is room, each plan whose result a full disk refused."""
        with self._lock:
            waiting = dict(self._disk_waiting)
        if not waiting or not self.has_room():
            return []
        done = []
        for plan_id, why in waiting.items():
            try:
                self._requeue(plan_id, f"planned again: its result was refused ({why})")
            except (IllegalTransitionError, NotFoundError):
                pass  # cancelled or deleted meanwhile: nothing to plan
            except Exception as exc:  # still no room for the record: next sweep
                log.info("plan %s still waits for disk space: %s", plan_id, describe(exc))
                continue
            else:
                self.submit(plan_id)
            with self._lock:
                self._disk_waiting.pop(plan_id, None)
            done.append(plan_id)
        if done:
            log.warning("re-queued %d plan(s) after the disk had room again: %s", len(done), done)
        return done

    # ------------------------------------------------------------------- jobs
    def submit(self, plan_id: str) -> None:
        assert self._executor is not None, "JobRunner.start() was not called"
        self._owners.assign(plan_id, self.server_id)
        plan = self.store.get_plan(plan_id)
        with self._lock:
            self._cancel[plan_id] = False
            clouds = str(self.store.arrays.path("clouds"))

            def send(executor: Executor) -> Future[Any]:
                return executor.submit(
                    execute_job,
                    plan.kind,
                    plan.params,
                    plan_id,
                    clouds,
                    self._queue,
                    self._cancel,
                )

            try:
                fut = send(self._executor)
            except BrokenProcessPool:  # a crashed worker broke the pool: replace it once
                self._executor = self._new_executor()
                fut = send(self._executor)
            self._futures[plan_id] = fut
        fut.add_done_callback(functools.partial(self._finish, plan_id))

    def cancel(self, plan_id: str, actor: str) -> str:
        """Cancel a queued or running plan; returns what happened."""
        plan = self.store.get_plan(plan_id)
        if plan.state not in (PlanState.QUEUED, PlanState.PLANNING):
            # Raises the 409 with the allowed actions.
            self.store.transition_plan(plan_id, "cancel", actor)
        with self._lock:
            fut = self._futures.get(plan_id)
            self._cancel[plan_id] = True
            if fut is not None and fut.cancel():
                self._futures.pop(plan_id, None)
                self._transition(plan_id, "cancel", actor, "cancelled before it started")
                return "cancelled"
            if fut is None and plan.state == PlanState.QUEUED:
                self._transition(plan_id, "cancel", actor, "cancelled")
                return "cancelled"
        self.store.audit(actor, "plan", plan_id, "cancel-request", "stop at next stage")
        return "cancelling"

    def running(self) -> list[str]:
        with self._lock:
            return list(self._futures)

    def running_count(self) -> int:
        """How many plans are queued or planning, without the lock (``submit``
        holds it across an IPC call): safe on the event loop."""
        return len(self._futures)

    # -------------------------------------------------------------- internals
    def _transition(
        self, plan_id: str, action: str, actor: str, reason: str = "", **kw: Any
    ) -> None:
        try:
            plan = self.store.transition_plan(plan_id, action, actor, reason, **kw)
        except (IllegalTransitionError, NotFoundError) as exc:
            log.info("ignored %s of plan %s: %s", action, plan_id, exc)
            return
        self.events.publish("plan", _event_body(plan))

    def _listen(self) -> None:
        while True:
            try:
                msg = self._queue.get()
            except (OSError, EOFError, BrokenPipeError):
                return
            if msg == _STOP:
                return
            plan_id, frac, stage = msg
            try:
                self._on_progress(plan_id, frac, stage)
            except Exception:  # never let one bad message kill the listener
                log.exception("progress update for %s failed", plan_id)

    def _on_progress(self, plan_id: str, frac: float, stage: str) -> None:
        with self._lock:
            plan = self.store.get_plan(plan_id)
            if plan.state == PlanState.QUEUED:
                self._transition(plan_id, "start", "planner", "worker picked it up")
            elif plan.state != PlanState.PLANNING:
                return  # a late message for a plan that already finished
            now = time.monotonic()
            # Throttle writes: progress can arrive thousands of times a second.
            if (
                stage != plan.stage
                or now - self._last_progress.get(plan_id, 0.0) > 0.1
                or frac >= 1
            ):
                self._last_progress[plan_id] = now
                self.store.set_progress(plan_id, frac, stage)
                self.events.publish(
                    "plan", {"id": plan_id, "state": "planning", "progress": frac, "stage": stage}
                )

    def _finish(self, plan_id: str, fut: Future[Any]) -> None:
        try:
            self._finish_locked(plan_id, fut)
        finally:
            for cb in list(self.on_finished):
                try:
                    cb(plan_id)
                except Exception:
                    log.exception("on_finished callback failed for %s", plan_id)

    def _finish_locked(self, plan_id: str, fut: Future[Any]) -> None:
        with self._lock:
            self._futures.pop(plan_id, None)
            self._last_progress.pop(plan_id, None)
            with contextlib.suppress(OSError, EOFError, BrokenPipeError):
                self._cancel.pop(plan_id, None)
            try:
                plan = self.store.get_plan(plan_id)
            except NotFoundError:
                return
            if fut.cancelled():
                return
            if plan.state == PlanState.QUEUED:
                self._transition(plan_id, "start", "planner")
            exc = fut.exception()
            if exc is None:
                result, arrays, checks, metrics, program, check = fut.result()
                if check is not None:
                    checks = [*checks, check]
                try:
                    rec = self.store.store_plan_result(
                        plan_id,
                        result=result,
                        arrays=arrays,
                        checks=checks,
                        metrics=metrics,
                        program=program,
                    )
                except (ValueError, TypeError) as store_exc:  # e.g. NaN in result JSON
                    self._transition(
                        plan_id,
                        "fail",
                        "planner",
                        f"result could not be stored: {store_exc}",
                        error=f"result could not be stored: {store_exc}",
                    )
                    return
                except IllegalTransitionError as ill:
                    log.info("plan %s finished but is now %s", plan_id, ill.state)
                    return
                except Exception as store_exc:
                    if not is_disk_full(store_exc):
                        raise
                    # Not lost and not stuck: it says why it waits, and the
                    # sweeper plans it again when there is room.
                    log.error("plan %s: result refused by a full disk; re-queued later", plan_id)
                    with self._lock:
                        self._disk_waiting[plan_id] = "disk full"
                    with contextlib.suppress(Exception):
                        self.store.set_progress(
                            plan_id, 0.0, "waiting for disk space: the result could not be stored"
                        )
                    return
                self.events.publish("plan", _event_body(rec))
            elif isinstance(exc, CancelledError):
                self._transition(plan_id, "cancel", "operator", str(exc))
            else:
                if isinstance(exc, BrokenProcessPool):
                    msg = "the planning worker process crashed (out of memory or a native fault)"
                    self._executor = self._new_executor()
                elif isinstance(exc, ValueError):
                    msg = f"{type(exc).__name__}: {exc}"  # planner input errors: no traceback
                else:
                    msg = f"{type(exc).__name__}: {exc}"
                    log.error(
                        "plan %s failed:\n%s",
                        plan_id,
                        "".join(traceback.format_exception(exc)),
                    )
                self._transition(plan_id, "fail", "planner", msg, error=msg)


@dataclass
class _ResultView:
    """A just-computed plan as :class:`server.kinds.base.PlanView` (for compilers)."""

    id: str
    kind: str
    state: str
    params: dict[str, Any]
    result: dict[str, Any]
    metrics: dict[str, float]
    checks: list[dict[str, Any]]
    arrays_data: dict[str, np.ndarray]

    @property
    def arrays(self) -> dict[str, str]:
        return {k: k for k in self.arrays_data}

    def array(self, name: str) -> np.ndarray:
        return self.arrays_data[name]


def compile_program(
    plan: Any,
    result: dict[str, Any],
    arrays: dict[str, np.ndarray],
    checks: list[dict[str, Any]],
    metrics: dict[str, float],
) -> tuple[list[dict[str, Any]] | None, dict[str, Any] | None]:
    """Compile a finished plan into its robot command program, with a check.

    The program is validated as the dispatch engine will parse it, and joint
    way-points against the robot's URDF limits, so an operator approves
    exactly what will be sent.  A kind without a compiler yields no program
    and no check (it cannot be dispatched).
    """
    from robots import load_robot
    from robots.protocol.commands import CommandError
    from robots.protocol.program import Program
    from server.kinds import registry

    kind = registry().get(plan.kind)
    if kind is None or kind.compile is None:
        return None, None
    view = _ResultView(plan.id, plan.kind, "planning", plan.params, result, metrics, checks, arrays)
    try:
        dicts = kind.compile(view)
        if dicts is None:  # the result has nothing for the robot to do
            return None, None
        program = Program.from_dicts(dicts, robot=kind.robot)
        problems = []
        if kind.robot is not None:
            problems = program.check_joint_limits(load_robot(kind.robot).dispatch_joint_limits)
    except (CommandError, ValueError, KeyError) as exc:
        return None, {
            "name": "command_program",
            "passed": False,
            "value": None,
            "limit": None,
            "message": f"could not compile the robot program: {exc}",
        }
    ok = not problems
    return program.to_dicts(), {
        "name": "command_program",
        "passed": ok,
        "value": len(program),
        "limit": None,
        "message": (
            f"{len(program)} commands, {program.duration_s:.1f} s, within joint limits"
            if ok
            else f"{len(problems)} way-points outside joint limits: " + "; ".join(problems[:3])
        ),
    }


def _event_body(plan: Any) -> dict[str, Any]:
    return {
        "id": plan.id,
        "kind": plan.kind,
        "state": plan.state,
        "progress": plan.progress,
        "stage": plan.stage,
        "error": plan.error,
    }
