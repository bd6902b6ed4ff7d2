"""The calibration methods: which optimizer runs, on which parameters, with which settings.

- ``lm``: Levenberg–Marquardt on the identifiable set, from the initial robot.
- ``pso``, ``ipso``, ``ldpso-bt``: a swarm searches every candidate, dependent ones
  included, as the papers do (a swarm does not need full rank), in a box around the
  initial robot; its model is then re-expressed in the identifiable parameters.
- ``hybrid``: a short IPSO lands in the basin, LM finishes from there.

Adding a method is one entry in :data:`robocal.calibration.registry.METHODS`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from ...model.compiled import resolve
from ...model.parameters import is_angle, is_frame
from ...optimize.lm import levenberg_marquardt
from ...optimize.result import OptimizeResult, Progress
from ..config import CalibrationConfig
from ..registry import METHODS
from ..timing import stage
from .problem import Problem

#: swarms search frame parameters at least this far (mm, rad) around the registration
FRAME_BOX = (5.0, 0.01)
#: residual evaluations of the plain least-squares fit that finds the data's scale before the
#: fit with the prior (:func:`fit_map`): a converging fit takes about ten
SCALE_EVALUATIONS = 30


@dataclass(frozen=True)
class Estimate:
    """The optimizer's outcome and what it says about the identifiable parameters.

    optimization: the optimizer's own result (for swarms, over the searched candidates);
    x: estimates (mm, rad) of ``problem.names``; reexpression_gap_mm: for swarms, the
    largest position difference between the swarm's model and its re-expression.
    """

    problem: Problem
    optimization: OptimizeResult
    x: np.ndarray
    reexpression_gap_mm: float | None = None

    def replace(self, **changes) -> Estimate:
        return replace(self, **changes)

    def refitted(self, problem: Problem, step: OptimizeResult, why: str) -> Estimate:
        """This estimate carried on by ``step``, a refit of ``problem`` (new weights, widths, a shared
        error): the optimizer's account extended with why, its history kept (χ² under other weights is
        another scale), the re-expression gap as it was."""
        merged = self.optimization.then(step, method=self.optimization.method,
                                        message=f"{self.optimization.message}; {why}: {step.message}",
                                        history=self.optimization.history)
        return Estimate(problem, merged, step.x, self.reexpression_gap_mm)


def settings(config: CalibrationConfig) -> dict:
    """The swarm settings of a run: the paper's, overridden by the config."""
    return config.swarm_settings.settings()


def swarm_box(names: list[str], method: str, box: tuple[float, float] | None) -> tuple[np.ndarray, np.ndarray]:
    """Lower and upper bounds of the search around the initial estimate (mm, rad)."""
    length, angle = box or METHODS[method].box
    upper = np.array([
        (max(angle, FRAME_BOX[1]) if is_angle(n) else max(length, FRAME_BOX[0])) if is_frame(n)
        else (angle if is_angle(n) else length)
        for n in names
    ])
    return -upper, upper


def fit_lm(problem: Problem, x0: np.ndarray, config: CalibrationConfig, progress: Progress | None = None,
           max_nfev: int | None = None, timed_as: str = "optimize") -> OptimizeResult:
    """LM on ``problem`` from x0, the data with the prior (:meth:`Problem.map_residuals`); its time
    counts to the stage ``timed_as`` (a cross-validation fold's refit is model selection, not the
    method's optimizing)."""
    # residuals are whitened: the loss scale, given in mm, is counted in units of σp
    with stage(timed_as):
        return levenberg_marquardt(problem.map_residuals, problem.map_jacobian, x0, loss=config.loss,
                                   f_scale=config.f_scale / problem.setup.sigma_position,
                                   max_nfev=max_nfev or config.max_evaluations, callback=progress)


def fit_map(problem: Problem, x0: np.ndarray, config: CalibrationConfig, progress: Progress | None = None,
            scaled: bool = False) -> tuple[Problem, OptimizeResult]:
    """The data with the prior, from x0: the problem it ended on (its weights) and LM's result.

    The prior weighs against the data through the data's σ.  Where that σ is not stated it is
    estimated from the residuals, and a fit that starts from a guessed σ can settle on the wrong
    side: a prior weighed against a σ far too large pulls the deviations in, the residuals grow,
    and the σ they show keeps the prior winning.  So the data's own scale comes first: a plain
    least-squares fit, the σ its residuals show (:func:`~robocal.calibration.fit.noise.block_sigmas`),
    then the fit with the prior from there.  ``scaled``: the problem's σ already come from a fit
    of these data (a parent model's settled weights), so the first fit is not needed."""
    if not problem.has_prior or scaled or config.noise_model.stated(problem.uses_orientation):
        return problem, fit_lm(problem, x0, config, progress)
    from .noise import block_sigmas

    plain = replace(problem.setup, prior=None).problem(problem.names)
    # the scale only: along a valley the data cannot see, plain LM would crawl for thousands of
    # evaluations without changing the residuals it leaves
    first = fit_lm(plain, x0, config, progress, max_nfev=min(SCALE_EVALUATIONS, config.max_evaluations or math.inf))
    if not np.all(np.isfinite(first.x)) or problem.n_residuals <= problem.n_params:
        return problem, fit_lm(problem, x0, config, progress)
    sigmas = block_sigmas(plain, first.x, config.noise_model)
    problem = problem.setup.with_noise(*sigmas).problem(problem.names)
    if config.max_evaluations is not None and first.nfev >= config.max_evaluations:
        return problem, first  # the user's cap is spent: the fit stopped before converging, and says so
    second = _gauss_newton(problem, first.x, config) or fit_lm(problem, first.x, config)
    # the history is both fits', each evaluation's sum of squares under its own weights: the plot
    # marks where the fit with the prior starts (its χ² is on the newly estimated σ, another scale)
    return problem, first.then(second, method=second.method, extra={"history_phases": [len(first.history),
                                                                                     len(second.history)]},
                               message=f"least squares for the data's scale (σp {sigmas[0]:.3g} mm, {first.nfev} "
                                       f"evaluations), then with the prior: {second.message}")


