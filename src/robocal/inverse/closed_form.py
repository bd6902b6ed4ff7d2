"""Closed-form inverses of the two common 6R architectures, on a chain's DH equivalent.

- ``spherical``: axis 1 ⟂ axis 2, axes 2 ∥ 3, axes 4, 5, 6 meeting in one point (KUKA, ABB,
  FANUC, Yaskawa and most industrial arms; Pieper's case, the "ortho-parallel" arms).  The wrist
  centre fixes joints 1–3: two solutions for joint 1 (in front of or behind axis 1), two for the
  planar pair 2–3 (elbow up or down); the wrist's orientation then gives two for 4–6 (flip).
- ``offset``: axis 1 ⟂ axis 2, axes 2 ∥ 3 ∥ 4, the wrist offset along axis 4 (the UR family).
  The offset along the parallel axes fixes joint 1 (two solutions), axis 6's direction joint 5
  (two), then joint 6, and joints 2–4 are a planar arm (two).

Both give up to eight solutions of DH angles φ (m, 8, 6) for end poses of the equivalent.  The
derivations hold for any α3, α4, α5 (with sin α4, sin α5 ≠ 0) and any offsets a1, d1–d4, a4
(offset) or a1, a3, d2–d4 (spherical).  A chain that is only near one of the forms (a calibrated
model) is solved on its nearest ideal form (:func:`idealized`) and polished on itself.
"""

from __future__ import annotations

import numpy as np

from ..math.se3 import invert
from ..math.so3 import rot_x, rot_z
from .equivalent import DHEquivalent

#: an exact form within these (rad, mm); a near form, solved on its ideal and polished, within
#: NEAR_*: a calibration moves α by hundredths of a degree and offsets by a millimetre or two
EXACT_RAD, EXACT_MM = 1e-9, 1e-6
NEAR_RAD, NEAR_MM = np.radians(3.0), 5.0
KINDS = ("spherical", "offset")


def _ideal_alpha(alpha: float, target: str) -> float:
    """α1 → ±90° (its side), α2/α3 → 0."""
    return float(np.sign(np.sin(alpha)) * np.pi / 2) if target == "ortho" else 0.0


def _snaps(eq: DHEquivalent, kind: str) -> dict[tuple[str, int], float]:
    """The ideal value of every parameter the form fixes."""
    out = {("alpha", 0): _ideal_alpha(eq.alpha[0], "ortho"), ("alpha", 1): 0.0}
    if kind == "spherical":
        out.update({("a", 3): 0.0, ("a", 4): 0.0, ("d", 4): 0.0})
    else:
        out.update({("alpha", 2): 0.0, ("a", 4): 0.0})
    return out


def _gap(eq: DHEquivalent, kind: str) -> tuple[float, float]:
    """Largest angle (rad) and length (mm) the form's ideal moves."""
    ang = length = 0.0
    for (name, i), value in _snaps(eq, kind).items():
        delta = abs(getattr(eq, name)[i] - value)
        if name == "alpha":
            ang = max(ang, min(delta, 2 * np.pi - delta))
        else:
            length = max(length, delta)
    return ang, length


def _usable(eq: DHEquivalent, kind: str) -> bool:
    """Whether the form's free quantities leave the closed form defined."""
    s4, s5 = np.sin(eq.alpha[3]), np.sin(eq.alpha[4])
    if abs(s4) < 0.5 or abs(s5) < 0.5 or abs(eq.a[1]) < 1.0:
        return False
    if kind == "spherical":
        return bool(np.hypot(eq.a[2], np.sin(eq.alpha[2]) * eq.d[3]) > 1.0)
    return abs(eq.a[2]) > 1.0


def form_of(eq: DHEquivalent | None) -> tuple[str | None, bool]:
    """The closed form a 6R equivalent is (or is near), and whether exactly."""
    if eq is None or len(eq.a) != 6:
        return None, False
    best = None
    for kind in KINDS:
        ang, length = _gap(eq, kind)
        if ang <= NEAR_RAD and length <= NEAR_MM and _usable(eq, kind):
            exact = ang <= EXACT_RAD and length <= EXACT_MM
            if best is None or (exact and not best[1]):
                best = (kind, exact)
    return best if best is not None else (None, False)


