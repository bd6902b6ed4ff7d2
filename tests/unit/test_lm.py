"""Levenberg–Marquardt: scipy semantics of the result, and the three solvers' fixed points."""

import numpy as np

from robocal.optimize import lm as lm_module
from robocal.optimize.lm import levenberg_marquardt

X0 = np.array([1.2, -0.5, 0.5])  # in the basin of the planted solution


def _problem(rng, m=400):
    """A nonlinear least-squares problem with a known zero-residual solution."""
    t = rng.uniform(0, 3, m)
    truth = np.array([1.5, -0.7, 0.3])

    def model(x):
        return x[0] * np.exp(x[1] * t) + x[2] * t

    y = model(truth)

    def residuals(x):
        return model(x) - y

    def jacobian(x):
        e = np.exp(x[1] * t)
        return np.column_stack([e, x[0] * t * e, t])

    return residuals, jacobian, truth


def test_minpack_converges_and_x_matches_fun(rng):
    residuals, jacobian, truth = _problem(rng)
    res = levenberg_marquardt(residuals, jacobian, X0)
    assert res.method == "lm" and res.status == "converged" and res.success
    np.testing.assert_allclose(res.x, truth, atol=1e-9)
    r = residuals(res.x)
    assert res.fun == float(r @ r)


def test_a_cap_is_not_success(rng):
    residuals, jacobian, _ = _problem(rng)
    res = levenberg_marquardt(residuals, jacobian, X0, max_nfev=2)
    assert res.status == "max_evaluations" and not res.success
    r = residuals(res.x)
    assert res.fun == float(r @ r)


def test_robust_loss_reports_trf(rng):
    residuals, jacobian, truth = _problem(rng)
    res = levenberg_marquardt(residuals, jacobian, X0, loss="huber", f_scale=0.1)
    assert res.method == "trf" and res.success
    np.testing.assert_allclose(res.x, truth, atol=1e-6)


def test_normal_equations_reach_minpacks_fixed_point(rng, monkeypatch):
    residuals, jacobian, _ = _problem(rng, m=2000)
    offset = rng.normal(0, 0.05, 2000)  # a problem with a nonzero minimum

    def r_noisy(x):
        return residuals(x) + offset

    ref = levenberg_marquardt(r_noisy, jacobian, X0)
    monkeypatch.setattr(lm_module, "NORMAL_EQUATIONS_ROWS", 100)
    res = levenberg_marquardt(r_noisy, jacobian, X0)
    assert res.method == "lm-normal" and res.status == "converged"
    np.testing.assert_allclose(res.x, ref.x, atol=1e-8)
