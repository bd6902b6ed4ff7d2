"""The calibration methods: which optimizer runs, on which parameters, with which settings.

- ``lm``: Levenberg–Marquardt on the identifiable set, from the initial robot.
- ``pso``, ``ipso``, ``ldpso-bt``: a swarm searches every candidate, dependent ones
  included, as the papers do (a swarm does not need full rank), in a box around the
  initial robot; its model is then re-expressed in the identifiable parameters.
- ``hybrid``: a short IPSO lands in the basin, LM finishes from there.

Adding a method is one entry in :data:`robocal.calibration.registry.METHODS`.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..backend import resolve
from ..model.parameters import is_angle, is_frame
from ..optimize.lm import levenberg_marquardt
from ..optimize.result import OptimizeResult, Progress
from .config import CalibrationConfig
from .problem import Problem
from .registry import METHODS
from .timing import stage

#: swarms search frame parameters at least this far (mm, rad) around the registration
FRAME_BOX = (5.0, 0.01)


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
    """LM on ``problem`` from x0; its time counts to the stage ``timed_as`` (a cross-validation
    fold's refit is model selection, not the method's optimizing)."""
    # residuals are whitened: the loss scale, given in mm, is counted in units of σp
    with stage(timed_as):
        return levenberg_marquardt(problem.residuals, problem.residual_jacobian, x0, loss=config.loss,
                                   f_scale=config.f_scale / problem.setup.sigma_position,
                                   max_nfev=max_nfev or config.max_evaluations, callback=progress)


def reexpress(search: Problem, x_search: np.ndarray, problem: Problem) -> tuple[np.ndarray, float]:
    """Express a swarm solution over the candidate set in the identifiable parameters.

    The swarm's values for dependent parameters are arbitrary along the dependency.  The
    model it found is re-expressed by fitting the identifiable parameters to that model's
    own predictions at the measured joints (not to the data), so the swarm's accuracy is
    reported as it is.  Returns the identifiable values and the largest position difference
    (mm) between the two expressions.
    """
    R, p = search.space.pose(search.full(x_search), search.meas.q, search.target_idx, search.joints)
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
            from ..optimize import kernels

            kernels.warm_up()
        if config.spec.halton:
            from scipy.stats import qmc  # noqa: F401  (its import is not the swarm's time)
    with stage("optimize"):
        return config.spec.swarm(objective, lower, upper, **kw)


def optimize(problem: Problem, search: Problem, config: CalibrationConfig,
             progress: Progress | None = None, start: np.ndarray | None = None) -> Estimate:
    """Run the configured method: LM on ``problem`` (the identifiable set), from ``start`` (its
    parameters' values; None: the registered nominal model), swarms on ``search``."""
    if config.spec.swarm is None:
        opt = fit_lm(problem, np.zeros(problem.n_params) if start is None else start, config, progress)
        return Estimate(problem, opt, opt.x)
    swarm = run_swarm(search, config, progress)
    x_id, gap = reexpress(search, swarm.x, problem)
    swarm.extra.update({"searched": search.names})
    if not config.least_squares:
        return Estimate(problem, swarm, x_id, gap)
    lm = fit_lm(problem, x_id, config)
    history = np.concatenate([swarm.history, lm.history]) if config.objective_kind == "sum_squares" else lm.history
    merged = swarm.then(lm, method=f"{swarm.method}+{lm.method}", history=history,
                        message=f"{swarm.method.upper()} {swarm.nit} generations (best {swarm.fun:.6g}), then LM: "
                                f"{lm.message}", extra={"swarm_generations": swarm.nit, "swarm_best": swarm.fun})
    return Estimate(problem, merged, lm.x, gap)
