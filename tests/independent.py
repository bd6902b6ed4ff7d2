"""An independent simulator for planted-truth tests: it shares no code with robocal.

Forward kinematics is the textbook product of 4×4 elementary matrices, one pose at a time,
written here from MODEL §1; noise comes from numpy's generator and scipy's rotations.  Tests
plant a truth with it and check what robocal recovers, so an error in robocal's kinematics
cannot cancel out.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

# Nominal tables (a mm, alpha deg, theta deg, d mm) of Wen et al. Table 1, of the KR5 arc's, IRB 120's
# and UR10's public DH tables, copied here on purpose.
TABLES = {
    "er10l-c10": [(170, -90, 0, 0), (780, 0, -90, 0), (140, -90, 0, 0), (0, 90, 0, 1060), (0, -90, 0, 0),
                  (0, 0, 0, 125)],
    "kr5-arc": [(180, -90, 0, 400), (600, 0, -90, 0), (120, 90, 0, 0), (0, -90, 0, -620), (0, 90, 0, 0),
                (0, 180, 0, -115)],
    "irb120": [(0, -90, 0, 290), (270, 0, -90, 0), (70, -90, 0, 0), (0, 90, 0, 302), (0, -90, 0, 0), (0, 0, 180, 72)],
    "ur10": [(0, 90, 0, 127.3), (-612, 0, 0, 0), (-572.3, 0, 0, 0), (0, 90, 0, 163.941), (0, -90, 0, 115.7),
             (0, 0, 0, 92.2)],
    # Universal Robots' published UR5 DH table
    "ur5": [(0, 90, 0, 89.159), (-425, 0, 0, 0), (-392.25, 0, 0, 0), (0, 90, 0, 109.15), (0, -90, 0, 94.65),
            (0, 0, 0, 82.3)],
    # the KR5 arc in KUKA's own axis conventions (A1 about -Z, A2 and A3 about +Y, A4 and A6 about -X), read off
    # ROS-Industrial's kuka_experimental URDF by hand: frame 0 sits at the shoulder's height, turned over (BASES)
    "kr5-kuka": [(180, 90, 0, 0), (600, 0, 0, 0), (120, 90, -90, 0), (0, 90, 180, -620), (0, 90, 180, 0),
                 (0, 0, 0, -115)],
    # a torso that turns the arm about the vertical, 500 mm below the arm's own base: a KR5 arc on
    # a turning column (the head's cameras ride on the torso, link 1)
    "torso-kr5": [(0, 0, 0, 500), (180, -90, 0, 400), (600, 0, -90, 0), (120, 90, 0, 0), (0, -90, 0, -620),
                  (0, 90, 0, 0), (0, 180, 0, -115)],
}
LIMITS_DEG = {
    "er10l-c10": [(-180, 180)] * 6,
    "kr5-arc": [(-155, 155), (-180, 65), (-15, 158), (-350, 350), (-130, 130), (-350, 350)],
    "irb120": [(-165, 165), (-110, 110), (-110, 70), (-160, 160), (-120, 120), (-400, 400)],
    "ur10": [(-360, 360)] * 6,
    "ur5": [(-360, 360)] * 6,
    "kr5-kuka": [(-155, 155), (-180, 65), (-15, 158), (-350, 350), (-130, 130), (-350, 350)],
    "torso-kr5": [(-170, 170), (-155, 155), (-180, 65), (-15, 158), (-350, 350), (-130, 130), (-350, 350)],
}


def _rz(t):
    c, s = np.cos(t), np.sin(t)
    return np.array([[c, -s, 0, 0], [s, c, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1.0]])


def _rx(t):
    c, s = np.cos(t), np.sin(t)
    return np.array([[1, 0, 0, 0], [0, c, -s, 0], [0, s, c, 0], [0, 0, 0, 1.0]])


def _ry(t):
    c, s = np.cos(t), np.sin(t)
    return np.array([[c, 0, s, 0], [0, 1, 0, 0], [-s, 0, c, 0], [0, 0, 0, 1.0]])


def _trans(x, y, z):
    T = np.eye(4)
    T[:3, 3] = (x, y, z)
    return T


def base_of(name: str) -> np.ndarray:
    """The robot's own base frame in its world (the KUKA-convention KR5: 400 mm up, turned over)."""
    return _trans(0, 0, 400) @ _rx(np.pi) if name == "kr5-kuka" else np.eye(4)


