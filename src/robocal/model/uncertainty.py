"""How well a calibrated model knows where its TCP is: the parameter covariance carried to the
predicted positions (MODEL §8).

For a pose q the predicted point p(q, x) moves with the identified parameters x by the
Jacobian J (3, k); with their covariance C (k, k) the point's covariance is Σ = J C Jᵀ (mm²,
in the measuring frame), and its standard uncertainty the root of its trace (the rms radius of
the error, mm).  This is the uncertainty of the parametric model from the noise of its
calibration: it says where the model is well determined and where the poses left it loose, not
how far the real robot is (the residual scatter says that).  A learned residual correction adds
its own, not counted here.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from .covariance import ParameterCovariance
from .parameters import ParameterSpace
from .terms import JointInputs, TermSpec


def point_covariance(robot, covariance: ParameterCovariance, q: np.ndarray, targets: Sequence[str] | None = None,
                     inputs: JointInputs | None = None) -> np.ndarray:
    """Σ (m, 3, 3) mm² of the predicted positions of ``robot`` at commanded joints q (m, n) rad."""
    q = np.atleast_2d(np.asarray(q, float))
    spec = robot.terms.spec() if robot.terms is not None else TermSpec()
    space = ParameterSpace.of(robot, None, spec)
    known = [n for n in covariance.names if n in set(space.names)]
    keep = [covariance.names.index(n) for n in known]
    C = covariance.matrix[np.ix_(keep, keep)]
    target_idx = None if targets is None else space.target_index(targets)
    Jc, _, _ = space.jacobian_columns(np.zeros(space.size), q, target_idx, frames=True,
                                      joints=space.joint_data(q, inputs))
    J = Jc[space.index(known)][:, :, :3]  # (k, m, 3)
    return np.einsum("kma,kl,lmb->mab", J, C, J)


def point_sigma(robot, covariance: ParameterCovariance, q: np.ndarray, targets: Sequence[str] | None = None,
                inputs: JointInputs | None = None) -> np.ndarray:
    """The standard uncertainty (m,) mm of each predicted position: √tr Σ, the rms radius."""
    S = point_covariance(robot, covariance, q, targets, inputs)
    return np.sqrt(np.maximum(np.einsum("mii->m", S), 0.0))


@dataclass(frozen=True)
class UncertaintyMap:
    """Predicted TCP positions (m, 3) mm and their standard uncertainty (m,) mm at joint sets
    drawn over the region the model was calibrated on (each joint's range, in any combination:
    configurations the poses never took are among them, and show where the model extrapolates);
    at_poses: the same σ at the calibration poses themselves."""

    position: np.ndarray
    sigma: np.ndarray
    at_poses: np.ndarray | None = None

    def summary(self) -> dict:
        out = {"points": int(self.sigma.size), **_spread(self.sigma)}
        if self.at_poses is not None:
            out["at_calibration_poses"] = _spread(self.at_poses)
        return out


def _spread(sigma: np.ndarray) -> dict:
    return {"median_mm": float(np.median(sigma)), "p95_mm": float(np.percentile(sigma, 95)),
            "max_mm": float(np.max(sigma))}


def uncertainty_map(robot, covariance: ParameterCovariance, q_low: np.ndarray, q_high: np.ndarray, n: int = 2000,
                    seed: int = 0, at_poses: np.ndarray | None = None) -> UncertaintyMap:
    """σ of the TCP at ``n`` joint sets drawn uniformly (seeded) between q_low and q_high (rad),
    and at_poses: σ already worked out at the calibration poses, kept beside them."""
    rng = np.random.default_rng(seed)
    q = rng.uniform(np.asarray(q_low, float), np.asarray(q_high, float), (n, len(q_low)))
    p = robot.positions(q)
    return UncertaintyMap(p, point_sigma(robot, covariance, q), at_poses)


def tcp_map(robot, meas, seed: int | None = 0) -> UncertaintyMap | None:
    """The predicted TCP's σ over the region ``robot`` was calibrated on and at its calibration
    poses ``meas`` (None without a covariance or a region); its parametric part only."""
    if robot.uncertainty is None or robot.region is None:
        return None
    parametric = robot.replace(residual=None, fallback=None)
    known = meas.targets if meas.targets is not None and all(t in robot.target_names for t in meas.targets) else None
    at_poses = point_sigma(parametric, robot.uncertainty, meas.q, known, meas.inputs)
    return uncertainty_map(parametric, robot.uncertainty, robot.region.lo, robot.region.hi, seed=seed or 0,
                           at_poses=at_poses)
