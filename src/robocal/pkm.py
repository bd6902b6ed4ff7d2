"""The 4-DOF 2TPR&2TPS parallel mechanism of Chen et al. (paper 003): geometry, kinematics, errors.

Frames and conventions (SPEC §5).  The fixed frame o sits at the midpoint of T3T4, the
moving frame o1 at the midpoint of R1R2; lengths in mm, angles in rad.  A platform
pose is (x, y, z, α, β, γ) with ``R = Rz(γ) Ry(β) Rx(α)`` and o1 = (x, y, z).  Limbs
1, 2 are T–P–S from T1, T2 to B1 = S1, B2 = S2; limbs 3, 4 are T–P–R from T3, T4 to
B3 = R2, B4 = R1.  Rod i has length ``|u_i|`` with ``u_i = R B_i + o1 − T_i``.

The revolute joints R1, R2 turn about the platform's x1 axis and each TPR limb is
perpendicular to its R axis, so ``c_i = (R e1) · u_i = 0`` for i = 3, 4.  With the
nominal points (B3, B4 on the y1 axis, T3 + T4 = 0) these two constraints are exactly
γ = 0 and x = z tan β (paper eq. 4–7), leaving q = (y, z, α, β).  With geometric errors
the same two constraints still hold physically but no longer reduce to those
formulas, so forward kinematics solves the six equations (four rods, two constraints)
for the six pose coordinates; for the nominal mechanism its answer has γ = 0 and
x = z tan β to rounding.

Commanded rod lengths are what the controller believes: the real length is the
commanded one plus the rod's zero-length error ΔL_i.

The paper's Table 1 gives d = 292.4 mm where its Table 2 has T1, T2 at x = 294.2 mm;
the other entries of both tables agree, so 294.2 (Table 2, the points actually used) is
taken and 292.4 read as a transposition of digits.
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from .errors import InputError, atomic_write
from .transforms import rot_x, rot_y, rot_z

AXES = ("x", "y", "z")
#: the 28 error parameters: fixed points, moving points, rod zero lengths (all mm)
PARAM_NAMES = tuple(
    [f"T{i}{a}" for i in range(1, 5) for a in AXES]
    + [f"B{i}{a}" for i in range(1, 5) for a in AXES]
    + [f"dL{i}" for i in range(1, 5)]
)
#: home pose used to start forward kinematics: platform level, 400 mm above the base
HOME = np.array([0.0, 0.0, 400.0, 0.0, 0.0, 0.0])
FK_TOL = 1e-10  # mm, on rod lengths and constraints
FK_MAX_ITER = 50


@dataclass(frozen=True)
class PKMGeometry:
    """Joint points (4, 3) of the fixed (T) and moving (B) platforms in mm, rod zero-length
    errors (4,) mm, rod length limits (mm) and the Hooke-joint swing limit (rad), measured
    between a rod and the fixed platform's normal (the paper gives ±60° without its axis)."""

    T: np.ndarray
    B: np.ndarray
    rod_zero: np.ndarray = field(default_factory=lambda: np.zeros(4))
    rod_limits: tuple[float, float] = (300.0, 520.0)
    hooke_limit: float = math.radians(60.0)
    name: str = "2TPR&2TPS"

    def __post_init__(self) -> None:
        for key, shape in (("T", (4, 3)), ("B", (4, 3)), ("rod_zero", (4,))):
            v = np.array(getattr(self, key), dtype=float)
            if v.shape != shape:
                raise ValueError(f"{key} must have shape {shape}")
            object.__setattr__(self, key, v)

    def vector(self) -> np.ndarray:
        """The 28 parameters in :data:`PARAM_NAMES` order."""
        return np.concatenate([self.T.ravel(), self.B.ravel(), self.rod_zero])

    def with_errors(self, delta) -> PKMGeometry:
        """This geometry with errors (28,) added (mm)."""
        delta = np.asarray(delta, dtype=float)
        if delta.shape != (28,):
            raise ValueError("a PKM error vector has 28 entries")
        return replace(
            self,
            T=self.T + delta[:12].reshape(4, 3),
            B=self.B + delta[12:24].reshape(4, 3),
            rod_zero=self.rod_zero + delta[24:],
        )


