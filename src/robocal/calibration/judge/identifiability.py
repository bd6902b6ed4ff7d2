"""Which deviation parameters a set of measurements can determine.

From the identification Jacobian at the initial model and the measured joint sets,
parameters are taken in a priority order and kept when their column adds a new direction
to the span of the columns already kept (a Gram–Schmidt pass on the R factor of the
column-equilibrated Jacobian, so mm and rad columns compare fairly).  A parameter is
dropped when its column is zero (no effect on what was measured) or lies in the span of
kept columns (dependent: its effect can be produced by the named others).  The priority
order keeps the frames (base, tools) first and then the joints from the flange back to
the base, so that of two dependent parameters the more conventional one stays: with
parallel axes 2 ∥ 3, d3 is kept and d2 dropped (as in Wen et al. 2019); with a base
frame, θ1 and d1 fold into it; with a tool offset, the last joint's a, d, α, θ fold into
the tool.

Observability figures (Sun & Hollerbach) use the Jacobian with angle columns scaled by a
length L (mm per rad, default the arm's reach) so they compare across robots:
O1 = (σ1⋯σk)^(1/k)/√N, O2 = σmin/σmax, O3 = σmin, O4 = σmin²/σmax, N = number of poses.
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from dataclasses import dataclass, field, replace

import numpy as np

#: sin of the angle between a column and the span of the kept ones below which the column
#: counts as dependent.  Exact dependencies sit at ~1e-14; 1e-6 means a parameter would
#: need a million times the measurement noise to be told apart.
DEPENDENCY_TOL = 1e-6
#: relative size (after angle columns are scaled by L) below which a column is zero
ZERO_TOL = 1e-9
#: equilibrated condition number above which the identification is reported as ill-conditioned
ILL_CONDITIONED = 1e5

#: kinds of reason for leaving a parameter out
NO_EFFECT, DEPENDENT, SECOND_ORDER, STILL = "no_effect", "dependent", "second_order", "still_joint"
#: a joint term whose input (direction, time, torque) the poses never varied
UNVARIED = "unvaried"
#: what data of unknown points or planes cannot see at all: the frame they stand in, the length scale
UNOBSERVABLE = "unobservable"


@dataclass(frozen=True)
class Reason:
    """Why a parameter is not identified: structured data, rendered by :meth:`text`.

    kind: ``no_effect`` (zero Jacobian column), ``dependent`` (in the span of ``related``),
    ``second_order`` (dependent at the nominal model, separable only at the estimate, which
    did not improve the fit significantly: ``p_value`` of the F-test), or ``still_joint``
    (dependent on ``related`` once ``joints``, which never moved in the data, are held still:
    only their read-back jitter would separate it).  For a
    dependent parameter D, ``coefficients`` c_j (one per related K_j) say that a deviation
    δD moves the data as δK_j = c_j δD would: the estimate of K_j absorbs c_j·δD.
    """

    kind: str
    related: tuple[str, ...] = ()
    p_value: float | None = None
    coefficients: tuple[float, ...] = ()
    joints: tuple[int, ...] = ()
    #: ``unvaried``: what the data lack, and what motion would make the term visible
    detail: str = ""

    def text(self) -> str:
        if self.kind == NO_EFFECT:
            return "no effect on the measured data (zero Jacobian column)"
        if self.kind in (UNVARIED, UNOBSERVABLE):
            return self.detail
        others = ", ".join(self.related) or "the others"
        if self.kind == DEPENDENT:
            return f"dependent on {others} (not separable with these measurements)"
        if self.kind == STILL:
            which = ", ".join(map(str, self.joints))
            return (f"needs the motion of joint{'s' if len(self.joints) > 1 else ''} {which}, which never moved: "
                    f"absorbed by {others}")
        return (f"dependent on {others} at the nominal model; separable only to second order at the estimate, "
                f"which did not improve the fit significantly (F-test p={self.p_value:.2g})")

    def to_dict(self) -> dict:
        out = {"kind": self.kind, "related": list(self.related)}
        if self.coefficients:
            out["coefficients"] = list(self.coefficients)
        if self.p_value is not None:
            out["p_value"] = self.p_value
        if self.joints:
            out["joints"] = list(self.joints)
        if self.detail:
            out["detail"] = self.detail
        return out


def _joint_of(name: str) -> tuple[int, int]:
    m = re.fullmatch(r"(a|alpha|theta|d|beta)(\d+)", name)
    if not m:
        return (-1, 0)
    kind_order = {"theta": 0, "d": 1, "a": 2, "alpha": 3, "beta": 4}
    return (int(m.group(2)), kind_order[m.group(1)])


def priority(names: Sequence[str]) -> list[int]:
    """Indices of ``names`` in the order they are offered for keeping."""

    def key(i: int):
        n = names[i]
        if n.startswith("base_"):
            return (0, 0, i)
        if n.startswith("tool"):
            return (1, 0, i)
        joint, kind = _joint_of(n)
        return (2, -joint, kind)

    return sorted(range(len(names)), key=key)


@dataclass(frozen=True)
class Identifiability:
    """Outcome of the identifiability analysis.

    kept/dropped are parameter names; reasons maps each dropped name to its :class:`Reason`;
    singular_values and the O-figures are of the L-scaled Jacobian of the kept set;
    condition is the condition number of the column-equilibrated kept Jacobian.
    """

    kept: list[str]
    dropped: list[str]
    reasons: dict[str, Reason]
    singular_values: np.ndarray
    condition: float
    observability: dict[str, float]
    length_scale: float
    n_poses: int
    warnings: list[str] = field(default_factory=list)

    @property
    def rank(self) -> int:
        return len(self.kept)

    def absorbed_by(self, name: str) -> list[tuple[str, float]]:
        """Dropped parameters whose deviation the kept ``name`` estimates too, with coefficients:
        its value estimates δname + Σ c·δdropped."""
        return [(d, r.coefficients[r.related.index(name)]) for d, r in self.reasons.items()
                if r.kind != NO_EFFECT and name in r.related and r.coefficients]

    def with_changes(self, **changes) -> Identifiability:
        return replace(self, **changes)

    def to_dict(self) -> dict:
        return {
            "rank": self.rank,
            "condition_number": self.condition,
            "observability": dict(self.observability),
            "length_scale_mm_per_rad": self.length_scale,
            "singular_values": [float(s) for s in self.singular_values],
            "warnings": list(self.warnings),
        }


def observability(J_scaled: np.ndarray, n_poses: int) -> dict[str, float]:
    """O1–O4 from the singular values of an (already scaled) Jacobian."""
    s = np.linalg.svd(J_scaled, compute_uv=False)
    k = J_scaled.shape[1]
    if k == 0 or s.size < k or s[-1] <= 0:
        return {"O1": 0.0, "O2": 0.0, "O3": 0.0, "O4": 0.0}
    return {
        "O1": float(np.exp(np.mean(np.log(s))) / np.sqrt(n_poses)),
        "O2": float(s[-1] / s[0]),
        "O3": float(s[-1]),
        "O4": float(s[-1] ** 2 / s[0]),
    }


def _scan(R: np.ndarray, order: list[int], zero: np.ndarray, names: Sequence[str], tol: float,
          norms: np.ndarray):
    """Greedy Gram–Schmidt scan over the columns of R (equilibrated: column j of the Jacobian
    divided by norms[j]) in ``order``: kept indices and reasons."""
    basis: list[np.ndarray] = []
    kept: list[int] = []
    reasons: dict[str, Reason] = {names[i]: Reason(NO_EFFECT) for i in np.flatnonzero(zero)}
    for i in order:
        if zero[i]:
            continue
        v = R[:, i]
        r = v.copy()
        for _ in range(2):  # twice is enough (Kahan–Parlett)
            for b in basis:
                r -= (b @ r) * b
        size = np.linalg.norm(r)
        if size > tol:
            basis.append(r / size)
            kept.append(i)
            continue
        coef, *_ = np.linalg.lstsq(R[:, kept], v, rcond=None)
        biggest = [j for j in np.argsort(-np.abs(coef)) if abs(coef[j]) > 1e-3 * np.abs(coef).max()][:5]
        # equilibrated columns: J_i/n_i = Σ c_j J_kj/n_kj, so δ_i acts as δ_kj = c_j n_i/n_kj · δ_i
        reasons[names[i]] = Reason(DEPENDENT, tuple(names[kept[j]] for j in biggest),
                                   coefficients=tuple(float(coef[j] * norms[i] / norms[kept[j]]) for j in biggest))
    return sorted(kept), reasons


def analyse(J: np.ndarray, names: Sequence[str], angle_mask: np.ndarray, n_poses: int, length_scale: float, *,
            tol: float = DEPENDENCY_TOL, prefer: Sequence[str] = ()) -> Identifiability:
    """Identifiable subset of the columns of J (rows: stacked weighted residuals).

    J: (rows, k) derivative of the residuals (mm) with respect to the parameters (mm or
    rad, ``angle_mask`` True for rad).  ``prefer``: names offered for keeping before all
    others.
    """
    names = list(names)
    J = np.asarray(J, dtype=float)
    k = J.shape[1]
    scale = np.where(angle_mask, 1.0 / length_scale, 1.0)  # rad columns in mm per L-mm
    raw_norms = np.linalg.norm(J, axis=0)
    norms = raw_norms * scale
    zero = norms <= ZERO_TOL * max(norms.max() if k else 0.0, 1e-300)
    Jn = np.where(zero, 0.0, J / np.where(zero, 1.0, raw_norms))
    # Work in the k×k triangular factor: same column geometry as J, cheap for 10⁵ poses.
    R = np.linalg.qr(Jn, mode="r") if Jn.shape[0] > k else Jn
    first = set(prefer)
    order = priority(names)
    order = [i for i in order if names[i] in first] + [i for i in order if names[i] not in first]
    kidx, reasons = _scan(R, order, zero, names, tol, raw_norms)
    # Jn = Q R with orthonormal Q: singular values of column subsets (and of their
    # rescalings) come from the small R instead of the tall Jacobian.
    col_scale = np.where(zero, 0.0, raw_norms) * scale
    if kidx:
        sv = np.linalg.svd(R[:, kidx] * col_scale[kidx], compute_uv=False)
        sn = np.linalg.svd(R[:, kidx], compute_uv=False)
        cond = float(sn[0] / sn[-1]) if sn[-1] > 0 else float("inf")
    else:
        sv, cond = np.zeros(0), float("inf")
    warnings = []
    if cond > ILL_CONDITIONED:
        warnings.append(f"identification is ill-conditioned (condition number {cond:.3g}): the poses barely separate "
                        "some kept parameters; expect large uncertainties")
    return Identifiability(
        kept=[names[i] for i in kidx],
        dropped=[n for n in names if n in reasons],
        reasons=reasons,
        singular_values=sv,
        condition=cond,
        observability=observability(R[:, kidx] * col_scale[kidx], n_poses),
        length_scale=length_scale,
        n_poses=n_poses,
        warnings=warnings,
    )
