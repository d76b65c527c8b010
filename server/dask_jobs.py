"""Planning jobs on a Dask cluster (``STEELPATH_DASK_SCHEDULER``).

The scheduler and workers are Dask's own (``dask scheduler``, ``dask
worker``); what runs on a worker is :func:`run_plan_on_worker`, which opens
the shared store itself, reads the plan (and its cloud) from it, runs the
same pure kind ``run`` as the local pool (:func:`server.jobs.run_kind`) and
writes progress and the result back to the store.  Nothing planned travels
back through Dask: a worker on another machine, or a server that restarted
meanwhile, needs nothing but the store.

The server (:class:`DaskJobRunner`) submits, and follows the plans it has in
flight by reading the store every ``poll_s``: it publishes the same bus
events and calls the same ``on_finished`` callbacks as the local runner.
Cancel is a flag in the store that the worker's progress call reads.

Failures: a worker that dies mid-plan makes Dask run the task again on
another worker; that start finds the plan still ``planning`` and is recorded
as a re-run (audit ``rerun``, stage and metric ``reruns``); one re-run is
allowed, the start after it fails the plan.  A run writes only while the plan
is still its own (:meth:`server.store.Store.start_plan_run` and the
conditional UPDATEs next to it), so a late "zombie" run can neither finish a
plan twice nor overwrite a cancel.  A worker whose plan has written no
progress for ``stuck_s`` is restarted through its nanny, which is a death as
above.

A lost scheduler cancels every future of the client ("scheduler connection
lost") and its workers exit; a supervisor (compose's restart policy, systemd)
starts them again.  Each plan this server follows that is still queued or
planning is then *lost*, not failed: the poller waits for the client to be
connected again (it reconnects by itself within ``connect_timeout_s``, after
which a new client is made, tried every ``reconnect_s``) and submits it again,
a plan left ``planning`` re-queued as a fresh start, as after a server restart.
"""

from __future__ import annotations

import contextlib
import inspect
import logging
import os
import secrets
import socket
import threading
import time
import traceback
from collections import OrderedDict
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from planners.errors import CancelledError, InvalidInputError
from server.events import EventBus
from server.jobs import JobRunner, run_kind
from server.lifecycle import IllegalTransitionError, PlanState
from server.store import NotFoundError, Store
from server.store.store import worker_address, worker_name

log = logging.getLogger(__name__)

#: Starts of one plan allowed on workers: the first run and one re-run.
MAX_STARTS = 2
#: A worker writes a plan's progress at most this often (≤ 5 writes/s): every
#: write is a committed transaction on the shared store.
PROGRESS_INTERVAL_S = 0.2
#: Stores a worker process keeps open (one per data directory / database).
_STORE_CACHE_SIZE = 4

_stores: OrderedDict[tuple[str, str | None], Store] = OrderedDict()
_stores_lock = threading.Lock()


def open_store(data_dir: str, database_url: str | None) -> Store:
    """The worker process's store for ``data_dir``/``database_url``, opened once.

    ``database_url`` is passed to :class:`Store` only when it is set, and only
    a store that takes it can serve one (otherwise the worker fails loudly
    rather than writing to a SQLite file no server reads).
    """
    key = (str(data_dir), database_url)
    with _stores_lock:
        store = _stores.get(key)
        if store is not None:
            _stores.move_to_end(key)
            return store
        kwargs: dict[str, Any] = {}
        if database_url:
            if "database_url" not in inspect.signature(Store).parameters:
                raise RuntimeError("this worker's Store cannot open a database URL")
            kwargs["database_url"] = database_url
        store = Store(Path(data_dir), **kwargs)
        _stores[key] = store
        while len(_stores) > _STORE_CACHE_SIZE:
            _, old = _stores.popitem(last=False)
            with contextlib.suppress(Exception):
                old.close()
        return store