def chen2023() -> PKMGeometry:
    """Chen et al. Table 2 (mm): T1 (294.2, −192.35, 0), T2 (294.2, 192.35, 0), T3 (0, 139.25, 0),
    T4 (0, −139.25, 0); B1 (140, −40, 0), B2 (140, 40, 0), B3 (0, 100, 0), B4 (0, −100, 0)."""
    T = [[294.2, -192.35, 0.0], [294.2, 192.35, 0.0], [0.0, 139.25, 0.0], [0.0, -139.25, 0.0]]
    B = [[140.0, -40.0, 0.0], [140.0, 40.0, 0.0], [0.0, 100.0, 0.0], [0.0, -100.0, 0.0]]
    return PKMGeometry(np.array(T), np.array(B))


# --- poses ------------------------------------------------------------------------------


def _rotate(R: np.ndarray, P: np.ndarray) -> np.ndarray:
    """R (…, 3, 3) applied to the four points P (4, 3) → (…, 4, 3)."""
    return np.swapaxes(R @ P.T, -1, -2)


def reduced_to_pose(q) -> np.ndarray:
    """(…, 4) (y, z, α, β) → (…, 6) pose with x = z tan β, γ = 0 (the nominal constraints)."""
    q = np.asarray(q, dtype=float)
    y, z, a, b = (q[..., k] for k in range(4))
    return np.stack([z * np.tan(b), y, z, a, b, np.zeros_like(y)], -1)


def rotation(pose) -> np.ndarray:
    pose = np.asarray(pose, dtype=float)
    return rot_z(pose[..., 5]) @ rot_y(pose[..., 4]) @ rot_x(pose[..., 3])


def _rotation_derivatives(pose):
    """R and ∂R/∂α, ∂R/∂β, ∂R/∂γ, each (…, 3, 3)."""
    a, b, g = pose[..., 3], pose[..., 4], pose[..., 5]
    Rx, Ry, Rz = rot_x(a), rot_y(b), rot_z(g)
    ca, sa, cb, sb, cg, sg = np.cos(a), np.sin(a), np.cos(b), np.sin(b), np.cos(g), np.sin(g)
    z = np.zeros_like(a)
    dRx = np.stack([np.stack([z, z, z], -1), np.stack([z, -sa, -ca], -1), np.stack([z, ca, -sa], -1)], -2)
    dRy = np.stack([np.stack([-sb, z, cb], -1), np.stack([z, z, z], -1), np.stack([-cb, z, -sb], -1)], -2)
    dRz = np.stack([np.stack([-sg, -cg, z], -1), np.stack([cg, -sg, z], -1), np.stack([z, z, z], -1)], -2)
    return Rz @ Ry @ Rx, (Rz @ Ry @ dRx, Rz @ dRy @ Rx, dRz @ Ry @ Rx)


def leg_vectors(geom: PKMGeometry, pose) -> np.ndarray:
    """u_i = R B_i + o1 − T_i, (…, 4, 3) in mm."""
    pose = np.asarray(pose, dtype=float)
    R = rotation(pose)
    return _rotate(R, geom.B) + pose[..., None, :3] - geom.T


def rod_lengths(geom: PKMGeometry, pose) -> np.ndarray:
    """Commanded rod lengths (…, 4) that put the platform at ``pose``: |u_i| − ΔL_i."""
    return np.linalg.norm(leg_vectors(geom, pose), axis=-1) - geom.rod_zero


def ik(geom: PKMGeometry, q) -> np.ndarray:
    """Inverse kinematics of the reduced pose q = (y, z, α, β) → commanded lengths (…, 4)."""
    return rod_lengths(geom, reduced_to_pose(q))


def jacobian(geom: PKMGeometry, q) -> np.ndarray:
    """Analytic ∂L/∂(y, z, α, β), (…, 4, 4): the paper's J_D (eq. 11–12, derived afresh).

    With u_i = R B_i + o1 − T_i and o1 = (z tan β, y, z):  ∂L_i/∂q_k = u_i · ∂u_i/∂q_k / L_i,
    ∂u/∂y = e2, ∂u/∂z = (tan β, 0, 1), ∂u/∂α = R_α B_i, ∂u/∂β = R_β B_i + (z sec²β, 0, 0).
    """
    q = np.asarray(q, dtype=float)
    pose = reduced_to_pose(q)
    R, (Ra, Rb, _) = _rotation_derivatives(pose)
    u = _rotate(R, geom.B) + pose[..., None, :3] - geom.T
    L = np.linalg.norm(u, axis=-1)
    z, b = q[..., 1], q[..., 3]
    du = np.zeros(u.shape + (4,))
    du[..., 1, 0] = 1.0
    du[..., 0, 1] = np.tan(b)[..., None]
    du[..., 2, 1] = 1.0
    du[..., 2] = _rotate(Ra, geom.B)
    du[..., :, 3] = _rotate(Rb, geom.B)
    du[..., 0, 3] += (z / np.cos(b) ** 2)[..., None]
    return np.einsum("...ia,...iak->...ik", u, du) / L[..., None]