def geometry(name: str, deviations: dict[str, float] | None = None) -> dict[str, np.ndarray]:
    """Per-joint arrays a, alpha, theta, d, beta (mm, rad) of a robot with deviations added."""
    t = np.array(TABLES[name], dtype=float)
    g = {"a": t[:, 0].copy(), "alpha": np.radians(t[:, 1]), "theta": np.radians(t[:, 2]), "d": t[:, 3].copy(),
         "beta": np.zeros(len(t))}
    for key, value in (deviations or {}).items():
        kind, joint = key.rstrip("0123456789"), int(key[len(key.rstrip("0123456789")):])
        g[kind][joint - 1] += value
    return g


def _rz_each(t: np.ndarray) -> np.ndarray:
    """Rz(t) for each angle of t (m,): (m, 4, 4)."""
    c, s = np.cos(t), np.sin(t)
    R = np.zeros((len(t), 4, 4))
    R[:, 0, 0], R[:, 0, 1], R[:, 1, 0], R[:, 1, 1] = c, -s, s, c
    R[:, 2, 2] = R[:, 3, 3] = 1.0
    return R


def poses(g: dict[str, np.ndarray], Q: np.ndarray, base=np.eye(4), tool=np.eye(4)) -> np.ndarray:
    """:func:`pose` at each row of Q (m, n) rad: (m, 4, 4), the same product for all the rows at once."""
    Q = np.atleast_2d(np.asarray(Q, dtype=float))
    T = np.broadcast_to(np.asarray(base, dtype=float), (len(Q), 4, 4))
    for i in range(Q.shape[1]):
        link = _trans(0, 0, g["d"][i]) @ _trans(g["a"][i], 0, 0) @ _rx(g["alpha"][i]) @ _ry(g["beta"][i])
        T = T @ _rz_each(Q[:, i] + g["theta"][i]) @ link
    return T @ tool


def pose(g: dict[str, np.ndarray], q: np.ndarray, base=np.eye(4), tool=np.eye(4)) -> np.ndarray:
    """T = base · Π Rz(q+θ) Tz(d) Tx(a) Rx(α) Ry(β) · tool, one 4×4 product per joint (hayati;
    β = 0 is standard DH)."""
    return poses(g, np.asarray(q, dtype=float)[None], base, tool)[0]


def reach(f, q: np.ndarray, target: np.ndarray, iterations: int = 40, tol: float = 1e-9) -> np.ndarray:
    """Joints from q where f (a map of joint sets (m, n) to points (m, 3)) is on ``target``: the
    least-norm Gauss–Newton step on forward differences (1e-7 rad), the point and its six
    neighbours in one call a step."""
    q = np.array(q, dtype=float)
    steps = np.vstack([np.zeros(len(q)), np.eye(len(q)) * 1e-7])
    for _ in range(iterations):
        at = f(q + steps) - target
        if np.max(np.abs(at[0])) < tol:
            break
        q = q - np.linalg.pinv(((at[1:] - at[0]) / 1e-7).T) @ at[0]
    return q


def campaign(name: str, deviations: dict[str, float], n: int, rng: np.random.Generator, *, noise: float,
             angle_noise: float = 0.0, measure: str = "pose", base=np.eye(4), tool=np.eye(4),
             joint_error=None) -> dict[str, np.ndarray | None]:
    """Commanded joints (n, 6) rad, measured positions (n, 3) mm and rotations (n, 3, 3) or None.

    joint_error(q) → Δq (n, 6) rad: an effect of the real robot that a geometric model does not contain.
    """
    lim = np.radians(LIMITS_DEG[name])
    q = rng.uniform(lim[:, 0], lim[:, 1], (n, 6))
    q_real = q + (0.0 if joint_error is None else joint_error(q))
    g = geometry(name, deviations)
    T = poses(g, q_real, base, tool)
    position = T[:, :3, 3] + rng.normal(0.0, noise, (n, 3))
    rotation = None
    if measure == "pose":
        rotation = Rotation.from_rotvec(rng.normal(0.0, angle_noise, (n, 3))).as_matrix() @ T[:, :3, :3]
    return {"q": q, "position": position, "rotation": rotation}


def link_frames(g: dict[str, np.ndarray], q: np.ndarray) -> list[np.ndarray]:
    """The frame after each joint (hayati/DH, base = identity), one 4×4 per joint."""
    T, out = np.eye(4), []
    for i, qi in enumerate(q):
        T = T @ _rz(qi + g["theta"][i]) @ _trans(0, 0, g["d"][i]) @ _trans(g["a"][i], 0, 0) @ _rx(g["alpha"][i]) \
            @ _ry(g["beta"][i])
        out.append(T)
    return out


