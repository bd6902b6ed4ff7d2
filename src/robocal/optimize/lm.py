"""Levenberg–Marquardt with an analytic Jacobian.

Three solvers behind one call, and the result's ``method`` says which one ran:

- ``lm``: MINPACK's Levenberg–Marquardt through scipy ``least_squares``;
- ``trf``: scipy's trust-region reflective solver, for robust losses (``huber``, …) and
  for problems with fewer residuals than parameters, which MINPACK does not take;
- ``lm-normal``: Levenberg–Marquardt on the k×k normal equations, above
  :data:`NORMAL_EQUATIONS_ROWS` residuals (10⁵ full poses are 6·10⁵ rows: MINPACK's QR
  of the tall Jacobian would cost far more than JᵀJ).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable

import numpy as np

from .result import OptimizeResult, Progress

NORMAL_EQUATIONS_ROWS = 30_000
LOSSES = ("linear", "huber", "soft_l1", "cauchy", "arctan")

Residuals = Callable[[np.ndarray], np.ndarray]


def _status(converged: bool, finite: bool, capped: bool) -> str:
    if not finite:
        return "diverged"
    return "converged" if converged else "max_evaluations" if capped else "failed"


def _lm_normal(residuals: Residuals, jacobian: Residuals, x0, tol: float, max_iter: int,
               callback: Progress | None) -> OptimizeResult:
    """Levenberg–Marquardt on the normal equations, with Marquardt's diagonal scaling and
    Nielsen's damping update.  Steps cost one JᵀJ product (BLAS) and a k×k solve; the
    residual itself is always evaluated exactly, so the fixed point is the same as MINPACK's."""
    start = time.perf_counter()
    x = np.asarray(x0, dtype=float).copy()
    r = residuals(x)
    cost = float(r @ r)
    history, nfev, njev = [cost], 1, 0

    def normal(x, r):
        J = jacobian(x)
        return J.T @ J, J.T @ r

    A, g = normal(x, r)
    njev += 1
    lam = 1e-6  # relative to diag(JᵀJ) (Marquardt scaling); a near start, so almost Gauss–Newton
    nu = 2.0
    converged, message = False, f"{max_iter} iterations"
    for _ in range(max_iter):
        D = np.maximum(np.diag(A), 1e-12 * max(float(np.max(np.diag(A))), 1e-300))
        try:
            h = np.linalg.solve(A + lam * np.diag(D), -g)
        except np.linalg.LinAlgError:
            h = np.linalg.lstsq(A + lam * np.diag(D), -g, rcond=None)[0]
        if np.linalg.norm(h) <= tol * (np.linalg.norm(x) + tol):
            converged, message = True, "step below xtol"
            break
        x_new = x + h
        r_new = residuals(x_new)
        nfev += 1
        cost_new = float(r_new @ r_new)
        predicted = float(h @ (lam * D * h - g))  # 2·(L(0) − L(h)) of the linear model
        rho = (cost - cost_new) / predicted if predicted > 0 else -1.0
        if callback is not None:
            callback(nfev, 0, min(cost, cost_new))
        if rho > 0 and np.isfinite(cost_new):
            decrease = cost - cost_new
            x, r, cost = x_new, r_new, cost_new
            history.append(cost)
            A, g = normal(x, r)
            njev += 1
            lam *= max(1.0 / 3.0, 1.0 - (2.0 * rho - 1.0) ** 3)
            nu = 2.0
            if decrease <= tol * cost or cost == 0.0:
                converged, message = True, "relative reduction of the sum of squares below ftol"
                break
        else:
            history.append(cost)
            lam *= nu
            nu *= 2.0
            if not np.isfinite(lam) or lam > 1e300:
                message = "damping grew without bound"
                break
    capped = not converged and message.endswith("iterations")
    return OptimizeResult("lm-normal", x, cost, np.array(history), njev, nfev,
                          _status(converged, math.isfinite(cost), capped), message, time.perf_counter() - start,
                          {"loss": "linear"})


def levenberg_marquardt(
    residuals: Residuals,
    jacobian: Residuals,
    x0: np.ndarray,
    *,
    loss: str = "linear",
    f_scale: float = 1.0,
    max_nfev: int | None = None,
    tol: float = 1e-12,
    callback: Progress | None = None,
) -> OptimizeResult:
    """Minimise ½·Σρ(r²) from x0 with the analytic Jacobian; ``fun`` is the plain Σr² at x.

    history holds the best sum of squared residuals after each residual evaluation, the one at
    x0 first; nfev counts them (scipy's count of MINPACK's is not the calls it made).
    """
    from scipy.optimize import least_squares

    start = time.perf_counter()
    x0 = np.asarray(x0, float)
    r0 = residuals(x0)
    if loss == "linear" and r0.size > NORMAL_EQUATIONS_ROWS:
        return _lm_normal(residuals, jacobian, x0, tol, 200 if max_nfev is None else max_nfev, callback)
    history: list[float] = [float(r0 @ r0)]

    def fun(x):
        r = residuals(x)
        value = float(r @ r)
        history.append(min(value, history[-1]) if history else value)
        if callback is not None:
            callback(len(history), 0, history[-1])  # total 0: unknown in advance
        return r

    method = "lm" if loss == "linear" and r0.size >= len(x0) else "trf"
    kwargs = {"loss": loss, "f_scale": f_scale} if method == "trf" else {}
    try:
        res = least_squares(fun, x0, jac=jacobian, method=method, x_scale="jac", xtol=tol, ftol=tol, gtol=tol,
                            max_nfev=max_nfev, **kwargs)
    except (ValueError, np.linalg.LinAlgError) as exc:
        cost = float(r0 @ r0)
        return OptimizeResult(method, x0, cost, np.array([cost]), 0, 1, "failed", str(exc),
                              time.perf_counter() - start, {"loss": loss})
    final = float(res.fun @ res.fun)
    finite = bool(np.all(np.isfinite(res.x))) and math.isfinite(final)
    return OptimizeResult(
        method=method,
        x=res.x,
        fun=final,
        history=np.array(history),
        nit=int(res.njev or 0),
        nfev=len(history),
        status=_status(res.status > 0, finite, res.status == 0),
        message=res.message,
        time_s=time.perf_counter() - start,
        extra={"loss": loss, "f_scale": f_scale},
    )
