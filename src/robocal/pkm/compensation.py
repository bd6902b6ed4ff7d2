"""Compensation of the 2TPR&2TPS mechanism: the paper's eq. 18, its iteration, and the model.

- :func:`compensate_paper`: drive to L* = IK(P*), measure P, L = IK(P), find ΔL minimising
  sqrt(Σ (L*_i − L_i − ΔL_i)²) by PSO, command L* + ΔL (Chen et al. eq. 18).
- :func:`compensate_iterated`: that correction repeated, a fixed-point iteration on the machine.
- :func:`compensate_model`: command the identified model's inverse kinematics.
- :func:`simulate_compensation`: all of them on a simulated machine with planted errors.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from .. import options as opt
from ..exceptions import InputError
from ..optimize.swarm import pso_batch
from ..presets import chen2023 as paper
from .geometry import PKMGeometry, chen2023, reduced_to_pose
from .identify import identify_simulated
from .kinematics import equations, forward, rod_lengths, workspace_targets


@dataclass
class Compensation:
    """Commanded lengths and the poses reached, per target."""

    method: str
    L_command: np.ndarray  # (n, 4) mm
    reached: np.ndarray  # (n, 6) real poses
    error: np.ndarray  # (n, 3) reached position − target position, mm
    history: np.ndarray | None = None
    time_s: float = 0.0

    @property
    def mean_error(self) -> float:
        return float(np.linalg.norm(self.error, axis=1).mean())

    @property
    def max_error(self) -> float:
        return float(np.linalg.norm(self.error, axis=1).max())


def _measure(real: PKMGeometry, L, guess, noise: float, rng) -> tuple[np.ndarray, np.ndarray]:
    """What the machine does for commanded L, and what the tracker reads (position + noise)."""
    pose = forward(real, L, guess).pose
    return pose, pose[:, :3] + (rng.normal(0.0, noise, pose[:, :3].shape) if noise > 0 else 0.0)


def _nominal_lengths_at(nominal: PKMGeometry, measured: np.ndarray, q_target: np.ndarray) -> np.ndarray:
    """L = IK(P) of the paper: nominal rod lengths for the measured position, with the target's
    α and the β that the measured x implies (x = z tan β); the tracker gives no orientation."""
    x, y, z = measured[:, 0], measured[:, 1], measured[:, 2]
    return rod_lengths(nominal, reduced_to_pose(np.column_stack([y, z, q_target[:, 2], np.arctan2(x, z)])))


def _outcome(method: str, real: PKMGeometry, L_cmd, P_star, start: float, history=None) -> Compensation:
    reached = forward(real, L_cmd, P_star).pose
    return Compensation(method, L_cmd, reached, reached[:, :3] - P_star[:, :3], history, time.perf_counter() - start)


def compensate_paper(nominal: PKMGeometry, real: PKMGeometry, q_target, *, noise: float = 0.0, seed: int = 0,
                     pso: dict | None = None) -> Compensation:
    """Chen et al. eq. 18, one swarm per target, all advanced in one batch.  The minimum is
    ΔL = L* − L exactly; the PSO finds it to its accuracy."""
    start = time.perf_counter()
    rng = np.random.default_rng(seed)
    q_target = np.asarray(q_target, float)
    P_star = reduced_to_pose(q_target)
    L_star = rod_lengths(nominal, P_star)
    _, measured = _measure(real, L_star, P_star, noise, rng)
    target = (L_star - _nominal_lengths_at(nominal, measured, q_target))[:, None, :]
    box = np.full(4, paper.PSO_BOX)

    def fitness(X):
        return np.sqrt(np.sum((target - X) ** 2, axis=-1))

    dL, _, history = pso_batch(fitness, -box, box, len(q_target), seed=seed, **{**paper.PSO, **(pso or {})})
    return _outcome("paper (eq. 18, PSO)", real, L_star + dL, P_star, start, history)


def compensate_iterated(nominal: PKMGeometry, real: PKMGeometry, q_target, *, rounds: int = 5, noise: float = 0.0,
                        seed: int = 0) -> Compensation:
    """The paper's rod-space correction repeated: each round measures the platform, maps it
    through the nominal inverse kinematics and adds L* − L to the command (closed form, the
    exact minimiser of eq. 18)."""
    start = time.perf_counter()
    rng = np.random.default_rng(seed)
    q_target = np.asarray(q_target, float)
    P_star = reduced_to_pose(q_target)
    L_star = rod_lengths(nominal, P_star)
    L_cmd = L_star.copy()
    history = []
    for _ in range(rounds):
        reached, measured = _measure(real, L_cmd, P_star, noise, rng)
        history.append(float(np.linalg.norm(reached[:, :3] - P_star[:, :3], axis=1).mean()))
        L_cmd = L_cmd + (L_star - _nominal_lengths_at(nominal, measured, q_target))
    out = _outcome(f"paper iterated ({rounds} rounds)", real, L_cmd, P_star, start)
    out.history = np.array(history + [out.mean_error])
    return out


def model_ik(geom: PKMGeometry, q_target, *, tol: float = 1e-10, max_iter: int = 50) -> np.ndarray:
    """Commanded lengths (n, 4) that put a mechanism with geometry ``geom`` at the target
    position (x, y, z of the reduced pose) with the target α; β and γ follow from the TPR
    constraints (for the nominal geometry: exactly the target pose)."""
    P_star = reduced_to_pose(np.asarray(q_target, float))
    pose = P_star.copy()
    for _ in range(max_iter):
        F, J = equations(geom, pose, np.zeros(pose.shape[:-1] + (4,)))
        G = np.concatenate([pose[:, :3] - P_star[:, :3], (pose[:, 3] - P_star[:, 3])[:, None], F[:, 4:]], axis=1)
        if np.abs(G).max() < tol:
            break
        JG = np.zeros((len(pose), 6, 6))
        JG[:, :3, :3] = np.eye(3)
        JG[:, 3, 3] = 1.0
        JG[:, 4:] = J[:, 4:]
        pose = pose - np.linalg.solve(JG, G[..., None])[..., 0]
    return rod_lengths(geom, pose)


def compensate_model(model: PKMGeometry, real: PKMGeometry, q_target) -> Compensation:
    """Command the identified model's inverse kinematics of each target."""
    start = time.perf_counter()
    P_star = reduced_to_pose(np.asarray(q_target, float))
    return _outcome("identified model", real, model_ik(model, q_target), P_star, start)


