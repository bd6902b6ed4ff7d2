"""Error model, sensitivity, identification and compensation of the 2TPR&2TPS mechanism.

- :func:`pose_error`: E = P° − P, the pose of the mechanism with errors minus the nominal
  pose for the same commanded rod lengths (Chen et al. eq. 14–17).
- :func:`sensitivity`: the paper's Fig. 4–9 study, 1 mm of error per parameter.
- :func:`identify`: beyond the paper, the identifiable subset of the 28 parameters from
  measured platform positions, by Levenberg–Marquardt with the same identifiability
  analysis as the serial arms.
- :func:`compensate_paper`, :func:`compensate_iterated`, :func:`compensate_model`: the
  paper's rod-space correction (eq. 18, PSO), its iteration to a fixed point, and exact
  compensation through the identified model's inverse kinematics.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from .identifiability import Identifiability, analyse
from .optimizers import levenberg_marquardt, pso_batch
from .pkm import (
    PARAM_NAMES,
    PKMGeometry,
    _equations,
    _rotation_derivatives,
    forward,
    reduced_to_pose,
    rod_lengths,
    workspace_violations,
)

#: the paper's compensation PSO (§4.2): N 100, c1 = c2 = 1.5, w 0.8, 200 iterations
PAPER_PSO = {"particles": 100, "iterations": 200, "w": 0.8, "c1": 1.5, "c2": 1.5}
#: search box of ΔL (mm) for that PSO: the paper gives none; rod corrections of a few tenths
#: of a millimetre come from errors of that size, so ±5 mm leaves a wide margin
PAPER_PSO_BOX = 5.0


def workspace_targets(
    geom: PKMGeometry, n: int, seed: int, *, y=(-60.0, 60.0), z=(330.0, 430.0), angle: float = 0.0
) -> np.ndarray:
    """n reduced poses (y, z, α, β) uniform in the given box (mm, rad), inside the workspace."""
    rng = np.random.default_rng(seed)
    out = []
    while len(out) < n:
        q = np.column_stack(
            [
                rng.uniform(*y, 4 * n),
                rng.uniform(*z, 4 * n),
                rng.uniform(-angle, angle, 4 * n),
                rng.uniform(-angle, angle, 4 * n),
            ]
        )
        viol = workspace_violations(geom, reduced_to_pose(q))
        out += [q[i] for i in range(len(q)) if not viol[i]]
    return np.array(out[:n])


def pose_error(nominal: PKMGeometry, real: PKMGeometry, q) -> np.ndarray:
    """E = P° − P (…, 6): the real mechanism's pose minus the nominal pose q, both at the
    rod lengths the nominal inverse kinematics commands for q."""
    P = reduced_to_pose(q)
    L = rod_lengths(nominal, P)
    return forward(real, L, P).pose - P


@dataclass
class Sensitivity:
    """Mean |E| per case and component (dx, dy, dz mm; dα, dβ, dγ rad), and per-pose E."""

    cases: dict[str, dict[str, np.ndarray]]  # group → label → E (poses, 6)

    def mean_table(self) -> dict[str, dict[str, list[float]]]:
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
    all_limbs = {label: E(names) for label, names in types.items()}
    return Sensitivity({"limb 1": limb1, "rod zero lengths": rods, "all four limbs": all_limbs})


# --- identification ---------------------------------------------------------------------------


def _param_jacobian(geom: PKMGeometry, pose: np.ndarray) -> np.ndarray:
    """∂F/∂θ (m, 6, 28) of the kinematic equations with respect to the 28 parameters."""
    R, _ = _rotation_derivatives(pose)
    u = np.einsum("...ab,ib->...ia", R, geom.B) + pose[..., None, :3] - geom.T
    n = u / np.linalg.norm(u, axis=-1, keepdims=True)
    m = len(pose)
    Ft = np.zeros((m, 6, 28))
    x1 = R[..., :, 0]
    for i in range(4):
        Ft[:, i, 3 * i : 3 * i + 3] = -n[:, i]
        Ft[:, i, 12 + 3 * i : 12 + 3 * i + 3] = np.einsum("mab,ma->mb", R, n[:, i])  # Rᵀ n
        Ft[:, i, 24 + i] = -1.0
    for r, i in ((4, 2), (5, 3)):
        Ft[:, r, 3 * i : 3 * i + 3] = -x1
        Ft[:, r, 12 + 3 * i] = 1.0  # ∂c/∂B_i = e1
    return Ft


def position_jacobian(geom: PKMGeometry, L_cmd: np.ndarray, guess=None):
    """Platform position (m, 3) and its derivative (m, 3, 28) with respect to the parameters,
    by implicit differentiation of the kinematic equations F(pose, θ) = 0."""
    r = forward(geom, L_cmd, guess)
    _, Fp = _equations(geom, r.pose, L_cmd)
    dpose = -np.linalg.solve(Fp, _param_jacobian(geom, r.pose))
    return r.pose, dpose[:, :3, :], r.converged


@dataclass
class PKMCalibration:
    geometry: PKMGeometry
    names: list[str]
    errors: np.ndarray
    uncertainty: np.ndarray | None
    identifiability: Identifiability
    rms_before: float
    rms_after: float
    status: str
    time_s: float
    extra: dict = field(default_factory=dict)

    def to_dict(self) -> dict:
        ident = self.identifiability
        return {
            "parameters": [
                {
                    "name": n,
                    "unit": "mm",
                    "error": float(e),
                    "uncertainty": None if self.uncertainty is None else float(u),
                }
                for n, e, u in zip(
                    self.names, self.errors, self.uncertainty if self.uncertainty is not None else self.errors
                )
            ],
            "dropped": [{"name": n, "reason": ident.reasons[n]} for n in ident.dropped],
            "identifiability": ident.to_dict(),
            "rms_before_mm": self.rms_before,
            "rms_after_mm": self.rms_after,
            "status": self.status,
            "time_s": self.time_s,
        }


def identify(nominal: PKMGeometry, L_cmd, positions, *, guess=None) -> PKMCalibration:
    """Identify the identifiable subset of the 28 parameters from commanded lengths (m, 4) and
    measured platform positions (m, 3) in the fixed frame (mm)."""
    start = time.perf_counter()
    L_cmd, positions = np.asarray(L_cmd, float), np.asarray(positions, float)
    names = list(PARAM_NAMES)
    P0, J0, ok = position_jacobian(nominal, L_cmd, guess)
    if not np.all(ok):
        raise ValueError("nominal forward kinematics failed for some commanded lengths")
    ident = analyse(-J0.reshape(-1, 28), names, np.zeros(28, bool), len(L_cmd), 1.0)
    active = np.array([names.index(n) for n in ident.kept])
    guesses = {"pose": P0.copy() if guess is None else np.asarray(guess, float)}

    def full(x):
        d = np.zeros(28)
        d[active] = x
        return d

    def residuals(x):
        r = forward(nominal.with_errors(full(x)), L_cmd, guesses["pose"])
        guesses["pose"] = r.pose
        return (positions - r.pose[:, :3]).ravel()

    def jac(x):
        _, J, _ = position_jacobian(nominal.with_errors(full(x)), L_cmd, guesses["pose"])
        return -J[:, :, active].reshape(-1, len(active))

    before = residuals(np.zeros(len(active)))
    opt = levenberg_marquardt(residuals, jac, np.zeros(len(active)))
    r = residuals(opt.x)
    dof = r.size - len(active)
    unc = None
    if dof > 0:
        J = jac(opt.x)
        s2 = float(r @ r) / dof
        unc = np.sqrt(np.diag(np.linalg.pinv(J.T @ J)) * s2)
    return PKMCalibration(
        geometry=nominal.with_errors(full(opt.x)), names=ident.kept, errors=opt.x, uncertainty=unc,
        identifiability=ident, rms_before=float(np.sqrt(np.mean(before.reshape(-1, 3) ** 2 * 3))),
        rms_after=float(np.sqrt(np.mean(np.sum(r.reshape(-1, 3) ** 2, axis=1)))), status=opt.status,
        time_s=time.perf_counter() - start, extra={"evaluations": opt.nfev, "iterations": opt.nit},
    )  # fmt: skip


# --- compensation -----------------------------------------------------------------------------


@dataclass
class Compensation:
    """Commanded lengths and the positions reached, per target."""

    method: str
    L_command: np.ndarray  # (n, 4)
    reached: np.ndarray  # (n, 6) real poses
    error: np.ndarray  # (n, 3) reached position − target position, mm
    history: np.ndarray | None = None
    time_s: float = 0.0

    @property
    def mean_error(self) -> float:
        return float(np.linalg.norm(self.error, axis=1).mean())


def _measure(real: PKMGeometry, L, guess, noise: float, rng) -> tuple[np.ndarray, np.ndarray]:
    """What the machine does for commanded L, and what the tracker reads (position + noise)."""
    pose = forward(real, L, guess).pose
    return pose, pose[:, :3] + (rng.normal(0.0, noise, pose[:, :3].shape) if noise > 0 else 0.0)


def _nominal_lengths_at(nominal: PKMGeometry, measured: np.ndarray, q_target: np.ndarray) -> np.ndarray:
    """L = IK(P) of the paper: nominal rod lengths for the measured position, with the target's
    α and the β that the measured x implies (x = z tan β); the tracker gives no orientation."""
    x, y, z = measured[:, 0], measured[:, 1], measured[:, 2]
    q = np.column_stack([y, z, q_target[:, 2], np.arctan2(x, z)])
    return rod_lengths(nominal, reduced_to_pose(q))


def compensate_paper(
    nominal: PKMGeometry, real: PKMGeometry, q_target, *, noise: float = 0.0, seed: int = 0, pso: dict | None = None
) -> Compensation:
    """Chen et al. eq. 18: drive to L* = IK(P*), measure P, L = IK(P), find ΔL minimising
    sqrt(Σ (L*_i − L_i − ΔL_i)²) by PSO (one swarm per target, all advanced in one batch),
    command L* + ΔL.  The minimum is ΔL = L* − L exactly; the PSO finds it to its accuracy."""
    start = time.perf_counter()
    rng = np.random.default_rng(seed)
    q_target = np.asarray(q_target, float)
    P_star = reduced_to_pose(q_target)
    L_star = rod_lengths(nominal, P_star)
    _, measured = _measure(real, L_star, P_star, noise, rng)
    L = _nominal_lengths_at(nominal, measured, q_target)
    target = (L_star - L)[:, None, :]
    settings = {**PAPER_PSO, **(pso or {})}
    box = np.full(4, PAPER_PSO_BOX)

    def f(X):
        return np.sqrt(np.sum((target - X) ** 2, axis=-1))

    dL, _, history = pso_batch(f, -box, box, len(q_target), seed=seed, **settings)
    L_cmd = L_star + dL
    reached, _ = _measure(real, L_cmd, P_star, 0.0, rng)
    return Compensation(
        "paper (eq. 18, PSO)", L_cmd, reached, reached[:, :3] - P_star[:, :3], history, time.perf_counter() - start
    )


def compensate_iterated(
    nominal: PKMGeometry, real: PKMGeometry, q_target, *, rounds: int = 5, noise: float = 0.0, seed: int = 0
) -> Compensation:
    """The paper's rod-space correction repeated: each round measures the platform, maps it
    through the nominal inverse kinematics and adds L* − L to the command (closed form,
    the exact minimiser of eq. 18), a fixed-point iteration on the real machine."""
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
    reached, _ = _measure(real, L_cmd, P_star, 0.0, rng)
    history.append(float(np.linalg.norm(reached[:, :3] - P_star[:, :3], axis=1).mean()))
    return Compensation(
        f"paper iterated ({rounds} rounds)",
        L_cmd,
        reached,
        reached[:, :3] - P_star[:, :3],
        np.array(history),
        time.perf_counter() - start,
    )


def model_ik(geom: PKMGeometry, q_target, *, tol: float = 1e-10, max_iter: int = 50) -> np.ndarray:
    """Commanded lengths (n, 4) that put a mechanism with geometry ``geom`` at the target
    position (x, y, z of the reduced pose) with the target α; β and γ follow from the
    TPR constraints (for the nominal geometry: exactly the target pose)."""
    q_target = np.asarray(q_target, float)
    P_star = reduced_to_pose(q_target)
    pose = P_star.copy()
    for _ in range(max_iter):
        F, J = _equations(geom, pose, np.zeros(pose.shape[:-1] + (4,)))
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
    q_target = np.asarray(q_target, float)
    P_star = reduced_to_pose(q_target)
    L_cmd = model_ik(model, q_target)
    reached = forward(real, L_cmd, P_star).pose
    return Compensation(
        "identified model", L_cmd, reached, reached[:, :3] - P_star[:, :3], None, time.perf_counter() - start
    )


def uncompensated(nominal: PKMGeometry, real: PKMGeometry, q_target) -> Compensation:
    P_star = reduced_to_pose(np.asarray(q_target, float))
    L = rod_lengths(nominal, P_star)
    reached = forward(real, L, P_star).pose
    return Compensation("none (nominal IK)", L, reached, reached[:, :3] - P_star[:, :3])


def identify_simulated(
    nominal: PKMGeometry, real: PKMGeometry, calibration_poses, *, noise: float = 0.0, seed: int = 0
) -> PKMCalibration:
    """Identify a simulated machine from its positions at ``calibration_poses`` (tracker noise σ mm)."""
    L = rod_lengths(nominal, reduced_to_pose(calibration_poses))
    P = forward(real, L, reduced_to_pose(calibration_poses)).pose[:, :3]
    if noise > 0:
        P = P + np.random.default_rng(seed + 5).normal(0.0, noise, P.shape)
    return identify(nominal, L, P)


def compare_methods(
    nominal: PKMGeometry,
    real: PKMGeometry,
    targets,
    model: PKMGeometry,
    *,
    noise: float = 0.0,
    seed: int = 0,
    rounds: int = 3,
    pso: dict | None = None,
) -> list[Compensation]:
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