def dask_setup(worker: Any) -> None:
    """``dask worker … --preload server.dask_jobs``: prepare a worker as the local pool does.

    Imports every plan kind and loads every robot now (a cold first plan of a
    kind otherwise spends 1-2 s on it), then freezes those objects out of the
    cyclic GC's walks (see :func:`server.jobs._worker_init` for the figures).
    """
    import gc

    from server.jobs import preload_kinds

    try:
        seconds = preload_kinds()
        log.info("worker %s preloaded the plan kinds in %.1f s", worker.name, seconds)
    except Exception:  # a preload error must not keep the worker from starting
        log.warning("preloading the plan kinds failed", exc_info=True)
    gc.freeze()
    if os.environ.get("MALLOC_TRIM_THRESHOLD_"):
        log.warning(
            "MALLOC_TRIM_THRESHOLD_ is set (Dask's nanny sets it by default): planning runs "
            "~1.6x slower; start the workers with DASK_CONFIG=docker/dask (it unsets it)"
        )


class StoreContext:
    """The :class:`server.kinds.base.JobContext` of a run on a Dask worker.

    Progress goes to the store (throttled to ``interval_s``, except the last
    ``1.0``), and every progress call reads the cancel flag, so a cancel is
    honoured at the next progress call as in the local pool.  A run that no
    longer owns its plan (it was re-run elsewhere) is stopped the same way.
    """

    def __init__(
        self, store: Store, plan_id: str, run: str, interval_s: float = PROGRESS_INTERVAL_S
    ) -> None:
        self.plan_id = plan_id
        self._store = store
        self._run = run
        self._interval = interval_s
        # The start wrote progress just now: the first write waits a period,
        # which also leaves a re-run's "re-run after …" stage visible a moment.
        self._last = time.monotonic()

    def cancelled(self) -> bool:
        asked, mine = self._store.plan_run_status(self.plan_id, self._run)
        return asked or not mine

    def progress(self, fraction: float, stage: str) -> None:
        asked, mine = self._store.plan_run_status(self.plan_id, self._run)
        if asked:
            raise CancelledError(f"plan {self.plan_id} was cancelled during {stage!r}")
        if not mine:
            raise CancelledError(f"plan {self.plan_id} is no longer this run's ({stage!r})")
        frac = float(min(max(fraction, 0.0), 1.0))
        now = time.monotonic()
        if now - self._last >= self._interval or frac >= 1:
            self._last = now
            self._store.set_run_progress(self.plan_id, self._run, frac, str(stage))

    def load_cloud(self, cloud_id: str) -> np.ndarray:
        try:
            return self._store.cloud_points(cloud_id)
        except (NotFoundError, FileNotFoundError, ValueError):
            raise InvalidInputError(f"no stored cloud with id {cloud_id!r}") from None


def _this_worker() -> tuple[str, str]:
    """``(name, address)`` of the Dask worker running this task (or this process)."""
    try:
        from distributed import get_worker

        w = get_worker()
        return str(w.name), str(w.address)
    except (ImportError, ValueError):
        return f"{socket.gethostname()}:{os.getpid()}", f"local://{os.getpid()}"


def run_plan_on_worker(plan_id: str, data_dir: str, database_url: str | None = None) -> str:
    """Plan ``plan_id`` on this worker, through the store; returns what became of it.

    The task Dask runs.  Outcomes: ``planned``/``rejected``/``failed``/
    ``cancelled`` when this run ended the plan; ``gone`` when it was no longer
    queued or planning; ``lost`` when another run took it over (or ended it)
    first, and this run wrote nothing.
    """
    from threadpoolctl import threadpool_limits

    from server.jobs import WORKER_BLAS_THREADS

    store = open_store(data_dir, database_url)
    name, address = _this_worker()
    run = f"{name}@{address}#{secrets.token_hex(6)}"
    what, plan = store.start_plan_run(plan_id, run, max_starts=MAX_STARTS)
    if what != "run":
        log.info("plan %s not run on %s: %s", plan_id, name, what)
        return "lost" if what == "raced" else what
    assert plan is not None
    rerun = plan.state == PlanState.PLANNING  # it was already planning: a previous run died
    ctx = StoreContext(store, plan_id, run)
    try:
        with threadpool_limits(WORKER_BLAS_THREADS, user_api="blas"):
            result, arrays, checks, metrics, program, check = run_kind(
                plan.kind, plan.params, plan_id, ctx
            )
    except CancelledError as exc:
        done = store.end_plan_run(plan_id, run, "cancel", "operator", str(exc))
        return "cancelled" if done else "lost"
    except Exception as exc:
        msg = f"{type(exc).__name__}: {exc}"
        if not isinstance(exc, ValueError):  # planner input errors: no traceback
            log.error("plan %s failed:\n%s", plan_id, "".join(traceback.format_exception(exc)))
        done = store.end_plan_run(plan_id, run, "fail", "planner", msg, error=msg)
        return "failed" if done else "lost"
    if check is not None:
        checks = [*checks, check]
    if rerun:  # ``plan`` is as it was before this start: attempts = earlier starts
        metrics["reruns"] = float(plan.attempts)
    try:
        done = store.finish_plan_run(
            plan_id,
            run,
            result=result,
            arrays=arrays,
            checks=checks,
            metrics=metrics,
            program=program,
        )
    except (ValueError, TypeError) as exc:  # e.g. NaN in the result JSON
        msg = f"result could not be stored: {exc}"
        done = store.end_plan_run(plan_id, run, "fail", "planner", msg, error=msg)
        return "failed" if done else "lost"
    if not done:
        return "lost"
    return "rejected" if any(not c.get("passed") for c in checks) else "planned"


