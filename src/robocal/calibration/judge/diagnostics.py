"""What a fit says about the model: goodness of fit, the joint pattern of what is left,
implausible deviations.

- :func:`goodness_of_fit`: χ² of the whitened residuals, its degrees of freedom and
  p-value; with stated noise a fit beyond the 99.9 % quantile is a *model misfit*.
- :func:`joint_patterns`: which joint's angle best explains the remaining residual, as an
  angle error periodic in that joint (Δq_i = Σ_h a_h cos(h q_i) + b_h sin(h q_i), h = 1, 2)
  pushed through the arm: the pattern a calibration engineer looks for when geometry is
  not the whole story (compliance under gravity, gear transmission errors).
- :func:`physicality`: the verdict on the model: joint deviations beyond 10 mm or 0.1 rad,
  or joint terms that turn a joint by more than a degree at the poses measured, are not
  physical for a calibrated arm.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

import numpy as np

from ...model.parameters import is_angle, is_frame, is_term
from ..fit.problem import Problem
from .statistics import ChiSquared

#: χ² quantile beyond which a fit with stated noise is called a misfit
MISFIT_QUANTILE = 0.999
#: identified joint deviations beyond these are not physical for a calibrated arm (mm, rad)
PLAUSIBLE_LENGTH_MM, PLAUSIBLE_ANGLE_RAD = 10.0, 0.1
#: a joint term that turns its joint by more than this at a measured pose (rad, 1°) is not physical:
#: compliance, gears and drift move joints by hundredths of a degree
PLAUSIBLE_TERM_RAD = math.radians(1.0)
HARMONICS = (1, 2)


@dataclass(frozen=True)
class GoodnessOfFit(ChiSquared):
    """χ² = Σ (residual/σ)² at the solution, on dof = N − k_eff degrees of freedom (k_eff: the
    parameters' effective number, less than k where a prior holds some)."""

    chi2: float
    dof: float
    noise_source: str

    def misfit(self) -> bool:
        """With stated noise: χ² beyond its 99.9 % quantile."""
        return self.noise_source == "stated" and self.dof > 0 and self.chi2 > chi2_quantile(MISFIT_QUANTILE, self.dof)

    def to_dict(self) -> dict:
        """χ², its degrees of freedom and reduced value; its p-value only where σ was stated (where σ
        is estimated from the same fit, χ² equals its dof by construction and tests nothing)."""
        out = {"chi2": self.chi2, "dof": self.dof, "reduced_chi2": self.reduced_chi2, "noise_source": self.noise_source}
        return {**out, "p_value": self.p_value} if self.noise_source == "stated" else out


def goodness_of_fit(problem: Problem, x: np.ndarray, noise_source: str,
                    effective: float | None = None) -> GoodnessOfFit:
    """χ² of the data's whitened residuals (the prior's pseudo-observations are not data) on the
    data's values less the parameters' effective number (``effective``: tr H over the data's rows,
    the parameter count without a prior) and the eliminated points' and planes' unknowns."""
    r = problem.residuals(x)
    used = problem.n_params if effective is None else effective
    return GoodnessOfFit(float(r @ r), float(problem.n_values - used - problem.n_nuisance), noise_source)


def _row_pose(problem: Problem) -> np.ndarray:
    """Pose index of each residual row (positions, then orientations, 3 rows a pose)."""
    m = problem.meas.n_poses
    per_block = np.repeat(np.arange(m), 3)
    return np.concatenate([per_block, per_block]) if problem.uses_orientation else per_block


def joint_patterns(problem: Problem, x: np.ndarray) -> list[tuple[int, float]]:
    """(joint, fraction of the whitened residual's sum of squares explained), best first.

    For joint i the residual is regressed on ∂r/∂q_i · {cos h q_i, sin h q_i}: what an angle
    error of that joint, periodic in its own angle, would leave in the measurements.
    """
    calibrated = problem.space.apply(problem.full(x))
    n = calibrated.n_joints
    thetas = problem.setup.around(calibrated).problem([f"theta{i + 1}" for i in range(n)])
    Jq = -thetas.residual_jacobian(np.zeros(n))  # d(residual)/dq: the θ column is the joint's
    r = problem.residuals(x)
    total = float(r @ r)
    if total <= 0:
        return []
    pose = _row_pose(problem)
    out = []
    for i in range(n):
        qi = problem.meas.q[pose, i]
        A = np.column_stack([Jq[:, i] * f(h * qi) for h in HARMONICS for f in (np.cos, np.sin)])
        coef, *_ = np.linalg.lstsq(A, r, rcond=None)
        left = r - A @ coef
        out.append((i + 1, max(0.0, 1.0 - float(left @ left) / total)))
    return sorted(out, key=lambda t: -t[1])


def chi2_quantile(q: float, dof: int) -> float:
    """The χ² distribution's q-quantile on ``dof`` degrees of freedom."""
    from scipy.special import chdtri

    return float(chdtri(dof, 1.0 - q))


def misfit_message(gof: GoodnessOfFit, patterns: list[tuple[int, float]]) -> str:
    """The ``model misfit:`` warning: how far beyond the noise, and the joint that explains most."""
    limit = chi2_quantile(MISFIT_QUANTILE, gof.dof) / gof.dof
    text = (f"model misfit: the residuals are {math.sqrt(gof.reduced_chi2):.3g}× the stated noise (reduced χ² "
            f"{gof.reduced_chi2:.3g} on {gof.dof:.0f} degrees of freedom, beyond its 99.9 % quantile {limit:.3g})")
    if patterns and patterns[0][1] > 0.2:
        joint, share = patterns[0]
        text += (f"; an angle error of joint {joint} periodic in q{joint} explains {100 * share:.0f} % of what is "
                 "left: an unmodelled joint effect such as compliance under gravity or transmission error")
    return text + "; or the stated noise is too small"


@dataclass(frozen=True)
class Physicality:
    """The verdict on whether a calibrated model is physical: the deviations a real arm of its
    kind does not have (name, value, unit as shown), and their likely cause."""

    implausible: tuple[tuple[str, float, str], ...] = ()
    cause: str = ""

    @property
    def physical(self) -> bool:
        return not self.implausible

    def listed(self) -> str:
        return ", ".join(f"{n} {v:+.4g} {u}" for n, v, u in self.implausible[:6]) + \
            (" …" if len(self.implausible) > 6 else "")

    def sentence(self) -> str:
        """The warning: what is not physical, why, and that the model needs checking."""
        return (f"implausible deviations (beyond {PLAUSIBLE_LENGTH_MM:g} mm or {PLAUSIBLE_ANGLE_RAD:g} rad of the "
                f"geometry, or a joint term turning its joint by more than {math.degrees(PLAUSIBLE_TERM_RAD):g}°, "
                "or 4 of its prior widths where that is more): "
                f"{self.listed()}; likely cause: {self.cause}. The calibrated model is not physical; check before "
                "using it")

    def to_dict(self) -> dict:
        return {"physical": self.physical, "cause": self.cause or None,
                "implausible": [{"name": n, "value": v, "unit": u} for n, v, u in self.implausible]}


def physicality(names: list[str], x: np.ndarray, uncertainty: np.ndarray | None, correlation: np.ndarray | None,
                turns: dict[str, float] | None = None, limits: np.ndarray | None = None) -> Physicality:
    """The verdict: joint deviations beyond PLAUSIBLE_* and joint terms whose largest turn of their
    joint at a measured pose (``turns``: parameter → rad) exceeds PLAUSIBLE_TERM_RAD, with the
    likely cause; ``limits`` (per parameter, its own units, a term's in rad of turn) replaces those
    bounds where the prior width the fit took is wider.  Frame parameters are left out: a base
    frame metres from the tracker is normal."""
    turns = turns or {}
    if limits is None:
        limits = np.array([PLAUSIBLE_TERM_RAD if n in turns else PLAUSIBLE_ANGLE_RAD if is_angle(n) else
                           PLAUSIBLE_LENGTH_MM for n in names])
    bad = [i for i, n in enumerate(names) if not is_frame(n) and (
        abs(turns[n]) > limits[i] if n in turns else abs(x[i]) > limits[i] if not is_term(n) else False)]
    if not bad:
        return Physicality()
    shown = tuple((names[i], float(np.degrees(turns[names[i]])), "° of turn") if names[i] in turns else
                  (names[i], float(x[i]), "rad" if is_angle(names[i]) else "mm") for i in bad)
    cause = "nearly dependent parameters, a wrong nominal model, or a missing model term"
    if correlation is not None:
        c = np.abs(np.nan_to_num(correlation, nan=0.0))
        np.fill_diagonal(c, 0.0)
        i = bad[int(np.argmax([c[b].max() for b in bad]))]
        j = int(np.argmax(c[i]))
        if c[i, j] > 0.99:
            cause = (f"{names[i]} and {names[j]} are nearly dependent (correlation {correlation[i, j]:+.4f}): "
                     f"{_dependency_hint(names[i], names[j])}")
    return Physicality(shown, cause)


def _dependency_hint(a: str, b: str) -> str:
    if re.fullmatch(r"d\d+", a) and re.fullmatch(r"d\d+", b):
        return "consecutive parallel axes without a β term, or too few poses moving them"
    return "the poses barely tell them apart; measure more, or more varied, poses"
