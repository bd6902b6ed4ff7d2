"""Identification of the mechanism's parameters from measured platform positions.

Beyond the paper: the identifiable subset of the 28 parameters, found by the same
identifiability analysis as the serial arms, fitted by Levenberg–Marquardt with the
position Jacobian from implicit differentiation of the kinematic equations.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from ..calibration.judge.identifiability import Identifiability, analyse
from ..calibration.judge.statistics import residual_variance, standard_uncertainties
from ..optimize.lm import levenberg_marquardt
from .geometry import PARAM_NAMES, PKMGeometry, reduced_to_pose, rotation_derivatives
from .kinematics import equations, forward, rod_lengths


def _param_jacobian(geom: PKMGeometry, pose: np.ndarray) -> np.ndarray:
    """∂F/∂θ (m, 6, 28) of the kinematic equations with respect to the 28 parameters."""
    R, _ = rotation_derivatives(pose)
    u = np.einsum("...ab,ib->...ia", R, geom.B) + pose[..., None, :3] - geom.T
    n = u / np.linalg.norm(u, axis=-1, keepdims=True)
    Ft = np.zeros((len(pose), 6, 28))
    x1 = R[..., :, 0]
    for i in range(4):
        Ft[:, i, 3 * i : 3 * i + 3] = -n[:, i]
        Ft[:, i, 12 + 3 * i : 12 + 3 * i + 3] = np.einsum("mab,ma->mb", R, n[:, i])  # Rᵀ n
        Ft[:, i, 24 + i] = -1.0
    for r, i in ((4, 2), (5, 3)):
        Ft[:, r, 3 * i : 3 * i + 3] = -x1
        Ft[:, r, 12 + 3 * i] = 1.0  # ∂c/∂B_i = e1
    return Ft


def position_jacobian(geom: PKMGeometry, L_cmd: np.ndarray, guess=None):
    """Platform position (m, 3) mm, its derivative (m, 3, 28) with respect to the parameters,
    and whether forward kinematics converged, by implicit differentiation of F(pose, θ) = 0."""
    r = forward(geom, L_cmd, guess)
    _, Fp = equations(geom, r.pose, L_cmd)
    dpose = -np.linalg.solve(Fp, _param_jacobian(geom, r.pose))
    return r.pose, dpose[:, :3, :], r.converged


@dataclass
class PKMCalibration:
    """Identified parameters (mm), their standard uncertainties, and the fit's RMS (mm)."""

    geometry: PKMGeometry
    names: list[str]
    errors: np.ndarray
    uncertainty: np.ndarray | None
    identifiability: Identifiability
    rms_before: float
    rms_after: float
    status: str
    time_s: float
    extra: dict = field(default_factory=dict)

    def to_dict(self) -> dict:
        ident = self.identifiability
        unc = self.uncertainty if self.uncertainty is not None else [None] * len(self.names)
        return {
            "parameters": [{"name": n, "unit": "mm", "error": float(e), "uncertainty": None if u is None else float(u)}
                           for n, e, u in zip(self.names, self.errors, unc)],
            "dropped": [{"name": n, "reason": ident.reasons[n].text(), **ident.reasons[n].to_dict()}
                        for n in ident.dropped],
            "identifiability": ident.to_dict(),
            "rms_before_mm": self.rms_before,
            "rms_after_mm": self.rms_after,
            "status": self.status,
            "time_s": self.time_s,
        }


def identify(nominal: PKMGeometry, L_cmd, positions, *, guess=None) -> PKMCalibration:
    """Identify the identifiable subset of the 28 parameters from commanded lengths (m, 4) and
    measured platform positions (m, 3) in the fixed frame (mm)."""
    start = time.perf_counter()
    L_cmd, positions = np.asarray(L_cmd, float), np.asarray(positions, float)
    names = list(PARAM_NAMES)
    P0, J0, ok = position_jacobian(nominal, L_cmd, guess)
    if not np.all(ok):
        raise ValueError("nominal forward kinematics failed for some commanded lengths")
    ident = analyse(-J0.reshape(-1, 28), names, np.zeros(28, bool), len(L_cmd), 1.0)
    active = np.array([names.index(n) for n in ident.kept])
    guesses = {"pose": P0.copy() if guess is None else np.asarray(guess, float)}

    def full(x):
        d = np.zeros(28)
        d[active] = x
        return d

    def residuals(x):
        r = forward(nominal.with_errors(full(x)), L_cmd, guesses["pose"])
        guesses["pose"] = r.pose
        return (positions - r.pose[:, :3]).ravel()

    def jac(x):
        _, J, _ = position_jacobian(nominal.with_errors(full(x)), L_cmd, guesses["pose"])
        return -J[:, :, active].reshape(-1, len(active))

    before = residuals(np.zeros(len(active)))
    opt = levenberg_marquardt(residuals, jac, np.zeros(len(active)))
    r = residuals(opt.x)
    variance = residual_variance(r, len(active))
    unc = standard_uncertainties(jac(opt.x), variance=variance) if np.isfinite(variance) else None
    return PKMCalibration(
        geometry=nominal.with_errors(full(opt.x)), names=ident.kept, errors=opt.x, uncertainty=unc,
        identifiability=ident, rms_before=float(np.sqrt(np.mean(np.sum(before.reshape(-1, 3) ** 2, axis=1)))),
        rms_after=float(np.sqrt(np.mean(np.sum(r.reshape(-1, 3) ** 2, axis=1)))), status=opt.status,
        time_s=time.perf_counter() - start, extra={"evaluations": opt.nfev, "iterations": opt.nit},
    )


def identify_simulated(nominal: PKMGeometry, real: PKMGeometry, calibration_poses, *, noise: float = 0.0,
                       seed: int = 0) -> PKMCalibration:
    """Identify a simulated machine from its positions at ``calibration_poses`` (tracker noise σ mm)."""
    L = rod_lengths(nominal, reduced_to_pose(calibration_poses))
    P = forward(real, L, reduced_to_pose(calibration_poses)).pose[:, :3]
    if noise > 0:
        P = P + np.random.default_rng(seed + 5).normal(0.0, noise, P.shape)
    return identify(nominal, L, P)


#: fewer measured poses than this cannot pin down the mechanism's identifiable parameters
MIN_POSES = 10


def identify_file(path, geometry: PKMGeometry) -> PKMCalibration:
    """Identify from a CSV with columns L1..L4 (commanded, mm) and x, y, z (measured, mm)."""
    from ..exceptions import InputError
    from .files import read_rows

    rows = read_rows(None, path, ("L1", "L2", "L3", "L4", "x", "y", "z"), "data")
    if len(rows) < MIN_POSES:
        raise InputError(f"{len(rows)} poses are too few to identify the mechanism (need ≥ {MIN_POSES})", source=path)
    try:
        return identify(geometry, rows[:, :4], rows[:, 4:])
    except ValueError as exc:
        raise InputError(str(exc), source=path) from None
