"""Choosing the model: geometry alone, or with joint terms and a residual correction.

``--model auto`` climbs a ladder and judges every rung by K-fold cross-validation on the
calibration data (K = 5, folds by ``pose_id``, so the reflectors of one pose stay together):

1. geometric; 2. + harmonics; 3. + compliance; 4. + both;
5. + residual (a Gaussian process) on the best of these.

Each rung is fitted on all the data; each fold then refits it on the other folds, from that
fit (same parameters, same noise weights), and predicts the held-out poses.  The lowest
cross-validated position RMS wins; a model within :data:`TIE` of a simpler one loses to it.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..model.measurements import Measurements
from ..model.metrics import Metrics
from ..model.residual import ResidualModel
from ..model.robot import Robot
from .config import CalibrationConfig
from .methods import fit_lm
from .pipeline import Fit, Inputs, fit_parametric, term_spec
from .residual import MAX_POINTS, fit_residual

LADDER: tuple[tuple[str, ...], ...] = ((), ("harmonics",), ("compliance",), ("compliance", "harmonics"))
K_FOLDS = 5
#: relative difference of cross-validated RMS within which the simpler model is kept
TIE = 0.01


def model_name(terms) -> str:
    terms = [t for t in ("compliance", "harmonics", "residual") if t in terms]
    return "+".join(terms) if terms else "geometric"


@dataclass
class Chosen:
    """The model a calibration ends with: its parametric fit, its residual correction, the ladder
    (auto only: rows {model, cv_rms_mm, n_params}) and what was said."""

    name: str
    fit: Fit
    residual: ResidualModel | None = None
    table: list[dict] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    geometric: Fit | None = None

    def budget(self, calibrated: Robot, validation: Measurements | None) -> list[dict]:
        """What each part of the model removes on the validation poses: position RMS (mm) of the
        nominal joints with fitted frames, the geometric fit, the fit with joint terms (each term
        refitted with the geometry: a term alone would take geometry's share too), and the
        residual correction on top."""
        if validation is None or calibrated.geometric or self.geometric is None:
            return []
        steps = [("nominal geometry, frames fitted", self.fit.setup.space.robot),
                 ("geometric calibration", self.geometric.robot)]
        parametric = calibrated.replace(residual=None)
        if self.fit is not self.geometric:
            steps.append((f"+ {self.name.replace('+residual', '').replace('residual', '') or 'terms'}", parametric))
        if calibrated.residual is not None:
            steps.append(("+ residual", calibrated))
        rows, last = [], None
        for label, robot in steps:
            rms = Metrics.of(robot, validation).position["rms"]
            rows.append({"model": label, "validation_rms_mm": rms, "removed_mm": None if last is None else last - rms})
            last = rms
        return rows


def folds(meas: Measurements, k: int, seed: int | None) -> list[np.ndarray]:
    """K folds of pose indices; poses sharing a pose_id (several reflectors) stay together."""
    labels = np.array(meas.pose_ids if meas.pose_ids is not None else [str(r) for r in meas.rows])
    groups = np.unique(labels)
    k = max(2, min(k, len(groups)))
    order = np.random.default_rng(seed).permutation(len(groups))
    fold_of = dict(zip(groups[order], np.arange(len(groups)) % k))
    assignment = np.array([fold_of[g] for g in labels])
    return [np.flatnonzero(assignment == f) for f in range(k)]


@dataclass
class CrossValidation:
    """Held-out position errors (m, 3) mm, the fold index sets, and each fold's estimate."""

    errors: np.ndarray
    folds: list[np.ndarray]
    estimates: list[np.ndarray]

    @property
    def rms(self) -> float:
        return float(np.sqrt(np.mean(np.sum(self.errors**2, axis=1))))


def cross_validate(fit: Fit, config: CalibrationConfig) -> CrossValidation:
    """Refit the fitted model on K−1 folds from its full-data estimate and predict the K-th."""
    problem, x0 = fit.estimate.problem, fit.estimate.x
    meas = problem.meas
    plain = CalibrationConfig.build(config, loss="linear")
    errors = np.zeros((meas.n_poses, 3))
    index_sets = folds(meas, K_FOLDS, config.seed)
    estimates = []
    for test in index_sets:
        train = np.setdiff1d(np.arange(meas.n_poses), test)
        x = fit_lm(problem.setup.with_measurements(meas.subset(train)).problem(problem.names), x0, plain).x
        dp, _ = problem.setup.with_measurements(meas.subset(test)).problem(problem.names).errors(x)
        errors[test] = dp
        estimates.append(x)
    return CrossValidation(errors, index_sets, estimates)


def residual_errors(fit: Fit, x: np.ndarray, index: np.ndarray | None = None) -> tuple[Measurements, np.ndarray]:
    """The poses (all, or ``index``) and what the parametric model with estimate x leaves there,
    (m, 3) mm or (m, 6) with orientations (rad)."""
    problem = fit.estimate.problem
    meas = problem.meas if index is None else problem.meas.subset(index)
    dp, dr = problem.setup.with_measurements(meas).problem(problem.names).errors(x)
    return meas, dp if dr is None else np.concatenate([dp, dr], axis=1)


def cross_validate_residual(fit: Fit, cv: CrossValidation, seed: int | None) -> tuple[float, tuple]:
    """Held-out position RMS (mm) of the parametric model plus a residual process, and the
    position kernel.  The kernel's hyperparameters are fitted once, on the residuals of the
    fit on all data; each fold then conditions a process with that kernel on its training poses
    and predicts its held-out ones (a choice of speed: re-optimising eight hyperparameters per
    fold costs minutes on a thousand poses and moves the figure little)."""
    meas, e = residual_errors(fit, fit.estimate.x)
    _, kernels = fit_residual(meas.q, e[:, :3], seed)
    corrected = np.zeros_like(cv.errors)
    for test, x in zip(cv.folds, cv.estimates):
        train = np.setdiff1d(np.arange(len(cv.errors)), test)
        train_meas, e_train = residual_errors(fit, x, train)
        gp, _ = fit_residual(train_meas.q, e_train[:, :3], seed, kernels)
        corrected[test] = cv.errors[test] - gp.predict(meas.q[test])
    return float(np.sqrt(np.mean(np.sum(corrected**2, axis=1)))), kernels


def residual_on_all(fit: Fit, seed: int | None, kernels: tuple | None = None) -> ResidualModel:
    """The residual model of a fit on all its poses (the position kernel reused when given)."""
    meas, e = residual_errors(fit, fit.estimate.x)
    return fit_residual(meas.q, e, seed, kernels)[0]


def fit_model(inputs: Inputs, config: CalibrationConfig, progress=None) -> Chosen:
    """The model the config asks for, or, for ``auto``, the one cross-validation chooses."""
    meas = inputs.meas
    if config.model != "auto":
        terms = config.model_terms
        fit = fit_parametric(inputs, config, term_spec(terms, meas, config), progress)
        residual = residual_on_all(fit, config.seed) if "residual" in terms else None
        geometric = fit
        if terms - {"residual"} and inputs.validation is not None:  # for the error budget
            geometric = fit_parametric(inputs, config, term_spec((), meas, config))
        return Chosen(model_name(terms), fit, residual, geometric=geometric)
    rows, fits = [], {}
    for terms in LADDER:
        fit = fit_parametric(inputs, config, term_spec(terms, meas, config), progress)
        cv = cross_validate(fit, config)
        fits[terms] = (fit, cv)
        rows.append({"model": model_name(terms), "cv_rms_mm": cv.rms, "n_params": fit.n_params})
    best = min(r["cv_rms_mm"] for r in rows)
    chosen_terms = next(t for t, r in zip(LADDER, rows) if r["cv_rms_mm"] <= best * (1 + TIE))
    # the residual process on the best parametric model, and on geometry alone: a process can
    # take structure that joint terms would have taken more coarsely
    tried = {}
    for terms in dict.fromkeys((chosen_terms, ())):
        fit, cv = fits[terms]
        tried[terms] = cross_validate_residual(fit, cv, config.seed)
        rows.append({"model": model_name(terms + ("residual",)), "cv_rms_mm": tried[terms][0],
                     "n_params": fit.n_params, "residual_points": int(min(len(cv.errors), MAX_POINTS))})
    best_gp = min(tried, key=lambda t: (tried[t][0], len(t)))
    fit, cv = fits[chosen_terms]
    name, residual, chosen_cv = model_name(chosen_terms), None, cv.rms
    if tried[best_gp][0] < cv.rms * (1 - TIE):
        fit = fits[best_gp][0]
        residual = residual_on_all(fit, config.seed, tried[best_gp][1])
        name, chosen_cv = model_name(best_gp + ("residual",)), tried[best_gp][0]
    notes = [f"model auto: {name} (cross-validated position RMS {chosen_cv:.4g} mm; geometric "
             f"{rows[0]['cv_rms_mm']:.4g} mm)"]
    return Chosen(name, fit, residual, rows, notes, geometric=fits[()][0])