@dataclass
class _Flight:
    """A plan this server submitted and follows until it leaves queued/planning."""

    future: Any
    state: str
    progress: float
    stage: str
    updated_at: str
    seen_change: float = field(default_factory=time.monotonic)
    restarting: bool = False
    #: Its future was cancelled by a lost scheduler: submit it again once connected.
    lost: bool = False


class DaskJobRunner(JobRunner):
    """:class:`server.jobs.JobRunner`'s API, with the jobs on a Dask cluster."""

    def __init__(
        self,
        store: Store,
        events: EventBus,
        *,
        scheduler: str,
        data_dir: Path,
        database_url: str | None = None,
        stuck_s: float = 600.0,
        poll_s: float = 0.2,
        connect_timeout_s: float = 30.0,
        reconnect_s: float = 2.0,
        server_id: str | None = None,
        orphan_after_s: float = 10.0,
        sweep_s: float = 2.0,
    ) -> None:
        super().__init__(
            store,
            events,
            mode="dask",
            workers=0,
            server_id=server_id,
            orphan_after_s=orphan_after_s,
            sweep_s=sweep_s,
        )
        self.scheduler = scheduler
        self.data_dir = str(Path(data_dir).resolve())
        self.database_url = database_url
        self.stuck_s = stuck_s
        self.poll_s = poll_s
        self.connect_timeout_s = connect_timeout_s
        self.reconnect_s = reconnect_s
        self._next_connect = 0.0
        self._client: Any = None
        self._flights: dict[str, _Flight] = {}
        self._stop = threading.Event()
        self._poller: threading.Thread | None = None

    # ---------------------------------------------------------------- control
    def start(self) -> None:
        from distributed import Client

        self._client = Client(self.scheduler, timeout=self.connect_timeout_s, set_as_default=False)
        self._recover()
        self._poller = threading.Thread(target=self._poll_loop, name="dask-jobs", daemon=True)
        self._poller.start()
        self._start_sweeper()

    def shutdown(self) -> None:
        """Stop following and disconnect.  Dask drops the tasks no worker has
        started; a running one cannot be interrupted and writes its plan to the
        store if it ends first.  The next start re-queues what is left queued or
        planning (:meth:`_recover`); a run still going then stops at its next
        progress call (the plan is no longer its)."""
        self._stop_sweeper()
        self._stop.set()
        if self._poller is not None:
            self._poller.join(timeout=5)
        if self._client is not None:
            with contextlib.suppress(Exception):
                self._client.close(timeout=10)

    def _requeue(self, plan_id: str, why: str) -> None:
        """Re-queue as a fresh start (attempts 0, no run): a run still going on a
        worker for the previous server stops at its next progress call."""
        self.store.transition_plan(
            plan_id,
            "requeue",
            "system",
            why,
            expect=PlanState.PLANNING,
            attempts=0,
            worker=None,
        )

    # ------------------------------------------------------------------- jobs
    def submit(self, plan_id: str) -> None:
        assert self._client is not None, "DaskJobRunner.start() was not called"
        self._owners.assign(plan_id, self.server_id)
        plan = self.store.get_plan(plan_id, result=False, program=False)
        if self._client.status != "running":
            # Not connected (the scheduler is being restarted): a message sent
            # now would be dropped; the poller submits it once connected.
            with self._lock:
                self._flights[plan_id] = _Flight(
                    None, plan.state, plan.progress, plan.stage, plan.updated_at, lost=True
                )
            return
        fut = self._client.submit(
            run_plan_on_worker,
            plan_id,
            self.data_dir,
            self.database_url,
            key=f"plan-{plan_id}-{secrets.token_hex(4)}",
            pure=False,
        )
        with self._lock:
            self._flights[plan_id] = _Flight(
                fut, plan.state, plan.progress, plan.stage, plan.updated_at
            )
        fut.add_done_callback(lambda f: self._task_done(plan_id, f))

    def cancel(self, plan_id: str, actor: str) -> str:
        """Cancel a queued or running plan; returns what happened."""
        plan = self.store.get_plan(plan_id, result=False, program=False)
        if plan.state not in (PlanState.QUEUED, PlanState.PLANNING):
            self.store.transition_plan(plan_id, "cancel", actor)  # the 409
        self.store.request_plan_cancel(plan_id)
        if plan.state == PlanState.QUEUED and self.store.cancel_queued_plan(
            plan_id, actor, "cancelled before it started"
        ):
            with self._lock:
                flight = self._flights.get(plan_id)
            if flight is not None and flight.future is not None:
                with contextlib.suppress(Exception):
                    self._client.cancel([flight.future], asynchronous=False)
            self._poll_once()  # publish now, as the local runner does
            return "cancelled"
        self.store.audit(actor, "plan", plan_id, "cancel-request", "stop at next stage")
        return "cancelling"

    def running(self) -> list[str]:
        with self._lock:
            return list(self._flights)

    def running_count(self) -> int:
        return len(self._flights)

    # -------------------------------------------------------------- internals
    def _task_done(self, plan_id: str, fut: Any) -> None:
        """The Dask task ended: if the plan was not ended by it, say why in the store.

        The poller then sees the plan leave queued/planning as for any end.
        """
        with self._lock:
            flight = self._flights.get(plan_id)
            if flight is None or flight.future is not fut:
                return  # not (any more) this server's task for the plan
        status = fut.status
        if status == "cancelled":
            # Not by this server (its cancel ends the plan in the store first):
            # the scheduler was lost.  Submitted again once connected.
            try:
                plan = self.store.get_plan(plan_id, result=False, program=False)
            except NotFoundError:
                return
            if plan.state in (PlanState.QUEUED, PlanState.PLANNING) and not plan.cancel_requested:
                log.warning(
                    "plan %s: the Dask scheduler was lost; it will be submitted again", plan_id
                )
                with self._lock:
                    if self._flights.get(plan_id) is flight:
                        flight.lost = True
            return
        if status == "error":
            exc = fut.exception()
            what = type(exc).__name__
            if what == "KilledWorker":
                msg = f"the Dask workers running it died too often ({exc})"
            else:
                msg = f"planning on the Dask cluster failed: {what}: {exc}"
        else:
            outcome = fut.result()
            if outcome != "lost":
                return
            msg = "its planning run lost the plan to another run, which did not end it"
        for state in (PlanState.PLANNING, PlanState.QUEUED):
            try:
                self.store.transition_plan(plan_id, "fail", "planner", msg, expect=state, error=msg)
                break
            except (IllegalTransitionError, NotFoundError):
                continue

    def _poll_loop(self) -> None:
        while not self._stop.wait(self.poll_s):
            try:
                self._poll_once()
            except Exception:  # a store hiccup must not stop the following
                log.exception("following the Dask plans failed")

    def _poll_once(self) -> None:
        """Read the plans in flight; publish what changed; end those that ended;
        submit again those a lost scheduler dropped."""
        with self._lock:
            ids = list(self._flights)
        if not ids:
            return
        self._resubmit_lost()
        rows = {r["id"]: r for r in self.store.plan_run_rows(ids)}
        ended: list[str] = []
        now = time.monotonic()
        with self._lock:
            for pid in ids:
                flight = self._flights.get(pid)
                if flight is None:
                    continue
                row = rows.get(pid)
                if row is None:  # deleted: nothing more to follow
                    self._flights.pop(pid, None)
                    ended.append(pid)
                    continue
                if row["updated_at"] != flight.updated_at:
                    flight.updated_at = row["updated_at"]
                    flight.seen_change = now
                if row["state"] != flight.state:
                    flight.state = row["state"]
                    flight.progress, flight.stage = row["progress"], row["stage"]
                    self.events.publish("plan", _row_event(row))
                    if row["state"] not in (PlanState.QUEUED, PlanState.PLANNING):
                        self._flights.pop(pid, None)
                        ended.append(pid)
                    continue
                if row["state"] == PlanState.PLANNING:
                    if (row["progress"], row["stage"]) != (flight.progress, flight.stage):
                        flight.progress, flight.stage = row["progress"], row["stage"]
                        self.events.publish(
                            "plan",
                            {
                                "id": pid,
                                "state": "planning",
                                "progress": row["progress"],
                                "stage": row["stage"],
                            },
                        )
                    if now - flight.seen_change > self.stuck_s and not flight.restarting:
                        flight.restarting = True
                        threading.Thread(
                            target=self._restart_stuck,
                            args=(pid, row["worker"], flight),
                            name="dask-restart",
                            daemon=True,
                        ).start()
        for pid in ended:
            for cb in list(self.on_finished):
                try:
                    cb(pid)
                except Exception:
                    log.exception("on_finished callback failed for %s", pid)

    def _connected(self) -> bool:
        """Whether the client is connected; a client that gave up reconnecting
        (closed) is replaced, at most every ``reconnect_s``."""
        status = self._client.status
        if status == "running":
            return True
        if status not in ("closed", "closing", "failed") or time.monotonic() < self._next_connect:
            return False  # still reconnecting by itself, or tried a moment ago
        self._next_connect = time.monotonic() + self.reconnect_s
        from distributed import Client

        try:
            client = Client(self.scheduler, timeout=self.reconnect_s, set_as_default=False)
        except (OSError, TimeoutError) as exc:
            log.warning("the Dask scheduler %s is unreachable: %s", self.scheduler, exc)
            return False
        old, self._client = self._client, client
        with contextlib.suppress(Exception):
            old.close(timeout=1)
        log.warning("connected to the Dask scheduler %s again", self.scheduler)
        return True

    def _resubmit_lost(self) -> None:
        """Submit again each plan whose future a lost scheduler cancelled."""
        with self._lock:
            lost = [pid for pid, f in self._flights.items() if f.lost]
        if not lost or not self._connected():
            return
        for pid in lost:
            try:
                plan = self.store.get_plan(pid, result=False, program=False)
            except NotFoundError:
                plan = None
            with self._lock:
                flight = self._flights.get(pid)
                if flight is None:
                    continue
                flight.lost = False
                if plan is None or plan.state not in (PlanState.QUEUED, PlanState.PLANNING):
                    continue  # ended meanwhile: the poll publishes it as any end
                self._flights.pop(pid, None)
            try:
                if plan.state == PlanState.PLANNING:
                    self._requeue(
                        pid, "the Dask scheduler was lost while planning; submitted again"
                    )
                else:
                    self.store.audit(
                        "system", "plan", pid, "resubmit", "the Dask scheduler was lost"
                    )
                self.submit(pid)
            except (IllegalTransitionError, NotFoundError) as exc:
                log.info("plan %s changed while being submitted again: %s", pid, exc)

    def _restart_stuck(self, plan_id: str, run: str | None, flight: _Flight) -> None:
        """Restart the worker of a plan that wrote no progress for ``stuck_s``.

        Its nanny starts a fresh worker process; Dask re-runs the task, which
        is that plan's re-run (or its failure after one).
        """
        address = worker_address(run)
        why = f"no progress for {self.stuck_s:g} s on worker {worker_name(run)}: restarting it"
        log.warning("plan %s: %s", plan_id, why)
        try:
            self.store.audit("system", "plan", plan_id, "worker-restart", why)
            if address is not None:
                self._client.restart_workers([address], timeout=60, raise_for_error=False)
        except Exception:
            log.exception("restarting the worker of plan %s failed", plan_id)
        finally:
            with self._lock:
                flight.seen_change = time.monotonic()
                flight.restarting = False


def _row_event(row: dict[str, Any]) -> dict[str, Any]:
    """The bus event of a plan's new state (as :func:`server.jobs._event_body`)."""
    return {
        "id": row["id"],
        "kind": row["kind"],
        "state": row["state"],
        "progress": row["progress"],
        "stage": row["stage"],
        "error": row["error"],
    }
