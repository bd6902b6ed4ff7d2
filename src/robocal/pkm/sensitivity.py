"""Pose errors of the 28-parameter error model and the paper's sensitivity study (Fig. 4–9)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .geometry import PARAM_NAMES, PKMGeometry, reduced_to_pose
from .kinematics import forward, rod_lengths


def pose_error(nominal: PKMGeometry, real: PKMGeometry, q) -> np.ndarray:
    """E = P° − P (…, 6) (Chen et al. eq. 14–17): the real mechanism's pose minus the nominal
    pose q, both at the rod lengths the nominal inverse kinematics commands for q."""
    P = reduced_to_pose(q)
    return forward(real, rod_lengths(nominal, P), P).pose - P


@dataclass
class Sensitivity:
    """Per case, the pose errors E (poses, 6): dx, dy, dz mm; dα, dβ, dγ rad."""

    cases: dict[str, dict[str, np.ndarray]]  # group → label → E

    def mean_table(self) -> dict[str, dict[str, list[float]]]:
        """Mean |E| per group, label and component."""
        return {g: {label: np.abs(E).mean(axis=0).tolist() for label, E in cs.items()} for g, cs in self.cases.items()}


def sensitivity(nominal: PKMGeometry, q, unit: float = 1.0) -> Sensitivity:
    """The paper's sensitivity study: ``unit`` mm of error on (1) each of limb 1's seven
    parameters alone, (2) each rod zero length alone, (3) each parameter type on all four
    limbs at once."""
    idx = {n: i for i, n in enumerate(PARAM_NAMES)}

    def E(names):
        d = np.zeros(28)
        d[[idx[n] for n in names]] = unit
        return pose_error(nominal, nominal.with_errors(d), q)

    limb1 = {n: E([n]) for n in ("dL1", "T1x", "T1y", "T1z", "B1x", "B1y", "B1z")}
    rods = {f"dL{i}": E([f"dL{i}"]) for i in range(1, 5)}
    types = {"dL": [f"dL{i}" for i in range(1, 5)]}
    for p in ("T", "B"):
        for a in ("x", "y", "z"):
            types[f"d{p}{a}"] = [f"{p}{i}{a}" for i in range(1, 5)]
    return Sensitivity({"limb 1": limb1, "rod zero lengths": rods,
                        "all four limbs": {label: E(names) for label, names in types.items()}})
