"""Kinematics of the 2TPR&2TPS mechanism: inverse, its Jacobian, forward (Newton), workspace.

The revolute joints R1, R2 turn about the platform's x1 axis and each TPR limb is
perpendicular to its R axis, so ``c_i = (R e1) · u_i = 0`` for i = 3, 4.  With the nominal
points (B3, B4 on the y1 axis, T3 + T4 = 0) these two constraints are exactly γ = 0 and
x = z tan β (paper eq. 4–7), leaving q = (y, z, α, β).  With geometric errors the same two
constraints still hold physically but no longer reduce to those formulas, so forward
kinematics solves the six equations (four rods, two constraints) for the six pose
coordinates; for the nominal mechanism its answer has γ = 0 and x = z tan β to rounding.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..exceptions import InputError
from .geometry import PKMGeometry, leg_vectors, reduced_to_pose, rotate, rotation_derivatives

#: home pose used to start forward kinematics: platform level, 400 mm above the base
HOME = np.array([0.0, 0.0, 400.0, 0.0, 0.0, 0.0])
FK_TOL = 1e-10  # mm, on rod lengths and constraints
FK_MAX_ITER = 50


def rod_lengths(geom: PKMGeometry, pose) -> np.ndarray:
    """Commanded rod lengths (…, 4) mm that put the platform at ``pose``: |u_i| − ΔL_i."""
    return np.linalg.norm(leg_vectors(geom, pose), axis=-1) - geom.rod_zero


def ik(geom: PKMGeometry, q) -> np.ndarray:
    """Inverse kinematics of the reduced pose q = (y, z, α, β) → commanded lengths (…, 4) mm."""
    return rod_lengths(geom, reduced_to_pose(q))


def jacobian(geom: PKMGeometry, q) -> np.ndarray:
    """Analytic ∂L/∂(y, z, α, β), (…, 4, 4): the paper's J_D (eq. 11–12, derived afresh).

    With u_i = R B_i + o1 − T_i and o1 = (z tan β, y, z):  ∂L_i/∂q_k = u_i · ∂u_i/∂q_k / L_i,
    ∂u/∂y = e2, ∂u/∂z = (tan β, 0, 1), ∂u/∂α = R_α B_i, ∂u/∂β = R_β B_i + (z sec²β, 0, 0).
    """
    q = np.asarray(q, dtype=float)
    pose = reduced_to_pose(q)
    R, (Ra, Rb, _) = rotation_derivatives(pose)
    u = rotate(R, geom.B) + pose[..., None, :3] - geom.T
    L = np.linalg.norm(u, axis=-1)
    z, b = q[..., 1], q[..., 3]
    du = np.zeros(u.shape + (4,))
    du[..., 1, 0] = 1.0
    du[..., 0, 1] = np.tan(b)[..., None]
    du[..., 2, 1] = 1.0
    du[..., 2] = rotate(Ra, geom.B)
    du[..., :, 3] = rotate(Rb, geom.B)
    du[..., 0, 3] += (z / np.cos(b) ** 2)[..., None]
    return np.einsum("...ia,...iak->...ik", u, du) / L[..., None]


def equations(geom: PKMGeometry, pose, L_cmd):
    """F (…, 6): rod-length mismatches (4) and TPR constraints (2), and ∂F/∂pose (…, 6, 6)."""
    R, dR = rotation_derivatives(pose)
    u = rotate(R, geom.B) + pose[..., None, :3] - geom.T
    Ln = np.linalg.norm(u, axis=-1)
    n = u / Ln[..., None]
    x1 = R[..., :, 0]  # R e1, the R joints' axis
    F = np.concatenate([Ln - geom.rod_zero - L_cmd, np.sum(x1[..., None, :] * u[..., 2:, :], axis=-1)], -1)
    J = np.zeros(F.shape + (6,))
    J[..., :4, :3] = n
    J[..., 4:, :3] = x1[..., None, :]
    for k in range(3):
        dRk = dR[k]
        J[..., :4, 3 + k] = np.sum(n * rotate(dRk, geom.B), axis=-1)
        # c_i = e1·B_i + (R e1)·(o1 − T_i): the first term does not depend on the pose
        J[..., 4:, 3 + k] = np.sum(dRk[..., None, :, 0] * (pose[..., None, :3] - geom.T[2:]), axis=-1)
    return F, J


@dataclass
class FKResult:
    pose: np.ndarray  # (…, 6)
    converged: np.ndarray  # (…,) bool
    iterations: int
    residual: np.ndarray  # (…,) max |F| in mm


def _newton_step(J, F) -> np.ndarray:
    try:
        step = np.linalg.solve(J, -F[..., None])[..., 0]
    except np.linalg.LinAlgError:  # a singular configuration somewhere in the batch
        step = (np.linalg.pinv(J) @ -F[..., None])[..., 0]
    # a Newton step that jumps more than 100 mm or 0.5 rad is damped: the assembly is far
    scale = np.minimum(1.0, np.minimum(100.0 / np.maximum(np.abs(step[..., :3]).max(-1), 1e-300),
                                       0.5 / np.maximum(np.abs(step[..., 3:]).max(-1), 1e-300)))
    return step * scale[..., None]


def forward(geom: PKMGeometry, L_cmd, guess=None, *, tol: float = FK_TOL, max_iter: int = FK_MAX_ITER) -> FKResult:
    """Forward kinematics by Newton iteration on the six equations, batched over (…, 4) lengths.

    guess: starting poses (…, 6) (default :data:`HOME`).  Rows that do not converge
    (lengths with no assembly, or a singular configuration) are flagged, not raised.
    """
    L_cmd = np.asarray(L_cmd, dtype=float)
    pose = np.broadcast_to(HOME if guess is None else np.asarray(guess, float), L_cmd.shape[:-1] + (6,)).copy()
    it = 0
    for it in range(1, max_iter + 1):  # noqa: B007 (it is reported)
        F, J = equations(geom, pose, L_cmd)
        res = np.abs(F).max(axis=-1)
        if np.all(res < tol):
            break
        pose = pose + _newton_step(J, F)
        pose = np.where(np.isfinite(pose), pose, HOME)
    else:
        F, _ = equations(geom, pose, L_cmd)
        res = np.abs(F).max(axis=-1)
    return FKResult(pose, res < tol * 10, it, res)


def fk(geom: PKMGeometry, L_cmd, guess=None) -> np.ndarray:
    """Forward kinematics (…, 6); raises InputError naming the rows without an assembly."""
    r = forward(geom, L_cmd, guess)
    if not np.all(r.converged):
        bad = np.flatnonzero(~np.asarray(r.converged).reshape(-1))
        raise InputError(f"rod lengths of row(s) {', '.join(str(i + 1) for i in bad[:5])} have no assembly "
                         f"(Newton did not converge in {FK_MAX_ITER} iterations to {FK_TOL} mm)",
                         source="pkm fk")
    return r.pose


def workspace_violations(geom: PKMGeometry, pose) -> list[list[str]]:
    """Per pose, what it violates: rod length limits and Hooke-joint swing (empty list: fine)."""
    pose = np.atleast_2d(np.asarray(pose, dtype=float))
    u = leg_vectors(geom, pose)
    L = np.linalg.norm(u, axis=-1)
    swing = np.arccos(np.clip(u[..., 2] / L, -1.0, 1.0))
    lo, hi = geom.rod_limits
    out = []
    for j in range(len(pose)):
        v = []
        for i in range(4):
            if not lo - 1e-9 <= L[j, i] <= hi + 1e-9:
                v.append(f"rod {i + 1} length {L[j, i]:.2f} mm outside {lo:g}–{hi:g}")
            if swing[j, i] > geom.hooke_limit + 1e-12:
                v.append(f"Hooke joint {i + 1} swing {math.degrees(swing[j, i]):.1f}° > "
                         f"{math.degrees(geom.hooke_limit):g}°")
        out.append(v)
    return out


def check_workspace(geom: PKMGeometry, pose, source: str = "pose") -> None:
    for j, v in enumerate(workspace_violations(geom, pose)):
        if v:
            raise InputError(f"pose {j + 1} is outside the workspace: {v[0]}", source=source)


def workspace_targets(geom: PKMGeometry, n: int, seed: int, *, y=(-60.0, 60.0), z=(330.0, 430.0),
                      angle: float = 0.0) -> np.ndarray:
    """n reduced poses (y, z, α, β) uniform in the given box (mm, rad), inside the workspace."""
    rng = np.random.default_rng(seed)
    out: list[np.ndarray] = []
    while len(out) < n:
        q = np.column_stack([rng.uniform(*y, 4 * n), rng.uniform(*z, 4 * n), rng.uniform(-angle, angle, 4 * n),
                             rng.uniform(-angle, angle, 4 * n)])
        viol = workspace_violations(geom, reduced_to_pose(q))
        out += [q[i] for i in range(len(q)) if not viol[i]]
    return np.array(out[:n])
