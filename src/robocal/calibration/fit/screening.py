"""Step 6: poses that fail the outlier test, left out by a robust fit or named.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...model.robot import Robot
from ..config import CalibrationConfig
from ..judge.statistics import MAX_OUTLIER_FRACTION, OUTLIER_GAP, OUTLIER_SIGMAS, leave_one_out, robust_outliers
from .methods import Estimate, fit_lm


@dataclass(frozen=True)
class Screening:
    """Outliers left out by a robust fit, and the plain fit that keeps them (for comparison)."""

    outliers: list[dict]
    with_outliers: Robot | None = None


#: below this many poses per estimated parameter, outliers are judged on leave-one-out residuals
LEVERAGE_POSES_PER_PARAMETER = 20


def poses_per_parameter(problem) -> float:
    return problem.meas.n_poses / max(1, problem.n_params)


def row_kinds(meas) -> tuple[np.ndarray, dict[int, int]]:
    """Each row's kind for the outlier test (0 tracker, 1 point, 2 plane, 3 camera) and the values a
    row of each kind carries: a plane row says only its offset along the normal, a camera row its
    pixel."""
    c = meas.constraints
    kinds = np.zeros(meas.n_poses, dtype=int)
    if c is not None:
        kinds = np.where(c.rows_of("plane"), 2, np.where(c.rows, 1, 0))
    if meas.camera is not None:
        kinds = np.where([bool(x) for x in meas.camera], 3, kinds)
    return kinds, {0: 3, 1: 3, 2: 1, 3: 2}


def screen_outliers(est: Estimate, config: CalibrationConfig) -> tuple[Estimate, Screening, list[str]]:
    """Step 6: poses that fail the outlier test (:func:`~robocal.calibration.judge.statistics.robust_outliers`).

    With a robust loss they are left out and the inliers refitted by plain least squares (the
    answer as if the outliers were never measured); a plain fit on every pose is kept beside
    it, so that validation can say what leaving them out did.  With a plain fit they are only
    named, with the suggestion of a robust loss: only poses that stand apart are named, so the
    suggestion is not made for the continuous tail of an incomplete model.
    """
    problem = est.problem
    if not config.least_squares or est.optimization.status != "converged":
        return est, Screening([]), []
    dp, _ = problem.errors(est.x)
    # leverage matters where poses are few against the parameters; with many, each pose's share
    # of the fit is about k/m and the residuals are their own leave-one-out values
    few = poses_per_parameter(problem) < LEVERAGE_POSES_PER_PARAMETER
    kinds, dofs = row_kinds(problem.meas)
    flagged, sigma = robust_outliers(leave_one_out(dp, problem.map_jacobian(est.x)) if few else dp, kinds, dofs)
    if not flagged.size:
        return est, Screening([]), []
    meas = problem.meas
    test = (f"leave-one-out residual beyond {OUTLIER_SIGMAS:g} σ̂ = {OUTLIER_SIGMAS * sigma:.3g} mm and standing "
            f"apart, {OUTLIER_GAP:g}× the next smaller one or more")
    if config.loss == "linear":
        return est, Screening([]), [f"{meas.labels(flagged)} look like outliers ({test}); a robust fit (loss huber, "
                                    "--loss huber) would leave them out"]
    plain = CalibrationConfig.build(config, loss="linear")
    keep_all = fit_lm(problem, est.x, plain)
    outliers = [{"row": int(meas.rows[i]), "pose_id": None if meas.pose_ids is None else meas.pose_ids[i],
                 "error_mm": float(np.linalg.norm(dp[i]))} for i in flagged]
    inliers = problem.setup.with_measurements(meas.subset(np.setdiff1d(np.arange(meas.n_poses), flagged)))
    refit_problem = inliers.problem(problem.names)
    lm = fit_lm(refit_problem, est.x, plain)
    merged = est.optimization.then(lm, method=est.optimization.method,
                                   message=f"{est.optimization.message}; {len(flagged)} outliers removed, inliers "
                                           f"refitted: {lm.message}", extra={"robust_scale_mm": sigma})
    notes = [f"{len(flagged)} outlier poses left out ({test}): {meas.labels(flagged)}"]
    if len(flagged) > MAX_OUTLIER_FRACTION * meas.n_poses:
        notes.append(f"{len(flagged)} of {meas.n_poses} poses ({100 * len(flagged) / meas.n_poses:.0f} %) left out "
                     f"as outliers, more than {100 * MAX_OUTLIER_FRACTION:g} %: the model may be incomplete rather "
                     "than the data bad; compare the validation figures with and without them")
    screening = Screening(outliers, problem.space.apply(problem.full(keep_all.x)))
    return est.replace(problem=refit_problem, optimization=merged, x=lm.x), screening, notes
