"""The choice among candidate models: the simplest that predicts held-out poses as well as the
best, by a paired test on their held-out errors.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...model.terms import TERMS
from ..config import LEARNED
from ..fit.parametric import Fit
from .crossval import FoldData, rms
from .trees import TreeCandidate

#: the joint terms in the order ``auto`` tries them (each term's ``rung``: the cheaper first)
TRIAL_ORDER: tuple[str, ...] = tuple(sorted(TERMS, key=lambda t: TERMS[t].rung))


def with_term(terms: tuple[str, ...], term: str) -> tuple[str, ...]:
    """``terms`` and ``term``, in registry order (the order of their parameters)."""
    return tuple(t for t in TERMS if t in terms or t == term)
#: relative difference of cross-validated RMS within which the simpler model is kept
TIE = 0.01
#: a simpler model is kept unless the paired test says it predicts held-out poses worse at this level
SIGNIFICANCE = 0.01


def model_name(terms) -> str:
    terms = [t for t in (*TERMS, *LEARNED) if t in terms]
    return "+".join(terms) if terms else "geometric"


def learned_of(name: str) -> str:
    """The learned part of a model's name (``trees``, ``residual``, ``trees+residual``; '' for none)."""
    return "+".join(t for t in LEARNED if t in name.split("+"))




def worse_p_value(simple: np.ndarray, best: np.ndarray, groups: np.ndarray) -> float:
    """One-sided p-value of "the simpler model predicts held-out poses worse than the best":
    a paired t-test on the per-pose difference of squared held-out errors (reflectors of one
    pose summed, since they share the pose's joint errors)."""
    from scipy.special import stdtr  # Student's t distribution function

    d = np.bincount(groups, np.sum(simple**2, axis=1) - np.sum(best**2, axis=1))
    if len(d) < 3 or not np.any(d):
        return 1.0
    spread = d.std(ddof=1)
    if spread == 0:
        return 0.0 if d.mean() > 0 else 1.0
    return float(stdtr(len(d) - 1, -d.mean() / (spread / np.sqrt(len(d)))))


@dataclass
class Candidate:
    """One rung of the ladder: its terms, its learned correction ('', ``residual``, ``trees``,
    ``trees+residual``), its parametric fit, its held-out errors, and what its correction's
    fit on all the poses starts from (the process's kernels, the trees)."""

    terms: tuple[str, ...]
    learned: str
    fit: Fit
    errors: np.ndarray
    kernels: tuple | None = None
    trees: TreeCandidate | None = None
    data: FoldData | None = None

    @property
    def residual(self) -> bool:
        return bool(self.learned)

    @property
    def name(self) -> str:
        return model_name(self.terms + tuple(self.learned.split("+")))

    @property
    def cv_rms(self) -> float:
        return rms(self.errors)


def choose(candidates: list[Candidate], groups: np.ndarray, significance: float = SIGNIFICANCE) -> Candidate:
    """The simplest candidate (the first, in ladder order) that predicts held-out poses as well
    as the best one: within :data:`TIE` of its RMS, or not worse by the paired test at
    ``significance``.  A richer model must earn its place beyond the luck of the folds, and
    never predicts the held-out poses worse than the first (geometry)."""
    simplest = candidates[0]
    eligible = [simplest] + [c for c in candidates[1:] if c.cv_rms < simplest.cv_rms]
    best = min(eligible, key=lambda c: c.cv_rms)
    for c in eligible:
        if c is best or c.cv_rms <= best.cv_rms * (1 + TIE) or \
                worse_p_value(c.errors, best.errors, groups) >= significance:
            return c
    return best
