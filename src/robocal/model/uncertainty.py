"""How well a calibrated model knows where its TCP is: its predicted position uncertainty (MODEL §8).

For a pose q the predicted point p(q, x) moves with the identified parameters x, geometry and
every joint term, by the Jacobian J (3, k); with their covariance C (k, k) the point's covariance
is Σ = J C Jᵀ (mm², in the measuring frame).  A learned residual correction adds its posterior
covariance, whose trace returns to the process's prior far from its data.  The standard
uncertainty is the root of the summed traces (the rms radius of the error, mm):
:func:`predicted_sigma`.  It grows wherever the model is less known: harmonics identified over a
short arc of their joint, a compliance whose torques the poses never reached, a residual away
from its poses.  It says how well the calibration determined the model, not how far the real
robot is (the residual scatter says that).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from .covariance import ParameterCovariance
from .parameters import ParameterSpace
from .terms import JointInputs, TermSpec


def point_covariance(robot, covariance: ParameterCovariance, q: np.ndarray, targets: Sequence[str] | None = None,
                     inputs: JointInputs | None = None, chains: Sequence[str] | None = None) -> np.ndarray:
    """Σ (m, 3, 3) mm² of the predicted positions of ``robot`` at commanded joints q (m, n) rad
    (a tree's: on each row's chain, ``chains``)."""
    q = np.atleast_2d(np.asarray(q, float))
    spec = robot.terms.spec() if robot.terms is not None else TermSpec()
    space = ParameterSpace.of(robot, None, spec)
    known = [n for n in covariance.names if n in set(space.names)]
    keep = [covariance.names.index(n) for n in known]
    C = covariance.matrix[np.ix_(keep, keep)]
    if robot.tree is not None and targets is None:
        targets = chains
    target_idx = None if targets is None else space.target_index(targets)
    chain = None if robot.tree is None else robot.tree.index(chains)
    Jc, _, _ = space.jacobian_columns(np.zeros(space.size), q, target_idx, frames=True,
                                      joints=space.joint_data(q, inputs), chain=chain)
    J = Jc[space.index(known)][:, :, :3]  # (k, m, 3)
    return np.einsum("kma,kmb->mab", J, np.tensordot(C, J, axes=(1, 0)))  # C J first: one pass over the poses


def point_sigma(robot, covariance: ParameterCovariance, q: np.ndarray, targets: Sequence[str] | None = None,
                inputs: JointInputs | None = None, chains: Sequence[str] | None = None) -> np.ndarray:
    """The standard uncertainty (m,) mm of each predicted position from the parameters alone: √tr Σ."""
    S = point_covariance(robot.replace(residual=None), covariance, q, targets, inputs, chains)
    return np.sqrt(np.maximum(np.einsum("mii->m", S), 0.0))


def predicted_sigma(robot, q: np.ndarray, targets: Sequence[str] | None = None,
                    inputs: JointInputs | None = None, chains: Sequence[str] | None = None) -> np.ndarray:
    """The whole model's predicted position uncertainty (m,) mm at commanded joints q (m, n) rad:
    √(tr J C Jᵀ + tr Σ_residual), the parameters' part where the robot carries their covariance,
    the residual process's where it has one (a process saved without its noise level adds none)."""
    q = np.atleast_2d(np.asarray(q, float))
    var = np.zeros(len(q))
    if robot.uncertainty is not None:
        var += point_sigma(robot, robot.uncertainty, q, targets, inputs, chains) ** 2
    if robot.residual is not None:
        var += np.nan_to_num(robot.residual.position_variance(q))
    return np.sqrt(var)


#: where an uncertainty map draws its joint sets: among those whose TCP lies in the box the measured
#: points span (the default: where the cell works), or over each joint's calibrated range
MAP_OVER = ("workspace", "joints")
#: the measured points' box grows by this share of its size on each side, for the map
BOX_MARGIN = 0.1