def uncompensated(nominal: PKMGeometry, real: PKMGeometry, q_target) -> Compensation:
    P_star = reduced_to_pose(np.asarray(q_target, float))
    return _outcome("none (nominal IK)", real, rod_lengths(nominal, P_star), P_star, time.perf_counter())


def compare_methods(nominal: PKMGeometry, real: PKMGeometry, targets, model: PKMGeometry, *, noise: float = 0.0,
                    seed: int = 0, rounds: int = 3, pso: dict | None = None) -> list[Compensation]:
    """Compensate ``targets`` four ways: not at all, the paper's eq. 18, its iteration, and
    through the identified ``model``."""
    return [
        uncompensated(nominal, real, targets),
        compensate_paper(nominal, real, targets, noise=noise, seed=seed, pso=pso),
        compensate_iterated(nominal, real, targets, rounds=rounds, noise=noise, seed=seed),
        compensate_model(model, real, targets),
    ]


def improvement(before: Compensation, after: Compensation) -> float:
    """Mean position accuracy improvement, % (the paper's figure): 100 (1 − mean_after / mean_before)."""
    return 100.0 * (1.0 - after.mean_error / before.mean_error)


def planted(seed: int, points: float = 0.5, rods: float = 0.5) -> np.ndarray:
    """Errors uniform in ±points mm on the 24 joint-point coordinates and ±rods mm on the rods."""
    rng = np.random.default_rng(seed)
    return np.concatenate([rng.uniform(-points, points, 24), rng.uniform(-rods, rods, 4)])


@dataclass
class CompensationStudy:
    """The four compensations of one simulated machine, with the improvement of each (%)."""

    runs: list[Compensation]
    errors: float
    noise: float

    def table(self) -> list[dict]:
        base = self.runs[0]
        return [{"method": r.method, "mean_mm": r.mean_error, "max_mm": r.max_error,
                 "improvement_pct": improvement(base, r)} for r in self.runs]


def simulate_compensation(*, errors: float = 0.5, targets: int = 30, noise: float = 0.0, seed: int = 0,
                          rounds: int = 5) -> CompensationStudy:
    """Plant errors (uniform ± ``errors`` mm on all 28 parameters) in Chen's mechanism, identify
    it from 40 measured poses, and compensate ``targets`` fresh targets four ways."""
    opt.number(errors, "errors", minimum=0.0)
    opt.number(noise, "noise", minimum=0.0)
    if targets < 1:
        raise InputError(f"need at least 1 target, got {targets}", option="targets")
    g = chen2023()
    real = g.with_errors(planted(seed, errors, errors))
    model = identify_simulated(g, real, workspace_targets(g, 40, seed + 2, angle=0.2), noise=noise, seed=seed)
    runs = compare_methods(g, real, workspace_targets(g, targets, seed + 1), model.geometry, noise=noise, seed=seed,
                           rounds=rounds)
    return CompensationStudy(runs, errors, noise)
