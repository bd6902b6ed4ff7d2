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
    −1 for other rows (worked out once a set of rows)."""
    cached = meas.__dict__.get("_shared_groups")
    if cached is not None:
        return cached
    out = np.full(meas.n_poses, -1)
    if meas.views is not None:
        labels = np.array(meas.pose_ids, dtype=str) if meas.pose_ids is not None else \
            np.unique(np.round(meas.q, 9), axis=0, return_inverse=True)[1].ravel()
        pose = np.unique(labels, return_inverse=True)[1].ravel()
        camera = meas.views.index
        key = np.where(camera >= 0, pose * (len(meas.views.names) + 1) + camera, -1)
        seen = key >= 0
        out[seen] = np.unique(key[seen], return_inverse=True)[1].ravel()
    object.__setattr__(meas, "_shared_groups", out)
    return out


@dataclass(frozen=True)
class Whitening:
    """W_g of :mod:`robocal.model.shared` for a set of rows: each group's rows in ``order``
    (contiguous from ``starts``), and each row's c_g/n_g (0 for rows in no group)."""

    order: np.ndarray
    starts: np.ndarray
    group: np.ndarray
    shrink: np.ndarray

    def apply(self, values: np.ndarray) -> np.ndarray:
        """``values`` (…, m, d) less each row's c_g/n_g times its group's sum (along the rows' axis)."""
        v = np.moveaxis(np.asarray(values, float), -2, 0)  # (m, …)
        flat = v.reshape(v.shape[0], -1)
        sums = np.add.reduceat(flat[self.order], self.starts[:-1], axis=0)  # (G, …)
        rows = self.group >= 0
        out = flat.copy()
        out[rows] -= self.shrink[rows, None] * sums[self.group[rows]]
        return np.moveaxis(out.reshape(v.shape), 0, -2)


@dataclass(frozen=True)
class SharedErrors:
    """The ratio ρ = σ_b²/σ_ε² of the error a group's camera rows share to each row's own."""

    ratio: float

    def transform(self, meas: Measurements) -> Whitening | None:
        """The whitening I − S of the rows' shared error (up to 1/σ_ε), S holding c_g/n_g within each
        group (:mod:`robocal.model.shared`); None where no row is in a group."""
        g = groups_of(meas)
        rows = np.flatnonzero(g >= 0)
        if not rows.size:
            return None
        n = np.bincount(g[rows])
        c = 1.0 - 1.0 / np.sqrt(1.0 + n * self.ratio)
        order = rows[np.argsort(g[rows], kind="stable")]
        shrink = np.zeros(meas.n_poses)
        shrink[rows] = (c / n)[g[rows]]
        return Whitening(order, np.concatenate([[0], np.cumsum(n)]), g, shrink)


def decorrelate(M: Whitening | None, values: np.ndarray) -> np.ndarray:
    """``values`` (…, m, d) whitened by M along the rows' axis (as they are without one)."""
    return values if M is None else M.apply(values)


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
