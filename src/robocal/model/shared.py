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

from dataclasses import dataclass

import numpy as np

from .measurements import Measurements


def groups_of(meas: Measurements) -> np.ndarray:
    """Each row's group: the camera rows of one pose (its joints, or its pose_id) and one camera;
    −1 for other rows."""
    if meas.views is None:
        return np.full(meas.n_poses, -1)
    labels = np.array(meas.pose_ids, dtype=str) if meas.pose_ids is not None else \
        np.unique(np.round(meas.q, 9), axis=0, return_inverse=True)[1].ravel().astype(str)
    pose = np.unique(labels, return_inverse=True)[1].ravel()
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
