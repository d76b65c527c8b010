"""Mappers that run the structure model's tiles in parallel.

:func:`planners.structure.model_structure` (and
:func:`planners.structure.model_structure_tiled`) take ``mapper``, a callable
like the builtin ``map``: it gets :func:`planners.structure.tiles.model_tile`
and an iterator of tile jobs and must give their results, in order.  The
planner stays pure; the server picks the mapper (:func:`structure_mapper`):

* with ``STEELPATH_DASK_SCHEDULER`` set, the tiles run on the Dask
  cluster's workers (:func:`dask_mapper`).  A plan already running on a
  worker (:func:`server.dask_jobs.run_plan_on_worker`) submits them through
  ``distributed.worker_client``, which secedes the plan's task from the
  worker's thread pool while it waits and rejoins after, so the tiles can
  use that thread too;
* otherwise on a local process pool of ``STEELPATH_STRUCTURE_TILE_WORKERS``
  processes (:func:`pool_mapper`; 1 or unset: the builtin ``map``, in the
  plan's own process).

Every mapper keeps at most ``in_flight`` tiles submitted and not yet
consumed (a sliding window), so the tiles' points in memory are bounded
whatever the scan's size.
"""

from __future__ import annotations

import multiprocessing as mp
import os
from collections import deque
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import ProcessPoolExecutor
from typing import Any

Mapper = Callable[[Callable[[Any], Any], Iterable[Any]], Iterable[Any]]


def windowed(
    submit: Callable[[Any], Any],
    result: Callable[[Any], Any],
    items: Iterable[Any],
    in_flight: int,
) -> Iterator[Any]:
    """``result(submit(item))`` for each item, in order, with at most
    ``in_flight`` submitted and not yet yielded."""
    pending: deque[Any] = deque()
    for item in items:
        pending.append(submit(item))
        if len(pending) >= max(1, in_flight):
            yield result(pending.popleft())
    while pending:
        yield result(pending.popleft())


def pool_mapper(workers: int, in_flight: int | None = None) -> Mapper:
    """A mapper on a process pool of ``workers`` (spawned) processes, made for
    each call and shut down after it; ``workers`` ≤ 1: the builtin ``map``."""
    if workers <= 1:
        return map

    def mapper(fn: Callable[[Any], Any], items: Iterable[Any]) -> Iterator[Any]:
        with ProcessPoolExecutor(workers, mp_context=mp.get_context("spawn")) as pool:
            yield from windowed(
                lambda job: pool.submit(fn, job),
                lambda fut: fut.result(),
                items,
                in_flight or 2 * workers,
            )

    return mapper


def dask_mapper(client: Any = None, in_flight: int | None = None) -> Mapper:
    """A mapper on a Dask cluster: through ``client`` when given, else, in a
    task running on a worker, through ``distributed.worker_client`` (seceding
    the task while the tiles run).  ``in_flight`` defaults to twice the
    cluster's threads."""

    def run(c: Any, fn: Callable[[Any], Any], items: Iterable[Any]) -> Iterator[Any]:
        window = in_flight or max(2, 2 * sum(c.nthreads().values()))
        yield from windowed(
            lambda job: c.submit(fn, job, pure=False),
            lambda fut: fut.result(),
            items,
            window,
        )

    def mapper(fn: Callable[[Any], Any], items: Iterable[Any]) -> Iterator[Any]:
        if client is not None:
            yield from run(client, fn, items)
            return
        from distributed import worker_client

        with worker_client() as c:
            yield from run(c, fn, items)

    return mapper


def structure_mapper() -> Mapper:
    """The mapper a plan's structure model uses here (module docstring)."""
    if os.environ.get("STEELPATH_DASK_SCHEDULER"):
        try:
            from distributed import get_worker

            get_worker()
        except (ImportError, ValueError):
            from distributed import Client

            return dask_mapper(Client(os.environ["STEELPATH_DASK_SCHEDULER"]))
        return dask_mapper()
    return pool_mapper(int(os.environ.get("STEELPATH_STRUCTURE_TILE_WORKERS", "1") or 1))


def lazy_structure_mapper() -> Mapper:
    """:func:`structure_mapper`, made only when a cloud is tiled: a plan over a
    small cloud opens no pool and no Dask client."""

    def run(fn: Callable[[Any], Any], items: Iterable[Any]) -> Iterable[Any]:
        return structure_mapper()(fn, items)

    return run
