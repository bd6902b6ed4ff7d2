"""The measuring instrument's own uncertainty, per measured point, and what the fit leaves beyond it.

A laser tracker states the standard deviation of every point it measures (``sx, sy, sz`` mm,
``srx, sry, srz`` deg columns: rotation-vector components about the measuring frame's axes),
or its vendor states a maximum permissible error U = A + B·L (``--instrument "A+B/m"``: A mm,
B mm per metre of the distance L from the instrument, the measuring frame's origin), taken as
U = k·σ per axis with k = 2 unless the statement gives another (``"A+B/m k=3"``).

The residuals of a calibration are the instrument's noise plus everything the model leaves
out.  Weighing each point by its instrument σ alone would trust a near point fifty times more
than a far one even where the model's own misfit, the same everywhere, dominates both; so each
point is weighed by σ_eff² = σ_i² + τ², with τ the scatter the model leaves beyond the
instrument, per block (position, orientation), chosen so that Σ r²/σ_eff² equals its degrees
of freedom (the Paule–Mandel estimator of random-effects meta-analysis; τ = 0 where the
instrument explains the residuals).  The weights enter the fit as dimensionless factors
σ_eff,i / σ̄_eff (see :class:`InstrumentWeights`), and the block σ the fit estimates is then
the residual scatter σ̄_eff, in millimetres and radians as before.

Goodness of fit then compares the misfit with the instrument's noise alone: χ² = Σ r²/σ_i² on
N − (degrees of freedom the parameters use), whose reduced value says how far beyond the
instrument the model's residuals reach.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

import numpy as np

from ...exceptions import InputError
from ...model.measurements import Measurements
from ..judge.statistics import ChiSquared

#: the coverage factor of an MPE statement that gives none: U = 2σ
DEFAULT_COVERAGE = 2.0
#: relative change of the weights below which refitting would not move the solution
WEIGHTS_SETTLED = 0.02
#: refits allowed while τ settles
MAX_ROUNDS = 4

_NUMBER = r"[0-9]*\.?[0-9]+(?:[eE][-+]?[0-9]+)?"
_STATEMENT = re.compile(rf"^\s*({_NUMBER})\s*(?:\+\s*({_NUMBER})\s*/\s*m)?\s*(?:[,;]?\s*k\s*=\s*({_NUMBER}))?\s*$")


@dataclass(frozen=True)
class Instrument:
    """An MPE-style statement U = a + b·L: a (mm), b (mm per m), coverage k (U = k σ per axis)."""

    a: float
    b: float = 0.0
    coverage: float = DEFAULT_COVERAGE
    text: str = ""

    @classmethod
    def parse(cls, text: str, option: str = "instrument") -> Instrument:
        m = _STATEMENT.match(text or "")
        if not m:
            raise InputError(f"expected A+B/m (mm, mm per metre of distance; e.g. 0.015+0.006/m), optionally with "
                             f"k=K (U = K σ, default {DEFAULT_COVERAGE:g}), got {text!r}", option=option)
        a, b = float(m.group(1)), float(m.group(2) or 0.0)
        k = float(m.group(3)) if m.group(3) else DEFAULT_COVERAGE
        if not all(math.isfinite(v) for v in (a, b, k)):
            raise InputError(f"the instrument's statement must give finite numbers, got {text!r}", option=option)
        if not (a > 0 or b > 0) or k <= 0:
            raise InputError(f"the instrument's statement must give an error > 0 and k > 0, got {text!r}",
                             option=option)
        return cls(a, b, k, text.strip())

    def sigma(self, position: np.ndarray) -> np.ndarray:
        """σ per axis (m, 3) mm of points at ``position`` (m, 3) mm in the measuring frame."""
        distance_m = np.linalg.norm(np.asarray(position, float), axis=-1) / 1000.0
        return np.repeat(((self.a + self.b * distance_m) / self.coverage)[:, None], 3, axis=1)

    def sentence(self) -> str:
        stated = "as stated" if self.coverage != DEFAULT_COVERAGE else "the default"
        law = f"{self.a:g} mm + {self.b:g} mm/m × distance" if self.b else f"{self.a:g} mm"
        return f"--instrument {self.text!r}: U = {law}, taken as {self.coverage:g} σ per axis ({stated} coverage)"


def with_instrument(meas: Measurements, instrument: Instrument) -> Measurements:
    """The measurements with position σ per point from the statement (orientation σ as they were)."""
    from dataclasses import replace

    return replace(meas, sigma_position=instrument.sigma(meas.position))


@dataclass(frozen=True)
class InstrumentWeights:
    """τ per block (mm, rad) and the reference σ̄_eff (rms over the calibration poses) that make
    each point's weight factor σ_eff,i / σ̄_eff dimensionless; None where a block has no σ."""

    tau_position: float | None
    tau_orientation: float | None
    ref_position: float | None
    ref_orientation: float | None

    @classmethod
    def of(cls, meas: Measurements, tau_position: float | None, tau_orientation: float | None) -> InstrumentWeights:
        def ref(sigma, tau):
            return None if sigma is None or tau is None else float(np.sqrt(np.mean(sigma**2) + tau**2))

        return cls(tau_position, tau_orientation, ref(meas.sigma_position, tau_position),
                   ref(meas.sigma_orientation, tau_orientation))

    def factors(self, meas: Measurements) -> tuple[np.ndarray | None, np.ndarray | None]:
        """σ_eff,i / σ̄_eff per residual (m, 3) of each block of ``meas`` (None: weighed alike)."""
        def factor(sigma, tau, ref):
            if sigma is None or tau is None or not ref:
                return None
            return np.sqrt(sigma**2 + tau**2) / ref

        return (factor(meas.sigma_position, self.tau_position, self.ref_position),
                factor(meas.sigma_orientation, self.tau_orientation, self.ref_orientation))

    def settled(self, other: InstrumentWeights | None, meas: Measurements) -> bool:
        """Whether these weights differ from ``other``'s by less than :data:`WEIGHTS_SETTLED` anywhere."""
        if other is None:
            return False
        for a, b in zip(self.factors(meas), other.factors(meas)):
            if (a is None) != (b is None) or (a is not None and np.max(np.abs(a / b - 1.0)) > WEIGHTS_SETTLED):
                return False
        return True


