"""Where a calibration's time goes: named stages, each timed exclusively.

:func:`calibrate` opens a :class:`Timings` (a context variable, so that concurrent
calibrations in threads keep their own) and the steps mark their work with :func:`stage`:
``load`` (robot and data files), ``compile`` (numba kernels compiled or loaded from their
cache before the first timed use), ``optimize`` (the optimizers: LM, swarms, their refits),
``statistics`` (identifiability, noise, goodness of fit, uncertainties), ``model`` (the model
ladder's cross-validation and the residual processes) and ``evaluate`` (metrics and the
final guard).  A stage inside another is that stage's time, not the outer one's, so the
stages add up to the total.
"""

from __future__ import annotations

import contextlib
import contextvars
import time
from collections.abc import Iterator

STAGES = ("load", "compile", "optimize", "statistics", "model", "evaluate")

_CURRENT: contextvars.ContextVar[Timings | None] = contextvars.ContextVar("timings", default=None)


class Timings:
    """Seconds per stage, exclusive of the stages nested in it; ``total`` from start to stop."""

    def __init__(self):
        self.seconds = dict.fromkeys(STAGES, 0.0)
        self._stack: list[list] = []
        self._start = time.perf_counter()
        self.total = 0.0

    def to_dict(self) -> dict[str, float]:
        return {**{f"{k}_s": v for k, v in self.seconds.items()}, "total_s": self.total}


@contextlib.contextmanager
def timed() -> Iterator[Timings]:
    """Collect the stages of everything run in the block."""
    timings = Timings()
    token = _CURRENT.set(timings)
    try:
        yield timings
    finally:
        _CURRENT.reset(token)
        timings.total = time.perf_counter() - timings._start


@contextlib.contextmanager
def stage(name: str) -> Iterator[None]:
    """Count the block's time to ``name`` (less what stages nested in it count to themselves)."""
    timings = _CURRENT.get()
    if timings is None:
        yield
        return
    frame = [name, time.perf_counter(), 0.0]  # name, start, time of nested stages
    timings._stack.append(frame)
    try:
        yield
    finally:
        timings._stack.pop()
        elapsed = time.perf_counter() - frame[1]
        timings.seconds[name] += elapsed - frame[2]
        if timings._stack:
            timings._stack[-1][2] += elapsed


def staged(name: str):
    """A decorator: the function's calls are :func:`stage` ``name``."""
    import functools

    def wrap(fn):
        @functools.wraps(fn)
        def inner(*args, **kwargs):
            with stage(name):
                return fn(*args, **kwargs)

        return inner

    return wrap