# --- forward kinematics -------------------------------------------------------------------


def _equations(geom: PKMGeometry, pose, L_cmd):
    """F (…, 6): rod-length mismatches (4) and TPR constraints (2), and ∂F/∂pose (…, 6, 6)."""
    R, dR = _rotation_derivatives(pose)
    u = _rotate(R, geom.B) + pose[..., None, :3] - geom.T
    Ln = np.linalg.norm(u, axis=-1)
    n = u / Ln[..., None]
    x1 = R[..., :, 0]  # R e1, the R joints' axis
    F = np.concatenate([Ln - geom.rod_zero - L_cmd, np.sum(x1[..., None, :] * u[..., 2:, :], axis=-1)], -1)
    J = np.zeros(F.shape + (6,))
    J[..., :4, :3] = n
    J[..., 4:, :3] = x1[..., None, :]
    for k in range(3):
        dRk = dR[k]
        du = _rotate(dRk, geom.B)
        J[..., :4, 3 + k] = np.sum(n * du, axis=-1)
        # c_i = e1·B_i + (R e1)·(o1 − T_i): the first term does not depend on the pose
        J[..., 4:, 3 + k] = np.sum(dRk[..., None, :, 0] * (pose[..., None, :3] - geom.T[2:]), axis=-1)
    return F, J


@dataclass
class FKResult:
    pose: np.ndarray  # (…, 6)
    converged: np.ndarray  # (…,) bool
    iterations: int
    residual: np.ndarray  # (…,) max |F| in mm


def forward(geom: PKMGeometry, L_cmd, guess=None, *, tol: float = FK_TOL, max_iter: int = FK_MAX_ITER) -> FKResult:
    """Forward kinematics by Newton iteration on the six equations, batched over (…, 4) lengths.

    guess: starting poses (…, 6) (default :data:`HOME`).  Rows that do not converge
    (lengths with no assembly, or a singular configuration) are flagged, not raised.
    """
    L_cmd = np.asarray(L_cmd, dtype=float)
    pose = np.broadcast_to(HOME if guess is None else np.asarray(guess, float), L_cmd.shape[:-1] + (6,)).copy()
    it = 0
    converged_in_loop = False
    for it in range(1, max_iter + 1):  # noqa: B007 (it is reported)
        F, J = _equations(geom, pose, L_cmd)
        res = np.abs(F).max(axis=-1)
        if np.all(res < tol):
            converged_in_loop = True
            break
        try:
            step = np.linalg.solve(J, -F[..., None])[..., 0]
        except np.linalg.LinAlgError:  # a singular configuration somewhere in the batch
            step = (np.linalg.pinv(J) @ -F[..., None])[..., 0]
        # a Newton step that jumps more than 100 mm or 0.5 rad is damped: the assembly is far
        scale = np.minimum(
            1.0,
            np.minimum(
                100.0 / np.maximum(np.abs(step[..., :3]).max(-1), 1e-300),
                0.5 / np.maximum(np.abs(step[..., 3:]).max(-1), 1e-300),
            ),
        )
        pose = pose + step * scale[..., None]
        pose = np.where(np.isfinite(pose), pose, HOME)
    if not converged_in_loop:
        F, _ = _equations(geom, pose, L_cmd)
        res = np.abs(F).max(axis=-1)
    return FKResult(pose, res < tol * 10, it, res)


def fk(geom: PKMGeometry, L_cmd, guess=None) -> np.ndarray:
    """Forward kinematics (…, 6); raises InputError naming the rows without an assembly."""
    r = forward(geom, L_cmd, guess)
    if not np.all(r.converged):
        bad = np.flatnonzero(~np.asarray(r.converged).reshape(-1))
        raise InputError(
            f"rod lengths of row(s) {', '.join(str(i + 1) for i in bad[:5])} have no assembly "
            f"(Newton did not converge in {FK_MAX_ITER} iterations to {FK_TOL} mm)",
            source="pkm fk",
        )
    return r.pose


# --- workspace --------------------------------------------------------------------------------


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
                v.append(
                    f"Hooke joint {i + 1} swing {math.degrees(swing[j, i]):.1f}° > {math.degrees(geom.hooke_limit):g}°"
                )
        out.append(v)
    return out