def paule_mandel(r2: np.ndarray, s2: np.ndarray, dof: float) -> float:
    """τ ≥ 0 with Σ r²/(s² + τ²) = dof (0 when the instrument's σ already explains the residuals)."""
    r2, s2 = np.ravel(r2), np.ravel(s2)
    if dof <= 0 or np.sum(r2 / s2) <= dof:
        return 0.0
    lo, hi = 0.0, float(np.sum(r2) / dof) + float(np.max(s2))  # at hi every term is below r²/(Σr²/dof)
    for _ in range(200):  # bisection on τ²: the sum falls monotonically
        mid = 0.5 * (lo + hi)
        if np.sum(r2 / (s2 + mid)) > dof:
            lo = mid
        else:
            hi = mid
        if hi - lo <= 1e-12 * max(hi, 1e-30):
            break
    return math.sqrt(0.5 * (lo + hi))


@dataclass(frozen=True)
class InstrumentFit(ChiSquared):
    """The misfit against the instrument's own noise: χ² = Σ r²/σ_i² over the blocks with σ, its
    degrees of freedom, and τ, the scatter per axis the model leaves beyond the instrument (mm,
    rad); source says where the σ came from."""

    source: str
    chi2: float
    dof: float
    tau_position: float | None
    tau_orientation: float | None
    sigma_position: tuple[float, float, float] | None  # min, median, max (mm)
    sigma_orientation: tuple[float, float, float] | None  # rad

    def sentence(self) -> str:
        parts = []
        if self.sigma_position is not None:
            parts.append(f"median σ {self.sigma_position[1]:.3g} mm")
        if self.sigma_orientation is not None:
            parts.append(f"{math.degrees(self.sigma_orientation[1]):.3g}°")
        beyond = []
        if self.tau_position is not None:
            beyond.append(f"{self.tau_position:.3g} mm")
        if self.tau_orientation is not None:
            beyond.append(f"{math.degrees(self.tau_orientation):.3g}°")
        red = self.reduced_chi2
        text = (f"instrument ({self.source}): {', '.join(parts)}; χ² against it {self.chi2:.4g} on "
                f"{self.dof:.0f} degrees of freedom (reduced {red:.3g}, p {self.p_value:.3g})")
        if any(t for t in (self.tau_position, self.tau_orientation)):
            text += f": the model leaves {' and '.join(beyond)} per axis beyond the instrument's noise"
        else:
            text += ": the residuals are within the instrument's noise"
        return text

    def to_dict(self) -> dict:
        def spread(v, scale=1.0):
            return None if v is None else {"min": v[0] * scale, "median": v[1] * scale, "max": v[2] * scale}

        return {"source": self.source, "chi2": self.chi2, "dof": self.dof, "reduced_chi2": self.reduced_chi2,
                "p_value": self.p_value,
                "beyond_instrument_position_mm": self.tau_position,
                "beyond_instrument_orientation_deg": None if self.tau_orientation is None else
                math.degrees(self.tau_orientation),
                "sigma_position_mm": spread(self.sigma_position),
                "sigma_orientation_deg": spread(self.sigma_orientation, 180.0 / math.pi)}


def _spread(sigma: np.ndarray | None):
    return None if sigma is None else (float(np.min(sigma)), float(np.median(sigma)), float(np.max(sigma)))


def beyond_instrument(problem, x: np.ndarray, used: tuple[float, float]) -> InstrumentWeights:
    """τ per block from the residuals at x, with the degrees of freedom the parameters use in
    each block (``used``: position, orientation; see :func:`robocal.calibration.fit.noise.leverage_split`)."""
    meas = problem.meas
    dp, dr = problem.errors(x)
    used_p, used_r = used
    tau_p = None if meas.sigma_position is None else paule_mandel(dp**2, meas.sigma_position**2, dp.size - used_p)
    tau_r = None if meas.sigma_orientation is None or dr is None else \
        paule_mandel(dr**2, meas.sigma_orientation**2, dr.size - used_r)
    return InstrumentWeights.of(meas, tau_p, tau_r)


