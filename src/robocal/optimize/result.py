"""The outcome of one optimization, with scipy's semantics."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

#: statuses: ``converged`` (a tolerance was met), ``completed`` (a fixed-budget method such
#: as a swarm ran all its planned generations), ``max_evaluations`` (a cap stopped an
#: iterative method before its tolerance), ``diverged`` (no finite value), ``failed``
STATUSES = ("converged", "completed", "max_evaluations", "diverged", "failed")

#: progress callback: (iteration or evaluation, total or 0 when unknown, best objective so far)
Progress = Callable[[int, int, float], None]


@dataclass
class OptimizeResult:
    """Outcome of one optimization (modelled on scipy's OptimizeResult).

    x: the solution; fun: the objective at x (always f(x)); history: best objective
    after each iteration (index 0 = initial population or starting point); nit:
    iterations (generations, or Jacobian evaluations for LM); nfev: objective or
    residual evaluations; status: one of :data:`STATUSES`; method: what actually ran
    (``lm``, ``trf``, ``lm-normal``, ``pso``, ``ipso``, ``ldpso-bt``, …); time_s: wall
    time; extra: method-specific figures.
    """

    method: str
    x: np.ndarray
    fun: float
    history: np.ndarray
    nit: int
    nfev: int
    status: str
    message: str
    time_s: float
    extra: dict = field(default_factory=dict)

    @property
    def success(self) -> bool:
        """True when the method finished by its own criterion, not stopped by a cap or a failure."""
        return self.status in ("converged", "completed") and math.isfinite(self.fun)

    def then(self, after: OptimizeResult, *, method: str | None = None, message: str | None = None,
             extra: dict | None = None, history: np.ndarray | None = None) -> OptimizeResult:
        """This run followed by ``after`` (started from this one's answer): the one place
        results are merged.  x, fun and status are ``after``'s; counts and times add up."""
        return OptimizeResult(
            method=method or f"{self.method}+{after.method}",
            x=after.x,
            fun=after.fun,
            history=np.concatenate([self.history, after.history]) if history is None else history,
            nit=self.nit + after.nit,
            nfev=self.nfev + after.nfev,
            status=after.status,
            message=message or f"{self.message}; then {after.message}",
            time_s=self.time_s + after.time_s,
            extra={**self.extra, **after.extra, **(extra or {})},
        )
