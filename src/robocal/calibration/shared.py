"""Errors a pose's camera rows share: the markers one camera saw at one pose are not independent looks.

The markers of one pose share the flange's unmodelled error, and one camera's detector bias and
its view of them; what a camera row's pixel error holds is then e = b_g + ε, with b_g (px, per
image axis) common to the rows of group g (one pose, one camera) and ε the row's own.  Weighed as
if the n rows of a group were n independent looks, the fit would take b_g as n times the
evidence it is and buy it with geometry.  With ρ = σ_b²/σ_ε² the group's covariance is
σ_ε² (I + ρ 11ᵀ), whitened by

    W_g = (I − c_g/n_g 11ᵀ) / σ_ε,   c_g = 1 − 1/√(1 + n_g ρ):

the rows' spread about their mean keeps its full weight, their mean counts once, as one look
with σ² = σ_ε²/n_g + σ_b².  ρ is estimated from the residuals (variance components: the spread
within the groups gives σ_ε², their means σ_b²), and the fit repeated until it settles.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..exceptions import Note
from ..model.measurements import Measurements
from .config import CalibrationConfig
from .methods import Estimate, fit_lm
from .noise import NoiseEstimate

#: relative change of ρ below which the weights have settled
SETTLED = 2e-2
#: refits allowed to the settling
MAX_ROUNDS = 4
#: a shared part below this share of a row's variance (σ_b² < 1 % of σ_ε²) is not worth modelling
NEGLIGIBLE = 1e-2


def groups_of(meas: Measurements) -> np.ndarray:
    """Each row's group: the camera rows of one pose (its joints, or its pose_id) and one camera;
    −1 for other rows."""
    if meas.views is None:
        return np.full(meas.n_poses, -1)
    from .crossval import pose_groups

    pose = pose_groups(meas)
    camera = meas.views.index
    key = np.where(camera >= 0, pose * (len(meas.views.names) + 1) + camera, -1)
    out = np.full(meas.n_poses, -1)
    seen = key >= 0
    out[seen] = np.unique(key[seen], return_inverse=True)[1].ravel()
    return out


@dataclass(frozen=True)
class SharedErrors:
    """The ratio ρ = σ_b²/σ_ε² of the error a group's camera rows share to each row's own."""

    ratio: float

    def transform(self, meas: Measurements):
        """The sparse (m, m) matrix I − S that whitens the rows' shared error (up to 1/σ_ε), S
        holding c_g/n_g within each group (:mod:`robocal.calibration.shared`)."""
        from scipy import sparse

        g = groups_of(meas)
        rows = np.flatnonzero(g >= 0)
        n = np.bincount(g[rows])
        c = 1.0 - 1.0 / np.sqrt(1.0 + n * self.ratio)
        order = rows[np.argsort(g[rows], kind="stable")]
        starts = np.concatenate([[0], np.cumsum(n)])
        i, j = [], []
        for k in range(len(n)):  # a group's rows, every pair
            members = order[starts[k]:starts[k + 1]]
            i.append(np.repeat(members, len(members)))
            j.append(np.tile(members, len(members)))
        i, j = np.concatenate(i), np.concatenate(j)
        values = -(c / n)[g[i]]
        m = meas.n_poses
        return sparse.identity(m, format="csr") + sparse.csr_matrix((values, (i, j)), shape=(m, m))


def decorrelate(M, values: np.ndarray) -> np.ndarray:
    """``values`` (…, m, d) with M (m, m) applied along the rows' axis."""
    if M is None:
        return values
    v = np.asarray(values)
    moved = np.moveaxis(v, -2, 0)
    out = M @ moved.reshape(moved.shape[0], -1)
    return np.moveaxis(np.asarray(out).reshape(moved.shape), 0, -2)


def estimate_ratio(errors: np.ndarray, meas: Measurements) -> tuple[float, float, float] | None:
    """(ρ, σ_ε, σ_b) px from the camera rows' errors (m, 3; pixels in the first two slots): the
    spread of each group's rows about their mean (2(n_g − 1) values each) gives σ_ε², the groups'
    means beyond what σ_ε gives them σ_b²; None where no group holds two rows."""
    g = groups_of(meas)
    rows = g >= 0
    if not rows.any():
        return None
    e, g = errors[rows, :2], g[rows]
    n = np.bincount(g)
    if not np.any(n >= 2):
        return None
    mean = np.stack([np.bincount(g, e[:, a]) / n for a in range(2)], axis=1)
    within = float(np.sum((e - mean[g]) ** 2))
    dof = 2.0 * float(np.sum(n - 1))
    s2 = within / dof
    shared = float(np.mean(np.sum(mean ** 2, axis=1) / 2.0 - s2 / n))
    s2b = max(shared, 0.0)
    return (s2b / s2 if s2 > 0 else 0.0), float(np.sqrt(s2)), float(np.sqrt(s2b))


def weigh_shared(est: Estimate, config: CalibrationConfig, noise: NoiseEstimate
                 ) -> tuple[Estimate, NoiseEstimate, list[str]]:
    """Camera rows: the share of their error a pose's rows in one camera have in common (ρ),
    estimated from the residuals, and the fit repeated with the rows weighed by it until ρ settles."""
    from .weighting import reweigh

    problem = est.problem
    if problem.views is None or not (config.least_squares and est.optimization.status == "converged"):
        return est, noise, []
    found = estimate_ratio(problem.errors(est.x)[0], problem.meas)
    if found is None or found[0] < NEGLIGIBLE:
        return est, noise, []
    ratio = found[0]
    for _ in range(MAX_ROUNDS):
        setup = replace(problem.setup, shared=SharedErrors(ratio))
        problem = setup.problem(problem.names)
        lm = fit_lm(problem, est.x, config)
        est = Estimate(problem, est.optimization.then(lm, method=est.optimization.method, message=(
            f"{est.optimization.message}; a pose's camera rows weighed as sharing an error (ρ {ratio:.3g}): "
            f"{lm.message}"), history=est.optimization.history), lm.x, est.reexpression_gap_mm)
        est, noise = reweigh(est, config)
        found = estimate_ratio(problem.errors(est.x)[0], problem.meas)
        if lm.status != "converged" or found is None or abs(found[0] / ratio - 1.0) <= SETTLED:
            break
        ratio = max(found[0], NEGLIGIBLE)
    _, own, common = found if found is not None else (ratio, float("nan"), float("nan"))
    n = np.bincount(groups_of(problem.meas)[groups_of(problem.meas) >= 0])
    return est, noise, [Note(f"a pose's camera rows share an error: σ {common:.3g} px common to the markers one camera "
                             f"saw at one pose, {own:.3g} px each row's own; what they share counts once for each of "
                             f"the {len(n)} groups (pose and camera), not once for each of its {np.mean(n):.3g} rows")]