@dataclass(frozen=True)
class UncertaintyMap:
    """Predicted TCP positions (m, 3) mm and their standard uncertainty (m,) mm at joint sets
    drawn over the region the model was calibrated on (each joint's range, in any combination:
    configurations the poses never took are among them, and show where the model extrapolates),
    kept where their TCP lies in ``box`` ((2, 3) mm, the measured points' box, base frame) with
    ``over`` ``workspace``; at_poses: the same σ at the calibration poses themselves."""

    position: np.ndarray
    sigma: np.ndarray
    at_poses: np.ndarray | None = None
    over: str = "joints"
    box: np.ndarray | None = None

    def summary(self) -> dict:
        out = {"points": int(self.sigma.size), "over": self.over, **_spread(self.sigma)}
        if self.box is not None:
            out["box_mm"] = self.box.tolist()
        if self.at_poses is not None:
            out["at_calibration_poses"] = _spread(self.at_poses)
        return out

    def brightest(self, share: float = 0.1) -> np.ndarray:
        """Where the largest σ lie: the mean position (3,) mm of the top ``share`` of the points."""
        top = self.sigma >= np.quantile(self.sigma, 1.0 - share)
        return self.position[top].mean(axis=0)


def _spread(sigma: np.ndarray) -> dict:
    return {"median_mm": float(np.median(sigma)), "p95_mm": float(np.percentile(sigma, 95)),
            "max_mm": float(np.max(sigma))}


def in_base(robot, points: np.ndarray) -> np.ndarray:
    """Points (…, 3) mm of the measuring frame in the robot's base frame."""
    B = np.linalg.inv(robot.base)
    return points @ B[:3, :3].T + B[:3, 3]


def _keep_inside(robot, q: np.ndarray, p: np.ndarray, box: np.ndarray, kept_q: list, kept_p: list) -> int:
    """Append the joint sets q and TCPs p (mm) whose TCP lies in ``box`` (the robot's base frame);
    how many they were."""
    local = in_base(robot, p)
    inside = np.all((local >= box[0]) & (local <= box[1]), axis=1)
    kept_q.append(q[inside])
    kept_p.append(p[inside])
    return int(np.count_nonzero(inside))