def idealized(eq: DHEquivalent, kind: str) -> DHEquivalent:
    """The equivalent with the parameters the form fixes set to their ideal values."""
    values = {k: getattr(eq, k).copy() for k in ("a", "alpha", "d")}
    for (name, i), value in _snaps(eq, kind).items():
        values[name][i] = value
    return DHEquivalent(values["a"], values["alpha"], eq.theta, values["d"], eq.s, eq.base, eq.tool)


def _acos_pair(c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """±acos(c), and whether c is a cosine (a rounding's worth beyond ±1 is let through)."""
    ok = np.abs(c) <= 1.0 + 1e-9
    angle = np.arccos(np.clip(c, -1.0, 1.0))
    return angle, ok


def _wrist(M: np.ndarray, alpha4: float, alpha5: float, sign: float):
    """φ4, φ5, φ6 of M = Rz(φ4) Rx(α4) Rz(φ5) Rx(α5) Rz(φ6), on the branch sign·φ5 ≥ 0."""
    c4, s4, c5, s5 = np.cos(alpha4), np.sin(alpha4), np.cos(alpha5), np.sin(alpha5)
    e = M[..., :, 2]
    b, ok = _acos_pair((c4 * c5 - e[..., 2]) / (s4 * s5))
    phi5 = sign * b
    X, Y = s5 * np.sin(phi5), -c4 * s5 * np.cos(phi5) - s4 * c5
    phi4 = np.arctan2(e[..., 1], e[..., 0]) - np.arctan2(Y, X)
    W = rot_z(phi4) @ rot_x(np.full_like(phi4, alpha4)) @ rot_z(phi5) @ rot_x(np.full_like(phi4, alpha5))
    N = np.swapaxes(W, -1, -2) @ M
    return phi4, phi5, np.arctan2(N[..., 1, 0], N[..., 0, 0]), ok


def _spherical(eq: DHEquivalent, Tf: np.ndarray):
    a, al, d = eq.a, eq.alpha, eq.d
    p = Tf[:, :3, 3] - d[5] * Tf[:, :3, 2]
    s1 = np.sin(al[0])
    ux, uy, uz = a[2], -np.sin(al[2]) * d[3], d[2] + np.cos(al[2]) * d[3]
    L = d[1] + uz
    rho_u, beta = np.hypot(ux, uy), np.arctan2(uy, ux)
    r2 = p[:, 0] ** 2 + p[:, 1] ** 2 - L * L
    rho = np.sqrt(np.maximum(r2, 0.0))
    out, valid = [], []
    for shoulder in (1.0, -1.0):
        X1 = shoulder * rho
        phi1 = np.arctan2(p[:, 1], p[:, 0]) - np.arctan2(-s1 * L, X1)
        Px, Py = X1 - a[0], (p[:, 2] - d[0]) / s1
        c3, ok3 = _acos_pair((Px ** 2 + Py ** 2 - a[1] ** 2 - rho_u ** 2) / (2 * a[1] * rho_u))
        for elbow in (1.0, -1.0):
            phi3 = elbow * c3 - beta
            phi2 = np.arctan2(Py, Px) - np.arctan2(rho_u * np.sin(phi3 + beta), a[1] + rho_u * np.cos(phi3 + beta))
            R03 = rot_z(phi1) @ rot_x(np.full_like(phi1, al[0])) @ rot_z(phi2 + phi3) @ rot_x(np.full_like(phi1, al[2]))
            M = np.swapaxes(R03, -1, -2) @ Tf[:, :3, :3]
            for wrist in (1.0, -1.0):
                phi4, phi5, phi6, ok5 = _wrist(M, al[3], al[4], wrist)
                out.append(np.stack([phi1, phi2, phi3, phi4, phi5, phi6], -1))
                valid.append((r2 >= -1e-9) & ok3 & ok5)
    return np.stack(out, 1), np.stack(valid, 1)


def _dh(phi: np.ndarray, a: float, alpha: float, d: float) -> np.ndarray:
    """Standard DH transforms (m, 4, 4) of angles φ (m,)."""
    T = np.zeros(phi.shape + (4, 4))
    T[..., :3, :3] = rot_z(phi) @ rot_x(np.full_like(phi, alpha))
    T[..., 0, 3], T[..., 1, 3], T[..., 2, 3], T[..., 3, 3] = a * np.cos(phi), a * np.sin(phi), d, 1.0
    return T


def _offset(eq: DHEquivalent, Tf: np.ndarray):
    a, al, d = eq.a, eq.alpha, eq.d
    o5 = Tf[:, :3, 3] - d[5] * Tf[:, :3, 2]
    s1 = np.sin(al[0])
    c4, s4, c5, s5 = np.cos(al[3]), np.sin(al[3]), np.cos(al[4]), np.sin(al[4])
    D = d[1] + d[2] + d[3] + c4 * d[4]
    r = np.hypot(o5[:, 0], o5[:, 1])
    psi = np.arctan2(o5[:, 1], o5[:, 0])
    ratio = s1 * D / np.maximum(r, 1e-300)
    ok1 = np.abs(ratio) <= 1.0 + 1e-9
    lean = np.arcsin(np.clip(ratio, -1.0, 1.0))
    out, valid = [], []
    for shoulder in (1.0, -1.0):
        phi1 = psi + (lean if shoulder > 0 else np.pi - lean)
        z1 = np.stack([s1 * np.sin(phi1), -s1 * np.cos(phi1), np.zeros_like(phi1)], -1)
        c, ok5 = _acos_pair((c4 * c5 - np.einsum("mi,mi->m", Tf[:, :3, 2], z1)) / (s4 * s5))
        z1_6 = np.einsum("mji,mj->mi", Tf[:, :3, :3], z1)
        T1_inv = invert(_dh(phi1, a[0], al[0], d[0]))
        for wrist in (1.0, -1.0):
            phi5 = wrist * c
            z1_5 = np.stack([s4 * np.sin(phi5), s4 * c5 * np.cos(phi5) + c4 * s5, -s4 * s5 * np.cos(phi5) + c4 * c5],
                            -1)
            # where axis 6 lines up with the parallel axes (φ5 = 0) joint 6 is free: 0 is taken
            free = np.hypot(z1_6[:, 0], z1_6[:, 1]) < 1e-12
            phi6 = np.where(free, 0.0, np.arctan2(z1_5[:, 1], z1_5[:, 0]) - np.arctan2(z1_6[:, 1], z1_6[:, 0]))
            T14 = T1_inv @ Tf @ invert(_dh(phi6, a[5], al[5], d[5])) @ invert(_dh(phi5, a[4], al[4], d[4]))
            Mr = T14[:, :3, :3] @ rot_x(np.full_like(phi1, -al[3]))
            Phi = np.arctan2(Mr[:, 1, 0], Mr[:, 0, 0])
            ox, oy = T14[:, 0, 3] - a[3] * np.cos(Phi), T14[:, 1, 3] - a[3] * np.sin(Phi)
            c3, ok3 = _acos_pair((ox ** 2 + oy ** 2 - a[1] ** 2 - a[2] ** 2) / (2 * a[1] * a[2]))
            for elbow in (1.0, -1.0):
                phi3 = elbow * c3
                phi2 = np.arctan2(oy, ox) - np.arctan2(a[2] * np.sin(phi3), a[1] + a[2] * np.cos(phi3))
                out.append(np.stack([phi1, phi2, phi3, Phi - phi2 - phi3, phi5, phi6], -1))
                valid.append(ok1 & ok5 & ok3)
    return np.stack(out, 1), np.stack(valid, 1)


def solve(eq: DHEquivalent, kind: str, T: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Up to eight solutions (m, 8, 6) of joint values (rad, wrapped into (−π, π]) reaching end
    poses T (m, 4, 4) in the measuring frame, on the form ``kind`` of ``eq`` taken as exact;
    and which exist (m, 8).  Branch k: shoulder (k // 4), elbow, wrist, as :func:`_spherical`
    and :func:`_offset` order them."""
    Tf = invert(eq.base) @ T @ invert(eq.tool)
    phi, valid = (_spherical if kind == "spherical" else _offset)(eq, Tf)
    return eq.q(phi), valid
