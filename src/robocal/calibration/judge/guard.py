"""The last check before a model is returned: no worse on its calibration poses than the
geometric fit, nor the geometric fit than the nominal joints with fitted frames.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ...model.metrics import pose_errors
from ...model.robot import Robot
from ..select.selection import Chosen
from ..timing import staged


@staged("evaluate")
def guard(chosen: Chosen) -> Chosen:
    """The last check before a model is returned: it must fit the calibration poses at least as
    well as the geometric fit (a richer model that does not has failed to converge or was
    misled), and the geometric fit at least as well as the nominal joints with their fitted
    frames (a calibration that made things worse has failed).  The better one is kept, and
    the note says why."""
    fit = chosen.fit
    meas = fit.estimate.problem.meas
    sigma_p, sigma_r = fit.noise.position, fit.noise.orientation

    def rms_of(robot: Robot) -> float:
        """Position RMS (mm) when it is all the data say; with orientations, the RMS of the
        errors weighed as the fit weighs them, in mm of position."""
        dp, dr = pose_errors(robot, meas)
        total = np.sum(dp * dp)
        if dr is not None and sigma_r:
            total += np.sum(dr * dr) * (sigma_p / sigma_r) ** 2
        return float(np.sqrt(total / len(dp)))

    model = fit.robot.replace(residual=chosen.residual)
    rms = rms_of(model)
    geometric = chosen.geometric
    if geometric is not None and geometric is not fit:
        rms_geometric = rms_of(geometric.robot)
        if rms > rms_geometric * (1 + 1e-6) + 1e-9:
            note = (f"model {chosen.name} fits the calibration poses worse than geometry alone ({rms:.4g} vs "
                    f"{rms_geometric:.4g} mm{'' if meas.rotation is None else ' weighed'} RMS): the geometric fit is "
                    "returned")
            chosen = replace(chosen, name="geometric", fit=geometric, residual=None,
                             notes=chosen.notes + [note], prediction=chosen.geometric_prediction)
            fit, rms = geometric, rms_geometric
    rms_nominal = rms_of(fit.setup.space.robot)
    if rms > rms_nominal * (1 + 1e-6) + 1e-9:
        est = fit.estimate
        held = replace(fit, estimate=est.replace(x=np.zeros_like(est.x)),
                       uncertainty=None if fit.uncertainty is None else np.full_like(fit.uncertainty, np.nan),
                       covariance=None)
        note = (f"the calibration fits the poses worse than the nominal model with its fitted frames ({rms:.4g} vs "
                f"{rms_nominal:.4g} mm RMS; optimizer {est.optimization.status}): the nominal joint geometry is "
                "returned unchanged; check the data and the robot file")
        chosen = replace(chosen, name="geometric", fit=held, residual=None, notes=chosen.notes + [note],
                         prediction=None)
    return chosen