def uncertainty_map(robot, q_low: np.ndarray, q_high: np.ndarray, n: int = 2000, seed: int = 0,
                    at_poses: np.ndarray | None = None, box: np.ndarray | None = None) -> UncertaintyMap:
    """The whole model's σ of the TCP at ``n`` joint sets drawn uniformly (seeded) between q_low
    and q_high (rad), and at_poses: σ already worked out at the calibration poses, kept beside them.
    ``box`` ((2, 3) mm, the robot's base frame): only joint sets whose TCP lies in it (drawn in rounds of
    candidates; where too few fall in it, the joint ranges' own draw)."""
    rng = np.random.default_rng(seed)
    q_low, q_high = np.asarray(q_low, float), np.asarray(q_high, float)
    # a tree's joint sets take its chains in turn: every tip mapped over the same region
    names = None if robot.tree is None else robot.tree.names

    def chains(m):
        return None if names is None else [names[i % len(names)] for i in range(m)]

    if box is not None:
        # a learned correction is costly on every candidate and moves none by more than its bound:
        # the model without it says which candidates cannot be in the box
        bound = 0.0 if robot.residual is None else robot.residual.position_bound()
        plain = robot if robot.residual is None else robot.replace(residual=None)
        kept_q, kept_p, got = [], [], 0
        for _ in range(20):  # rounds of candidates: a box a tenth of the reach keeps a few per cent
            q = robot.couple(rng.uniform(q_low, q_high, (10 * n, len(q_low))))
            p = plain.positions(q, chains=chains(len(q)))
            if plain is not robot:
                local = in_base(robot, p)
                near = np.flatnonzero(np.all((local >= box[0] - bound) & (local <= box[1] + bound), axis=1))
                # the correction on the near candidates in draw order, a batch at a time, until enough
                # are inside: the map keeps the first n inside, and each pose's correction is its own
                start, size = 0, n + n // 4
                while start < len(near) and got < n:
                    part, start = near[start:start + size], start + size
                    new = _keep_inside(robot, q[part], robot.positions(q[part]), box, kept_q, kept_p)
                    got += new
                    # the next batch sized by the share of this one inside, with a quarter to spare
                    size = max(n // 4, int(1.25 * (n - got) * len(part) / max(new, 1)))
            else:
                got += _keep_inside(robot, q, p, box, kept_q, kept_p)
            if got >= n:
                break
        q, p = np.concatenate(kept_q)[:n], np.concatenate(kept_p)[:n]
        if len(q) >= n // 4:
            return UncertaintyMap(p, predicted_sigma(robot, q, chains=chains(len(q))), at_poses, "workspace", box)
    q = robot.couple(rng.uniform(q_low, q_high, (n, len(q_low))))
    return UncertaintyMap(robot.positions(q, chains=chains(n)), predicted_sigma(robot, q, chains=chains(n)), at_poses)


def known_targets(robot, meas) -> list[str] | None:
    """The measurements' reflectors where the robot knows them all, else None (its tool)."""
    return meas.targets if meas.targets is not None and all(t in robot.target_names for t in meas.targets) else None


def tcp_map(robot, meas, seed: int | None = 0, over: str = "workspace") -> UncertaintyMap | None:
    """The predicted TCP's σ over the region ``robot`` was calibrated on (``over`` ``workspace``: where its
    TCP lies in the box the measured points span; ``joints``: anywhere in the joint ranges) and at its
    calibration poses ``meas`` (None without a covariance or a region), the whole model's."""
    if robot.uncertainty is None or robot.region is None:
        return None
    at_poses = predicted_sigma(robot, meas.q, known_targets(robot, meas), meas.inputs, meas.chain)
    box = None
    if over == "workspace":
        points = in_base(robot, robot.positions(meas.q, chains=meas.chain))  # the TCP at the calibration poses
        lo, hi = points.min(axis=0), points.max(axis=0)
        pad = BOX_MARGIN * np.maximum(hi - lo, 1.0)
        box = np.stack([lo - pad, hi + pad])
    return uncertainty_map(robot, robot.region.lo, robot.region.hi, seed=seed or 0, at_poses=at_poses, box=box)


def region_note(robot, q: np.ndarray, targets: Sequence[str] | None = None,
                inputs: JointInputs | None = None, chains: Sequence[str] | None = None) -> str | None:
    """What to say of poses q (m, n) rad the model knows less well than its calibration poses:
    those whose predicted position uncertainty exceeds
    :data:`~robocal.model.region.SIGMA_FACTOR` times its median there (with a covariance), else
    those beyond the joint ranges it was calibrated on; None when there are none."""
    region = robot.region
    if region is None:
        return None
    faded = correction_note(robot.residual, q)
    if robot.uncertainty is not None and region.sigma_mm:
        text = region.describe_sigma(predicted_sigma(robot, np.atleast_2d(q), targets, inputs, chains))
    else:
        text = region.describe(q)
        text = None if text is None else f"{text}: the model is extrapolated there; expect larger errors"
    return "; ".join(t for t in (text, faded) if t) or None


def correction_note(correction, q: np.ndarray) -> str | None:
    """The poses q (m, n) rad beyond the data of a learned correction, or None: where less than half
    of it is kept (the fringe of its data, where a little is, holds a twentieth of its own held-out
    poses by construction), and where none is."""
    if correction is None:
        return None
    weight = correction.weight(np.atleast_2d(np.asarray(q, float)))
    partly, gone = int(np.sum(weight < 0.5)), int(np.sum(weight <= 1e-9))
    if partly == 0:
        return None
    return (f"{partly} of {len(weight)} poses lie beyond the data of the learned correction ({correction.kind}): less "
            f"than half of it is kept there, none at {gone} of them, where the model is its parametric part alone")
