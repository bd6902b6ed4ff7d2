"""Which implementation runs the hot loops, and on how many threads.

Functions that have a compiled path take ``backend=`` (``auto``, ``numba``, ``numpy``);
:func:`robocal.model.compiled.resolve` turns it into one of the two (``auto``: numba when it
is installed, ``ROBOCAL_NO_NUMBA`` is not set and its kernels are compiled).  Here: whether
numba is installed, and how many threads a kernel call, BLAS and a worker pool get.
"""

from __future__ import annotations

import functools
import importlib.util
import os
from pathlib import Path

from .exceptions import RobocalWarning

BACKENDS = ("auto", "numba", "numpy")


@functools.cache
def numba_installed() -> bool:
    return importlib.util.find_spec("numba") is not None


#: chain evaluations per kernel call below which the numba kernels run on one thread.  Measured
#: on the 2-core development machine (benchmarks/bench_threads.py): quiet, a second thread halves
#: every call from 40 evaluations up; with one busy process per core, a call that waits at the
#: parallel region's barrier for a preempted thread loses a scheduler slice (6–8 ms) whatever
#: its size, up to 70× a serial call of a swarm's size.  Above this size (≈ 20 ms of serial
#: work) a lost slice costs less than the second core gains.
PARALLEL_MIN_WORK = 200_000


def _own_running() -> int:
    """Threads of this process running or waiting for a core (Linux): this one, and a compiled
    kernel's helper threads spinning a moment after their work (OpenMP's wait policy)."""
    count = 0
    for stat in Path("/proc/self/task").glob("*/stat"):
        try:
            # the state follows the command's closing parenthesis
            count += stat.read_text(encoding="ascii", errors="replace").rsplit(")", 1)[1].split()[0] == "R"
        except (OSError, IndexError):
            pass
    return max(count, 1)


def _runnable_now(looks: int = 5, interval: float = 0.005) -> int | None:
    """Threads of other processes running or waiting for a core right now, plus this one: the
    least of a few looks at Linux's count of runnable tasks (/proc/loadavg) less this process's
    own over ``looks × interval`` s (this process's helper threads that spin a moment after a
    kernel are its own, free once it waits on its workers); None elsewhere."""
    import time

    counts = []
    try:
        for i in range(looks):
            with open("/proc/loadavg", encoding="ascii") as f:
                total = int(f.read().split()[3].split("/")[0])
            counts.append(max(total - _own_running(), 0) + 1)
            if i + 1 < looks:
                time.sleep(interval)
    except (OSError, ValueError, IndexError):
        return None
    return min(counts)


def idle_cores(now: bool = False, looks: int = 5) -> int:
    """Cores this process may use that the rest of the system leaves free (at least 1): the
    1-minute load less this process's own running thread, or with ``now`` (Linux) the threads
    runnable at this moment, the least of ``looks`` looks 5 ms apart (the 1-minute load lags a
    minute behind work that starts or ends, this process's own just-ended workers included)."""
    try:
        cores = len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        cores = os.cpu_count() or 1
    runnable = _runnable_now(looks) if now else None
    if runnable is not None:
        return max(1, min(cores, cores - (runnable - 1)))
    try:
        busy = max(0.0, os.getloadavg()[0] - 1.0)
    except (AttributeError, OSError):
        busy = 0.0
    return max(1, min(cores, int(cores - busy + 0.5)))


def kernel_threads(work: int, now: bool = False) -> int:
    """Threads for a numba kernel call of ``work`` chain evaluations: one below
    :data:`PARALLEL_MIN_WORK` or in a child process, else the idle cores (never more than numba was
    started with; ``now``: those idle at this moment, one look, for a call that follows work of this
    process's own that the 1-minute load still counts).  A child's cores are its parent's to share
    out (a study's or a pool's workers), and numba's OpenMP layer aborts a forked child that starts it."""
    if work < PARALLEL_MIN_WORK:
        return 1
    import multiprocessing

    if multiprocessing.parent_process() is not None:
        return 1
    import numba

    return max(1, min(numba.config.NUMBA_NUM_THREADS, idle_cores(now=True, looks=1) if now else idle_cores()))


def run_kernel(serial, parallel, work: int, *args, now: bool = False):
    """A compiled kernel's call of ``work`` chain evaluations: its serial entry point where one
    thread is all the call should have (:func:`kernel_threads`, ``now`` as there; a serial kernel
    also starts no OpenMP layer), else its parallel one on the idle cores."""
    threads = kernel_threads(work, now)
    if threads == 1:
        return serial(*args)
    import numba

    previous = numba.get_num_threads()
    numba.set_num_threads(min(previous, threads))
    try:
        return parallel(*args)
    finally:
        numba.set_num_threads(previous)


#: matrices smaller than this on a side run BLAS/LAPACK on one thread: on the 2-core development
#: machine a second thread pays for a Cholesky or a product only from about 2000 on a side
#: (benchmarks/bench_threads.py), and costs up to twice the time on the many small calls of a
#: calibration (k × k normal equations, n ≤ 2000 residual-process points, tall Jacobians)
BLAS_PARALLEL_SIDE = 2000


class blas_threads:
    """For the block, BLAS and LAPACK (numpy's and scipy's) on one thread when the largest dense
    matrix side is below :data:`BLAS_PARALLEL_SIDE`, else as they were.  threadpoolctl sets the
    libraries loaded at entry, so scipy's linear algebra is loaded first; the previous limits
    come back on exit."""

    def __init__(self, side: int):
        self.side = side
        self._limits = None

    def __enter__(self):
        if self.side >= BLAS_PARALLEL_SIDE:
            return self
        try:
            import scipy.linalg  # noqa: F401  (its BLAS, so that the limit reaches it)
            from threadpoolctl import threadpool_limits
        except ImportError:
            return self
        self._limits = threadpool_limits(1, user_api="blas")
        return self

    def __exit__(self, *exc):
        if self._limits is not None:
            self._limits.restore_original_limits()
        return False