def instrument_fit(problem, x: np.ndarray, source: str, used: tuple[float, float]) -> InstrumentFit:
    """χ² of the residuals at x against the instrument's σ alone, and τ beyond it."""
    meas = problem.meas
    dp, dr = problem.errors(x)
    used_p, used_r = used
    chi2, dof = 0.0, 0.0
    if meas.sigma_position is not None:
        chi2 += float(np.sum((dp / meas.sigma_position) ** 2))
        dof += dp.size - used_p
    use_r = meas.sigma_orientation is not None and dr is not None
    if use_r:
        chi2 += float(np.sum((dr / meas.sigma_orientation) ** 2))
        dof += dr.size - used_r
    tau = beyond_instrument(problem, x, used)
    return InstrumentFit(source, chi2, dof, tau.tau_position, tau.tau_orientation, _spread(meas.sigma_position),
                         _spread(meas.sigma_orientation) if use_r else None)


@dataclass(frozen=True)
class KindWeights:
    """Tracker rows, rows that touched points or planes and rows a camera saw, each weighed by its
    own σ (mm; px for camera rows): the tracker's noise, the probe's seat in a socket and a camera's
    pixels are not one scatter.  The interface of :class:`InstrumentWeights` (relative factors per
    residual), so the problem weighs by it; a kind the data have not is None."""

    tracker: float | None
    contact: float | None
    camera: float | None = None

    @property
    def present(self) -> dict[str, float]:
        return {k: v for k, v in (("tracker", self.tracker), ("contact", self.contact), ("camera", self.camera))
                if v is not None}

    @property
    def ref(self) -> float:
        return float(np.sqrt(np.mean([v ** 2 for v in self.present.values()])))

    def factors(self, meas: Measurements) -> tuple[np.ndarray | None, np.ndarray | None]:
        kind = row_kinds(meas)  # a subset may hold one kind only
        sigma = np.array([self.tracker or 0.0, self.contact or 0.0, self.camera or 0.0])[kind]
        return np.repeat((sigma / self.ref)[:, None], 3, axis=1), None

    def settled(self, other, meas: Measurements) -> bool:
        if not isinstance(other, KindWeights) or set(self.present) != set(other.present):
            return False
        return all(abs(v / other.present[k] - 1.0) <= WEIGHTS_SETTLED for k, v in self.present.items())

    def sentence(self) -> str:
        said = {"tracker": "tracker rows σ {:.3g} mm", "contact": "rows that touched points or planes σ {:.3g} mm",
                "camera": "camera rows σ {:.3g} px"}
        listed = ", ".join(said[k].format(v) for k, v in self.present.items())
        return f"{listed} (each estimated from its own residuals)"


#: the kinds of rows, as :func:`row_kinds` numbers them
KINDS = ("tracker", "contact", "camera")


def row_kinds(meas: Measurements) -> np.ndarray:
    """Each row's kind: 0 a tracker's, 1 one that touched a point or plane, 2 one a camera saw."""
    kind = np.zeros(meas.n_poses, dtype=int)
    c = meas.constraints
    if c is not None:
        kind[c.rows] = 1
    if meas.camera is not None:
        kind[np.array([bool(x) for x in meas.camera])] = 2
    return kind


def several_kinds(meas: Measurements) -> bool:
    """Whether the rows are of more than one kind (each then weighed by its own σ)."""
    return len(np.unique(row_kinds(meas))) > 1


def kind_weights(problem, x: np.ndarray) -> KindWeights:
    """Each kind of rows' σ (mm, px) from its residuals at x, with the degrees of freedom the fit used
    in its rows (the hat matrix's trace over them) and, for contact rows, the eliminated points
    and planes."""
    c = problem.constraints
    kind = row_kinds(problem.meas)
    dp, _ = problem.errors(x)
    J = problem.residual_jacobian(x)
    Jp = J[:problem.n_position_rows()]
    inv = np.linalg.pinv(J.T @ J + problem.prior_information())
    planes = np.zeros(len(kind), bool) if c is None else c.rows_of("plane")
    sigma = []
    for k in range(len(KINDS)):
        rows = kind == k
        if not rows.any():
            sigma.append(None)
            continue
        mask = np.repeat(rows, 3)
        used = float(np.sum((Jp[mask].T @ Jp[mask]) * inv.T))
        # a plane row says one value (its offset along the normal), a point row three, a pixel two
        values = {0: 3 * int(rows.sum()), 1: 3 * int(rows.sum()) - 2 * int(planes.sum()) - (0 if c is None else
                                                                                          c.n_unknowns),
                  2: 2 * int(rows.sum())}[k]
        sigma.append(float(np.sqrt(np.sum(dp[rows] ** 2) / max(values - used, 1.0))))
    return KindWeights(*sigma)