def _gauss_newton(problem: Problem, x0: np.ndarray, config: CalibrationConfig) -> OptimizeResult | None:
    """The Gauss–Newton step of the data with the prior from the plain fit, where the problem is
    linear there (the χ² it reaches misses the χ² it predicts by less than
    :data:`~robocal.calibration.fit.noise.LINEAR_CHI2`): then it is the fit LM would converge to, at the
    cost of one Jacobian.  None where it is not, or with a robust loss."""
    from .noise import LINEAR_CHI2

    if config.loss != "linear":
        return None
    with stage("optimize"):
        r, J = problem.map_residuals(x0), problem.map_jacobian(x0)
        scale = 1.0 / np.maximum(np.linalg.norm(J, axis=0), 1e-300)  # mm and rad columns alike
        Js = J * scale
        y = np.linalg.lstsq(Js.T @ Js, -(Js.T @ r), rcond=None)[0]
        predicted = float(r @ r) + 2.0 * float(y @ (Js.T @ r)) + float(y @ (Js.T @ Js) @ y)
        x = x0 + y * scale
        reached = problem.map_residuals(x)
        chi2 = float(reached @ reached)
    if not abs(chi2 - predicted) <= LINEAR_CHI2:
        return None
    return OptimizeResult("gauss-newton", x, chi2, np.array([chi2]), 1, 1, "converged", "one Gauss–Newton step", 0.0)


def reexpress(search: Problem, x_search: np.ndarray, problem: Problem) -> tuple[np.ndarray, float]:
    """Express a swarm solution over the candidate set in the identifiable parameters.

    The swarm's values for dependent parameters are arbitrary along the dependency.  The
    model it found is re-expressed by fitting the identifiable parameters to that model's
    own predictions at the measured joints (not to the data), so the swarm's accuracy is
    reported as it is.  Returns the identifiable values and the largest position difference
    (mm) between the two expressions.
    """
    R, p = search.space.pose(search.full(x_search), search.meas.q, search.target_idx, search.joints,
                             chain=search.chain_index)
    synthetic = replace(search.meas, position=p, rotation=R if problem.uses_orientation else None)
    fit = problem.setup.with_measurements(synthetic).problem(problem.names)
    lm = levenberg_marquardt(fit.residuals, fit.residual_jacobian, search.full(x_search)[problem.active])
    dp, _ = fit.errors(lm.x)
    return lm.x, float(np.linalg.norm(dp, axis=-1).max())


def run_swarm(search: Problem, config: CalibrationConfig, progress: Progress | None) -> OptimizeResult:
    """The configured swarm over the searched candidates (hybrid: its IPSO stage)."""
    lower, upper = swarm_box(search.names, config.method, config.box)
    # particle 0 starts at the initial estimate (nominal joints, fitted frames): the papers draw
    # every particle at random, but on real data that start is already within a millimetre or
    # two, and a swarm should never end worse than the model it was handed
    kw = {"seed": config.seed, "callback": progress, "backend": config.backend, "start": np.zeros(len(search.names)),
          **settings(config), **({"halton_scramble": config.halton_scramble} if config.spec.halton else {})}

    def objective(X):
        return search.objective(X, config.objective_kind)

    with stage("compile"):  # compiled (or loaded from numba's cache) before the swarm's clock starts
        objective(np.zeros((1, len(search.names))))
        if resolve(config.backend) == "numba":
            from ...optimize import kernels

            kernels.warm_up()
    with stage("optimize"):
        return config.spec.swarm(objective, lower, upper, **kw)


def optimize(problem: Problem, search: Problem, config: CalibrationConfig,
             progress: Progress | None = None, start: np.ndarray | None = None, scaled: bool = False) -> Estimate:
    """Run the configured method: LM on ``problem`` (the identifiable set, with its prior), from
    ``start`` (its parameters' values; None: the registered nominal model), swarms on ``search``;
    ``scaled``: the problem's σ are already the data's (see :func:`fit_map`)."""
    if config.spec.swarm is None:
        problem, opt = fit_map(problem, np.zeros(problem.n_params) if start is None else start, config, progress,
                               scaled)
        return Estimate(problem, opt, opt.x)
    swarm = run_swarm(search, config, progress)
    x_id, gap = reexpress(search, swarm.x, problem)
    swarm.extra.update({"searched": search.names})
    if not config.least_squares:
        return Estimate(problem, swarm, x_id, gap)
    problem, lm = fit_map(problem, x_id, config, scaled=scaled)
    history = np.concatenate([swarm.history, lm.history]) if config.objective_kind == "sum_squares" else lm.history
    merged = swarm.then(lm, method=f"{swarm.method}+{lm.method}", history=history,
                        message=f"{swarm.method.upper()} {swarm.nit} generations (best {swarm.fun:.6g}), then LM: "
                                f"{lm.message}", extra={"swarm_generations": swarm.nit, "swarm_best": swarm.fun})
    return Estimate(problem, merged, lm.x, gap)
