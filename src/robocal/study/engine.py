"""Mapping independent seeded runs over Dask: local worker processes or an existing cluster.

:func:`map_runs` cuts the items into batches (tasks of sensible size: enough of them per worker
to balance the load, few enough that scheduling stays small against the work), submits them
with ``dask.distributed``'s futures and yields each item's result as its batch completes
(``as_completed``).  Dask does the scheduling, the retries of a lost worker's tasks and the
transport; robocal only batches.  With one local worker and no scheduler the items run in this
process; without Dask installed (the main install), local workers are the standard library's
process pool, and only a scheduler needs the ``cluster`` extra.
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


def run_batch(fn: Callable[[Any], Any], items: Sequence, setup: Callable[[], None] | None = None,
              backend: str | None = None) -> list:
    """One task on a worker: one thread per process, ``auto`` meaning the parent's ``backend``
    (so that a run gives the same numbers wherever it runs, whatever each process finds in numba's
    cache), ``setup()`` once (warm caches, load a robot), then ``fn`` on every item."""
    one_thread()
    if backend is not None:
        from ..model.compiled import pin

        pin(backend)
    if setup is not None:
        setup()
    return [fn(item) for item in items]


def _parents_backend() -> str:
    """What ``auto`` means in this process (numba where its kernels are compiled), for its workers."""
    from ..model.compiled import resolve

    return resolve("auto")


#: seconds to connect to a scheduler's address, and to wait for its greeting
PROBE_TIMEOUT = 5.0


def probe_scheduler(address: str) -> None:
    """Check that a Dask scheduler answers at ``address`` before handing it to Dask, whose
    client would wait for ever on a port where something else listens.

    A Dask listener greets every new TCP connection with its handshake (a frame count as a
    little-endian uint64, then msgpack frames) before the client says anything; an HTTP server
    (the dashboard, say) waits for a request instead.  Addresses of other protocols (tls://,
    ucx://) are left to Dask.
    """
    import socket
    import struct
    from urllib.parse import urlsplit

    scheme = address.split("://", 1)[0] if "://" in address else "tcp"
    if scheme != "tcp":
        return
    url = urlsplit(address if "://" in address else f"tcp://{address}")
    try:
        host, port = url.hostname, url.port
    except ValueError:
        host, port = None, None
    if not host or port is None:
        raise InputError(f"expected tcp://HOST:PORT, got {address!r}", option="scheduler")

    def fail(why: str) -> InputError:
        return InputError(f"cannot reach the Dask scheduler at {address}: {why}", option="scheduler")

    try:
        sock = socket.create_connection((host, port), timeout=PROBE_TIMEOUT)
    except socket.gaierror:
        raise fail(f"unknown host {host!r}") from None
    except ConnectionRefusedError:
        raise fail("nothing listens there (connection refused); start the scheduler or check the address") from None
    except TimeoutError:
        raise fail(f"no answer within {PROBE_TIMEOUT:g} s") from None
    except OSError as exc:
        raise fail(exc.strerror or exc.__class__.__name__) from None
    with sock:
        try:
            greeting = sock.recv(8)
        except OSError:  # a timeout: it listens, and waits for a request
            greeting = b""
    frames = struct.unpack("<Q", greeting)[0] if len(greeting) == 8 else 0
    if not 0 < frames < 1000:
        raise fail(f"something listens there but is not a Dask scheduler (no handshake within {PROBE_TIMEOUT:g} s: "
                   "an HTTP server, a dashboard port?); a scheduler listens on tcp://HOST:8786 by default")


def _has_dask() -> bool:
    import importlib.util

    return importlib.util.find_spec("distributed") is not None


def _map_local(fn, items: list, workers: int, setup, batch: int | None, progress) -> Iterator[tuple[Any, Any]]:
    """Local worker processes without Dask (the main install): the standard library's process
    pool, the same batches and the same results; a cluster needs the ``cluster`` extra."""
    from concurrent.futures import ProcessPoolExecutor, as_completed

    size = batch or batch_size(len(items), workers)
    chunks = [items[i:i + size] for i in range(0, len(items), size)]
    done = 0
    with ProcessPoolExecutor(max_workers=workers) as pool:
        backend = _parents_backend()
        futures = {pool.submit(run_batch, fn, chunk, setup, backend): chunk for chunk in chunks}
        try:
            for future in as_completed(futures):
                chunk = futures[future]
                yield from zip(chunk, future.result())
                done += len(chunk)
                if progress:
                    progress(done, len(items))
        except BaseException:
            for future in futures:
                future.cancel()
            raise


def _client(workers: int | None, scheduler: str | None):
    """A Dask client on a new local cluster of worker processes, or on the given scheduler."""
    try:
        from dask.distributed import Client, LocalCluster
    except ImportError:
        raise InputError("a Dask scheduler needs the cluster extra: pip install 'robocal[cluster]'",
                         option="scheduler" if scheduler else "workers") from None
    if scheduler is not None:
        probe_scheduler(scheduler)
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

    if scheduler is None and not _has_dask():
        yield from _map_local(fn, items, workers or os.cpu_count() or 1, setup, batch, progress)
        return
    client, cluster = _client(workers, scheduler)
    from dask.distributed import as_completed

    try:
        n_workers = len(client.scheduler_info().get("workers", {})) or workers or os.cpu_count() or 1
        size = batch or batch_size(len(items), n_workers)
        chunks = [items[i:i + size] for i in range(0, len(items), size)]
        study = uuid.uuid4().hex
        backend = _parents_backend()
        futures = {client.submit(run_batch, fn, chunk, setup, backend, key=f"robocal-runs-{study}-{k}"): chunk
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