def _worker_start(modules: tuple[str, ...] = ()) -> None:
    """In a worker of :class:`worker_pool`: Ctrl-C is the parent's to handle (it says so once and
    ends the pool), BLAS runs on one thread (the workers share the cores out already), and the
    modules its pieces will need are imported now (``modules``: scikit-learn's trees take a
    second to import, which each worker would otherwise pay at its first piece)."""
    import importlib
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    for module in modules:
        try:
            importlib.import_module(module)
        except ImportError:  # the piece that needs it says so, where it runs
            pass
    try:
        from threadpoolctl import threadpool_limits

        threadpool_limits(1)
    except ImportError:
        pass


def _started() -> None:
    """A worker's first piece: nothing, so that it starts (and imports) while the parent works."""


def _workers_allowed() -> int:
    """``ROBOCAL_WORKERS`` when set to a whole number ≥ 1, else no cap."""
    value = os.environ.get("ROBOCAL_WORKERS", "")
    return int(value) if value.isdigit() and int(value) >= 1 else 1 << 16


class worker_pool:
    """Worker processes for the independent pieces of one calibration (``auto``'s parametric
    fits of a round, the residual process's tunings from several starts and its folds), as many
    as the cores idle when it opens (:func:`idle_cores` now), at most ``workers``.  They are
    forked, so they start in milliseconds with everything imported; scipy's LAPACK holds the
    interpreter lock, so threads could not share the work.  The pieces must not run numba's
    kernels: its OpenMP layer aborts a forked child that does (the pieces are numpy and scipy
    alone); should a worker die all the same, the pieces run here and a warning says so.  On
    one idle core, off Linux (fork is unsafe with macOS's frameworks) or inside a worker
    process already (a study's), the pieces run here, one after the other: ``map`` gives the
    same results either way, in order.

    The environment variable ``ROBOCAL_WORKERS`` caps the workers (``1``: none), read when a
    pool opens.  ``robocal bench`` times ``--model auto`` with and without them (W6).

    ``prepare``: modules each worker imports as it starts; the workers start when the pool opens,
    so a pool opened before the parent's own work has them ready by the first piece."""

    def __init__(self, workers: int = 8, prepare: tuple[str, ...] = ()):
        self.workers = workers
        self.prepare = tuple(prepare)
        self._pool = None

    def __enter__(self) -> worker_pool:
        import multiprocessing
        import sys

        n = min(self.workers, _workers_allowed())
        n = min(n, idle_cores(now=True)) if n >= 2 else n
        if n >= 2 and sys.platform == "linux" and multiprocessing.parent_process() is None:
            from concurrent.futures import ProcessPoolExecutor

            self._pool = ProcessPoolExecutor(n, mp_context=multiprocessing.get_context("fork"),
                                             initializer=_worker_start, initargs=(self.prepare,))
            if self.prepare:
                for _ in range(n):  # each submission starts a worker while none is idle
                    self._pool.submit(_started)
        return self

    def map(self, fn, items) -> list:
        """``[fn(item) for item in items]``, on the workers when there are any (fn a module-level
        function, items picklable)."""
        items = list(items)
        if self._pool is None or len(items) < 2:
            return [fn(item) for item in items]
        import warnings
        from concurrent.futures.process import BrokenProcessPool

        try:
            with warnings.catch_warnings():  # Python ≥ 3.12 warns of forking a process that has threads
                warnings.simplefilter("ignore", DeprecationWarning)
                return list(self._pool.map(fn, items))
        except BrokenProcessPool:  # a worker died (killed, out of memory): the pieces run here
            self._pool.shutdown(wait=False, cancel_futures=True)
            self._pool = None
            warnings.warn(RobocalWarning("a worker process ended abruptly (killed, or out of memory?): its pieces of "
                                         "the work ran again in this process, with the same results, more slowly"),
                          stacklevel=2)
            return [fn(item) for item in items]

    def submit(self, fn, items) -> Pending:
        """``map`` begun now and collected later (:meth:`Pending.result`): on the workers the pieces
        start at once, ahead of any later ``map``'s, whose pieces then fill the cores they leave
        idle; without workers they run here when collected.  Either way the results are ``map``'s."""
        items = list(items)
        if self._pool is None:
            return Pending(self, fn, items, None)
        import warnings
        from concurrent.futures.process import BrokenProcessPool

        try:
            with warnings.catch_warnings():  # as in map
                warnings.simplefilter("ignore", DeprecationWarning)
                return Pending(self, fn, items, [self._pool.submit(fn, item) for item in items])
        except BrokenProcessPool:
            return Pending(self, fn, items, None)

    def __exit__(self, *exc):
        if self._pool is not None:
            self._pool.shutdown(wait=True, cancel_futures=True)
        return False


class Pending:
    """Pieces handed to :meth:`worker_pool.submit`: ``result()`` gives their results in order, as
    ``map`` would (should a worker have died, ``map`` runs them here and says so)."""

    def __init__(self, pool: worker_pool, fn, items: list, futures: list | None):
        self.pool, self.fn, self.items, self.futures = pool, fn, items, futures

    def result(self) -> list:
        if self.futures is not None:
            from concurrent.futures.process import BrokenProcessPool

            try:
                return [f.result() for f in self.futures]
            except BrokenProcessPool:
                pass
        return self.pool.map(self.fn, self.items)


#: the pieces run in this process, one after the other (see :class:`worker_pool`)
SERIAL = worker_pool(1)
