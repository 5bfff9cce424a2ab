"""One parallel map for the stage chain, grading and evaluation (bottom layer: imports no other song module).

Executors: ``serial`` (in this process), ``process`` (a local pool of spawned processes) and ``dask``
(a ``dask.distributed`` cluster at ``scheduler``, or a local one). Results stream back in completion
order; callers that need an order sort them (every job's output is independent of the others, so
outputs never depend on the executor or the worker count).

Worker processes watch their parent: a pool worker whose parent dies (``kill -9``) exits within a
second instead of running on as an orphan (:func:`_watch_parent`).
"""

from __future__ import annotations

import os
import threading
import time
from collections.abc import Callable, Iterable, Iterator
from typing import Any, Literal

ExecutorName = Literal["serial", "process", "dask"]
EXECUTORS: tuple[str, ...] = ("serial", "process", "dask")
PARENT_POLL_S = 0.5  # how often a pool worker checks that its parent is alive


def _watch_parent(parent_pid: int) -> None:
    """Pool-worker initializer: exit as soon as the parent process is gone (its pid changes to a reaper)."""

    def watch() -> None:
        while True:
            if os.getppid() != parent_pid:
                os._exit(1)
            time.sleep(PARENT_POLL_S)

    threading.Thread(target=watch, name="song-parent-watch", daemon=True).start()


def _process_map(fn: Callable[[Any], Any], jobs: list[Any], workers: int) -> Iterator[Any]:
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor, as_completed

    # spawn, not fork: workers start clean (no inherited torch/OpenMP state or open handles).
    context = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(
        max_workers=workers, mp_context=context, initializer=_watch_parent, initargs=(os.getpid(),)
    ) as pool:
        futures = [pool.submit(fn, job) for job in jobs]
        try:
            for future in as_completed(futures):
                yield future.result()
        finally:
            for future in futures:
                future.cancel()


def _dask_map(fn: Callable[[Any], Any], jobs: list[Any], workers: int, scheduler: str | None) -> Iterator[Any]:
    try:
        from dask.distributed import Client, LocalCluster, as_completed
    except ImportError as exc:
        from song.errors import MissingDependencyError

        raise MissingDependencyError("dask.distributed", "dask") from exc
    cluster = None
    if scheduler:
        client = Client(scheduler)
    else:
        cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=None)
        client = Client(cluster)
    try:
        futures = [client.submit(fn, job, pure=False) for job in jobs]
        for future in as_completed(futures):
            yield future.result()
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


def parallel_map(
    fn: Callable[[Any], Any],
    jobs: Iterable[Any],
    workers: int = 1,
    executor: ExecutorName = "process",
    scheduler: str | None = None,
) -> Iterator[Any]:
    """``fn(job)`` for every job, in completion order.

    Args:
        fn: a picklable module-level function of one argument.
        jobs: picklable job descriptions.
        workers: processes for ``process`` (serial when ≤ 1 or a single job) and the local Dask cluster.
        executor: ``serial`` | ``process`` | ``dask``.
        scheduler: a Dask scheduler address (``tcp://host:8786``); None starts a local cluster.
    """
    from song.errors import SongError

    jobs = list(jobs)
    if executor not in EXECUTORS:
        raise SongError(f"unknown executor '{executor}'; choose one of {', '.join(EXECUTORS)}")
    if executor == "serial" or (executor == "process" and (workers <= 1 or len(jobs) <= 1)):
        yield from map(fn, jobs)
    elif executor == "process":
        yield from _process_map(fn, jobs, workers)
    else:
        yield from _dask_map(fn, jobs, workers, scheduler)


def default_workers() -> int:
    """The CPU cores this process may use."""
    return max(1, len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1)
