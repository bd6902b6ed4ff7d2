"""The learned corrections a calibrated model may carry, one interface: a Gaussian process
(:mod:`robocal.model.residual`), gradient-boosted trees (:mod:`robocal.model.trees`), or the
trees with a process on what they leave (:class:`Stacked`); and the reader of their files.

Each predicts δ (m, 3 or 6) at commanded joints (``predict``), the trace of its position error
covariance (``position_variance``, mm²), adds itself to a pose (``correct``), says what it took
from the data (``dof``) and serialises to a plain dict (``to_dict``) whose ``kind`` names it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .residual import ResidualModel, apply_correction
from .trees import TreeResidual


@dataclass(frozen=True, eq=False)
class Stacked:
    """Trees, then a Gaussian process fitted to what the trees leave: their corrections add, and
    so do their variances (inside the data the trees' own error is the process's to say: the
    trees part is built with ``inside`` 0)."""

    trees: TreeResidual
    process: ResidualModel
    kind = "trees+residual"

    @property
    def parts(self) -> tuple:
        return (self.trees, self.process)

    @property
    def axes(self) -> np.ndarray:
        return self.trees.axes

    @property
    def outputs(self) -> int:
        return max(self.trees.outputs, self.process.outputs)

    @property
    def n_joints(self) -> int:
        return self.trees.n_joints

    @property
    def dof(self) -> float:
        return float(self.trees.dof + self.process.dof)

    def predict(self, q: np.ndarray, positions: bool = False) -> np.ndarray:
        out = np.zeros((len(np.atleast_2d(q)), self.outputs))
        for part in self.parts:
            d = part.predict(q, positions)
            out[:, :d.shape[1]] += d
        return out

    def position_bound(self) -> float:
        """The largest |δp| (mm) the two parts add anywhere."""
        return self.trees.position_bound() + self.process.position_bound()

    def position_variance(self, q: np.ndarray) -> np.ndarray:
        return self.trees.position_variance(q) + np.nan_to_num(self.process.position_variance(q))

    def weight(self, q: np.ndarray) -> np.ndarray:
        """The share of the correction kept at q: the larger of the two parts' (each fades on its own)."""
        return np.maximum(self.trees.weight(q), self.process.weight(q))

    def correct(self, q, R, p, base_rotation, rotations: bool = True):
        return apply_correction(self, q, R, p, base_rotation, rotations)

    def summary(self) -> dict:
        return {"kind": "gradient-boosted trees, then a gaussian process on what they leave",
                "trees": self.trees.summary(), "process": self.process.summary(),
                **({"effective_dof": self.dof} if np.isfinite(self.dof) else {})}

    def to_dict(self) -> dict:
        return {"kind": "stacked: trees, then a gaussian process", "trees": self.trees.to_dict(),
                "process": self.process.to_dict()}


Correction = ResidualModel | TreeResidual | Stacked


def correction_from_dict(d: dict) -> Correction:
    """The correction a sidecar file holds, by its ``kind`` (a file without one, from before the
    trees, is a Gaussian process)."""
    kind = str(d.get("kind", "gaussian"))
    if kind.startswith("stacked"):
        return Stacked(TreeResidual.from_dict(d["trees"]), ResidualModel.from_dict(d["process"]))
    if kind.startswith("gradient-boosted"):
        return TreeResidual.from_dict(d)
    if kind.startswith("gaussian"):
        return ResidualModel.from_dict(d)
    raise ValueError(f"unknown kind of correction {kind!r} (gaussian processes, gradient-boosted trees, stacked)")