def gravity_torques(g: dict[str, np.ndarray], q: np.ndarray, masses, centres, step: float = 1e-6) -> np.ndarray:
    """Gravity torques (n,) N·m about each joint, of point masses (kg) at centres (mm, each in its
    link's frame), from the potential energy by central differences: τ_i = ∂(Σ m_j g⃗·c_j)/∂q_i,
    the load joint i holds, with gravity along −z of the base."""
    gvec = np.array([0.0, 0.0, -9.80665])

    def work(qq):
        return sum(m * gvec @ (T @ np.append(c, 1.0))[:3] / 1000.0
                   for m, c, T in zip(masses, centres, link_frames(g, qq)))

    tau = np.zeros(len(q))
    for i in range(len(q)):
        dq = np.zeros(len(q))
        dq[i] = step
        tau[i] = (work(q + dq) - work(q - dq)) / (2 * step)
    return tau


def uniform_deviations(name: str, length: float, angle: float, rng: np.random.Generator) -> dict[str, float]:
    """Deviations of a, d (uniform in ±length mm) and α, θ (±angle rad) of every joint."""
    n = len(TABLES[name])
    out = {}
    for i in range(1, n + 1):
        for kind, half in (("a", length), ("alpha", angle), ("theta", angle), ("d", length)):
            out[f"{kind}{i}"] = float(rng.uniform(-half, half))
    return out


def measurements(name: str, deviations: dict[str, float], n: int, seed: int, **kw):
    """A campaign of :func:`campaign` as robocal's data container (only the container: every
    number is this module's)."""
    from robocal.model.measurements import Measurements

    c = campaign(name, deviations, n, np.random.default_rng(seed), **kw)
    return Measurements(q=c["q"], position=c["position"], rotation=c["rotation"])


def robot_toml(name: str, deviations: dict[str, float], tool=None, base=None, coupling: str = "") -> str:
    """A robot file (standard DH, mm and deg) of a table with deviations (mm, rad), written here:
    how a test hands a planted truth to robocal as a calibrated model.  tool: (x, y, z) mm; base:
    4×4 (default the robot's own, :func:`base_of`); coupling: a [controller] table's TOML."""
    g = geometry(name, deviations)
    lines = [f'name = "{name} (planted)"', 'convention = "dh"']
    B = base_of(name) if base is None else np.asarray(base, float)
    if not np.allclose(B, np.eye(4)):
        rpy = Rotation.from_matrix(B[:3, :3]).as_euler("xyz", degrees=True)  # fixed axes: Rz·Ry·Rx
        lines += ["[base]", "xyz = [" + ", ".join(repr(float(v)) for v in B[:3, 3]) + "]",
                  "rpy = [" + ", ".join(repr(float(v)) for v in rpy) + "]"]
    if coupling:
        lines += [coupling]
    for i in range(len(g["a"])):
        lines += ["[[joint]]", f"a = {float(g['a'][i])!r}", f"alpha = {float(np.degrees(g['alpha'][i]))!r}",
                  f"theta = {float(np.degrees(g['theta'][i]))!r}", f"d = {float(g['d'][i])!r}",
                  f"limits = [{LIMITS_DEG[name][i][0]}, {LIMITS_DEG[name][i][1]}]"]
    if tool is not None:
        lines += ["[tool]", f"xyz = [{tool[0]!r}, {tool[1]!r}, {tool[2]!r}]", "rpy = [0.0, 0.0, 0.0]"]
    return "\n".join(lines) + "\n"


def inverse(g: dict[str, np.ndarray], T_goal: np.ndarray, q0: np.ndarray, tool=np.eye(4), iterations: int = 100,
            base=np.eye(4)):
    """Joints reaching T_goal from q0 by Gauss–Newton on finite differences of :func:`pose` (rad):
    a controller's inverse started from the joints a target was taught at stays on their branch."""
    from scipy.spatial.transform import Rotation as Rot

    q = np.array(q0, float)

    def error(qq):
        T = pose(g, qq, base=base, tool=tool)
        return np.concatenate([T_goal[:3, 3] - T[:3, 3],
                               100.0 * Rot.from_matrix(T_goal[:3, :3] @ T[:3, :3].T).as_rotvec()])

    for _ in range(iterations):
        e = error(q)
        if np.linalg.norm(e) < 1e-10:
            break
        J = np.column_stack([(error(q + h) - e) / 1e-7 for h in np.eye(len(q)) * 1e-7])
        q = q - np.linalg.lstsq(J, e, rcond=None)[0]
    return q

