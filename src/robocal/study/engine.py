"""Mapping independent seeded runs over Dask: local worker processes or an existing cluster.

:func:`map_runs` cuts the items into batches (tasks of sensible size: enough of them per worker
to balance the load, few enough that scheduling stays small against the work), submits them
with ``dask.distributed``'s futures and yields each item's result as its batch completes
(``as_completed``).  Dask does the scheduling, the retries of a lost worker's tasks and the
transport; robocal only batches.  With one local worker and no scheduler the items run in this
process, and Dask is not needed.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator, Sequence
from typing import Any

from ..exceptions import InputError

#: tasks per worker a study is cut into, at least: enough for the fast workers to take over
#: the slow ones' share at the end
TASKS_PER_WORKER = 8
#: most runs in one task: a lost task costs no more than this many runs
MAX_BATCH = 50


def batch_size(n_items: int, workers: int) -> int:
    """Runs per task for ``n_items`` runs on ``workers`` workers."""
    return max(1, min(MAX_BATCH, math.ceil(n_items / max(1, workers * TASKS_PER_WORKER))))


def one_thread() -> None:
    """In a worker process: one thread for numba's kernels and for BLAS, since the cores are
    shared out between the worker processes already (threads on top would fight over them)."""
    try:
        import numba

        numba.set_num_threads(1)
    except ImportError:
        pass
    try:
        from threadpoolctl import threadpool_limits

        threadpool_limits(1)
    except ImportError:
        pass


def run_batch(fn: Callable[[Any], Any], items: Sequence, setup: Callable[[], None] | None = None) -> list:
    """One task on a worker: one thread per process, ``setup()`` once (warm caches, load a
    robot), then ``fn`` on every item."""
    one_thread()
    if setup is not None:
        setup()
    return [fn(item) for item in items]


def _client(workers: int | None, scheduler: str | None):
    """A Dask client on a new local cluster of worker processes, or on the given scheduler."""
    try:
        from dask.distributed import Client, LocalCluster
    except ImportError:
        raise InputError("needs Dask: pip install 'robocal[cluster]'",
                         option="scheduler" if scheduler else "workers") from None
    if scheduler is not None:
        try:
            return Client(scheduler, timeout=10), None
        except (OSError, TimeoutError, ValueError) as exc:
            raise InputError(f"cannot reach the Dask scheduler at {scheduler} ({exc.__class__.__name__})",
                             option="scheduler") from None
    # one thread per process: the runs are numpy-bound and hold the GIL between array calls
    cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=None)
    return Client(cluster), cluster


def map_runs(fn: Callable[[Any], Any], items: Sequence, *, workers: int | None = None, scheduler: str | None = None,
             setup: Callable[[], None] | None = None, batch: int | None = None,
             progress: Callable[[int, int], None] | None = None) -> Iterator[tuple[Any, Any]]:
    """``(item, fn(item))`` for every item, in the order their tasks complete.

    workers: local worker processes (default: the machine's cores); scheduler: the address of
    an existing Dask scheduler (``tcp://host:port``) instead.  setup: called once per task
    before its runs.  batch: runs per task (default: :func:`batch_size`).  progress: called
    with (runs done, runs in all).  ``fn`` and ``setup`` must be importable functions (they
    travel to the workers by reference) and each run independent of the others.
    """
    items = list(items)
    if not items:
        return
    if scheduler is None and workers == 1:
        for k, item in enumerate(items):
            if k == 0 and setup is not None:
                setup()
            yield item, fn(item)
            if progress:
                progress(k + 1, len(items))
        return
    import os
    import uuid

    from dask.distributed import as_completed

    client, cluster = _client(workers, scheduler)
    try:
        n_workers = len(client.scheduler_info().get("workers", {})) or workers or os.cpu_count() or 1
        size = batch or batch_size(len(items), n_workers)
        chunks = [items[i:i + size] for i in range(0, len(items), size)]
        study = uuid.uuid4().hex
        futures = {client.submit(run_batch, fn, chunk, setup, key=f"robocal-runs-{study}-{k}"): chunk
                   for k, chunk in enumerate(chunks)}
        done = 0
        for future in as_completed(futures):
            chunk = futures[future]
            for item, result in zip(chunk, future.result()):
                yield item, result
            done += len(chunk)
            if progress:
                progress(done, len(items))
    finally:
        client.close()
        if cluster is not None:
            cluster.close()