def check_workspace(geom: PKMGeometry, pose, source: str = "pose") -> None:
    for j, v in enumerate(workspace_violations(geom, pose)):
        if v:
            raise InputError(f"pose {j + 1} is outside the workspace: {v[0]}", source=source)


# --- files ------------------------------------------------------------------------------------

_KEYS = {"name", "fixed", "moving", "rod_zero", "rod_limits", "hooke_limit", "source"}


def load_pkm(spec: str | Path | PKMGeometry | None = None) -> PKMGeometry:
    """Geometry from a TOML file, or the built-in ``2tpr2tps`` (Chen et al. Table 2)."""
    if isinstance(spec, PKMGeometry):
        return spec
    if spec is None or str(spec).lower() in ("2tpr2tps", "chen2023"):
        return chen2023()
    path = Path(spec)
    if not path.is_file():
        raise InputError("no such mechanism file (built-in: 2tpr2tps)", source=path)
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise InputError(f"not valid TOML: {exc}", source=path) from None
    unknown = set(data) - _KEYS
    if unknown:
        raise InputError(f"unknown key '{sorted(unknown)[0]}' (allowed: {', '.join(sorted(_KEYS))})", source=path)

    def points(table, prefix):
        if not isinstance(data.get(table), dict):
            raise InputError(f"missing table [{table}]", source=path)
        t = data[table]
        extra = set(t) - {f"{prefix}{i}" for i in range(1, 5)}
        if extra:
            raise InputError(f"unknown key '{sorted(extra)[0]}'", source=path, where=f"[{table}]")
        out = []
        for i in range(1, 5):
            v = t.get(f"{prefix}{i}")
            if not (
                isinstance(v, list)
                and len(v) == 3
                and all(isinstance(c, (int, float)) and not isinstance(c, bool) and math.isfinite(c) for c in v)
            ):
                raise InputError(
                    f"expected 3 finite numbers (mm), got {v!r}", source=path, where=f"[{table}] {prefix}{i}"
                )
            out.append([float(c) for c in v])
        return np.array(out)

    T, B = points("fixed", "T"), points("moving", "B")
    rz = data.get("rod_zero", [0.0] * 4)
    if not (isinstance(rz, list) and len(rz) == 4 and all(isinstance(c, (int, float)) for c in rz)):
        raise InputError(f"expected 4 numbers (mm), got {rz!r}", source=path, where="rod_zero")
    lim = data.get("rod_limits", [300.0, 520.0])
    if not (
        isinstance(lim, list) and len(lim) == 2 and all(isinstance(c, (int, float)) for c in lim) and lim[0] < lim[1]
    ):
        raise InputError(f"expected [low, high] mm, got {lim!r}", source=path, where="rod_limits")
    hk = data.get("hooke_limit", 60.0)
    if not isinstance(hk, (int, float)) or not 0 < hk <= 90:
        raise InputError(f"expected degrees in (0, 90], got {hk!r}", source=path, where="hooke_limit")
    return PKMGeometry(
        T, B, np.array(rz, float), (float(lim[0]), float(lim[1])), math.radians(hk), str(data.get("name", path.stem))
    )


def pkm_to_toml(geom: PKMGeometry, comment: str | None = None) -> str:
    lines = [f"# {c}" for c in (comment or "").splitlines()]
    # top-level keys first: in TOML everything after a [table] header belongs to that table
    lines += [
        f'name = "{geom.name}"',
        f"rod_zero = [{', '.join(repr(float(v)) for v in geom.rod_zero)}]  # mm",
        f"rod_limits = [{geom.rod_limits[0]!r}, {geom.rod_limits[1]!r}]  # mm",
        f"hooke_limit = {math.degrees(geom.hooke_limit)!r}  # deg",
        "",
        "[fixed]  # mm, fixed-platform frame",
    ]
    lines += [f"T{i + 1} = [{', '.join(repr(float(v)) for v in geom.T[i])}]" for i in range(4)]
    lines += ["", "[moving]  # mm, moving-platform frame"]
    lines += [f"B{i + 1} = [{', '.join(repr(float(v)) for v in geom.B[i])}]" for i in range(4)]
    lines.append("")
    return "\n".join(lines)


def save_pkm(geom: PKMGeometry, path: str | Path, comment: str | None = None) -> None:
    atomic_write(path, pkm_to_toml(geom, comment))
