"""Program filtering: the corrected value of every target of a program.

The controller keeps its nominal model.  A Cartesian target is the TCP pose the programmer
wants (in the program's base frame).  robocal finds the joints q with which the accurate
(calibrated) robot puts the TCP there, on the configuration the target names, and writes the
pose the nominal model gives for q: the controller, inverting its nominal model on that
configuration, then commands exactly q.  A joint target keeps its intent, the pose the
nominal model gives for the taught joints: it is replaced by the joints that make the
accurate robot reach that pose.  Every corrected target is checked by sending it back through
the nominal inverse and the accurate forward model; a target that cannot be corrected (out of
reach, singular, at a limit, or the check fails) keeps its value and is flagged.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..compensation.commands import compensate
from ..compensation.ik import solve_ik
from ..io.goals import Goals
from ..math.se3 import homogeneous, invert
from ..math.so3 import orientation_error
from ..model.jointspace import ready_configurations
from ..model.robot import Robot
from .program import Program, Target

#: the round trip (nominal inverse, accurate forward) must land within these (mm, deg)
CHECK_MM, CHECK_DEG = 0.01, 0.001
#: a nominal solution reaches its target within these (mm, rad)
REACHED_MM, REACHED_RAD = 1e-3, 1e-6
#: a correction beyond this (mm) is not a calibration's: two different robots or tools
LARGE_CORRECTION_MM = 20.0
#: random starts of the nominal inverse, beside the well-conditioned ones
RANDOM_STARTS = 24


@dataclass
class Correction:
    """A target's outcome: status (``ok`` or why it was left as it was), the corrected pose
    (4×4, program frame, mm) or joints (rad), the accurate robot's joints for it, how much it
    moved (mm, deg; joints: deg) and what the round trip shows (mm, deg)."""

    target: Target
    status: str
    pose: np.ndarray | None = None
    q: np.ndarray | None = None
    moved_mm: float = 0.0
    turned_deg: float = 0.0
    joints_deg: float = 0.0
    check_mm: float | None = None
    check_deg: float | None = None

    @property
    def corrected(self) -> bool:
        return self.status == "ok"

    def to_dict(self) -> dict:
        t = self.target
        out = {"target": t.name, "line": t.line, "kind": t.kind, "status": self.status}
        if self.corrected:
            out.update({"moved_mm": self.moved_mm, "turned_deg": self.turned_deg, "joints_deg": self.joints_deg,
                        "check_mm": self.check_mm, "check_deg": self.check_deg})
        return out


def _gap(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Distance (mm) and angle (deg) between frames a and b (m, 4, 4)."""
    return (np.linalg.norm(a[:, :3, 3] - b[:, :3, 3], axis=1),
            np.degrees(np.linalg.norm(orientation_error(a[:, :3, :3], b[:, :3, :3]), axis=1)))


def config_mismatch(language: str, q: np.ndarray, config: dict) -> int:
    """How many of the configuration flags a target names the joints q (n,) rad miss."""
    deg = np.degrees(q)
    if language == "krl" and "T" in config:
        turn = sum(1 << i for i in range(min(6, len(q))) if deg[i] < 0)
        return bin(turn ^ config["T"]).count("1")
    if language == "rapid" and "cf1" in config:
        return sum(int(math.floor(deg[j] / 90.0)) != config[k] for j, k in ((0, "cf1"), (3, "cf4"), (5, "cf6"))
                   if j < len(q))
    return 0


def _turns(q: np.ndarray, turn: int, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """q with each joint whose sign differs from KRL's T turned by ±360° where the limits allow."""
    q = q.copy()
    for i in range(min(6, len(q))):
        negative = bool(turn >> i & 1)
        if (q[i] < 0) != negative:
            alt = q[i] + (-2.0 if not negative else 2.0) * np.pi
            if lo[i] <= alt <= hi[i]:
                q[i] = alt
    return q


def nominal_joints(nominal: Robot, goals: np.ndarray, targets: list[Target], language: str,
                   seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Joints (m, n) rad with which the nominal model reaches each goal (m, 4, 4) on the
    configuration its target names (KRL T, RAPID cf1 cf4 cf6, a PolyScope waypoint's taught
    joints), nearest the previous target's where the flags leave a choice; and whether reached."""
    m, n = len(goals), nominal.n_joints
    rng = np.random.default_rng(seed)
    lo, hi = nominal.limits[:, 0], nominal.limits[:, 1]
    finite_lo, finite_hi = np.where(np.isfinite(lo), lo, -np.pi), np.where(np.isfinite(hi), hi, np.pi)
    starts = np.vstack([*ready_configurations(nominal)[:8], rng.uniform(finite_lo, finite_hi, (RANDOM_STARTS, n))])
    per_target = []
    for t in targets:
        extra = [t.taught] if t.taught is not None else []
        if language == "krl" and "T" in t.config:  # the signs T names, on the well-conditioned starts
            signs = np.array([-1.0 if t.config["T"] >> i & 1 else 1.0 for i in range(n)])
            extra += [np.clip(np.maximum(np.abs(s0), np.radians(5.0)) * signs, lo, hi) for s0 in starts[:8]]
        if language == "rapid" and "cf1" in t.config:  # the quadrants' middles
            s = starts[0].copy()
            for j, k in ((0, "cf1"), (3, "cf4"), (5, "cf6")):
                s[j] = np.radians((t.config[k] + 0.5) * 90.0)
            extra.append(np.clip(s, lo, hi))
        per_target.append(np.vstack([*extra, starts]) if extra else starts)
    k = max(len(s) for s in per_target)
    seeds = np.stack([np.vstack([s, np.repeat(s[-1:], k - len(s), axis=0)]) for s in per_target])  # (m, k, n)
    T = np.repeat(goals, k, axis=0)
    sol = solve_ik(nominal, T[:, :3, 3], T[:, :3, :3], seeds.reshape(-1, n))
    q = sol.q.reshape(m, k, n)
    ok = ((sol.position_error <= REACHED_MM) & (sol.rotation_error <= REACHED_RAD)).reshape(m, k)
    out, reached, previous = np.zeros((m, n)), np.zeros(m, bool), None
    for i, t in enumerate(targets):
        candidates = [j for j in range(k) if ok[i, j]]
        if not candidates:
            continue
        if language == "krl" and "T" in t.config:  # a turn of ±360° within the limits: the same pose
            for j in candidates:
                q[i, j] = _turns(q[i, j], t.config["T"], lo, hi)
        reference = t.taught if t.taught is not None else previous
        scores = [(config_mismatch(language, q[i, j], t.config),
                   0.0 if reference is None else float(np.max(np.abs(q[i, j] - reference)))) for j in candidates]
        best = candidates[min(range(len(candidates)), key=scores.__getitem__)]
        out[i], reached[i], previous = q[i, best], True, q[i, best]
    return out, reached


def filter_targets(program: Program, nominal: Robot, accurate: Robot, tool: np.ndarray | None = None,
                   seed: int = 0) -> tuple[list[Correction], list[str]]:
    """The correction of every target of ``program`` (see the module docstring); the notes."""
    notes = list(program.notes)
    tcp = tool if tool is not None else (program.tool if program.tool is not None else nominal.tool)
    base = program.base
    base = np.eye(4) if base is None else base
    nominal = nominal.with_tool(tcp)
    out: dict[int, Correction] = {}
    poses = [i for i, t in enumerate(program.targets) if t.kind == "pose"]
    joints = [i for i, t in enumerate(program.targets) if t.kind == "joints"]
    if poses:
        targets = [program.targets[i] for i in poses]
        goals = base @ homogeneous(np.stack([t.rotation for t in targets]), np.stack([t.position for t in targets]))
        q_nom, reached = nominal_joints(nominal, goals, targets, program.language, seed)
        for i, t, r in zip(poses, targets, reached):
            if not r:
                out[i] = Correction(t, "unreachable (nominal model)")
        keep = [j for j, r in enumerate(reached) if r]
        if keep:
            res = _compensate(nominal, accurate, tcp, q_nom[keep], goals[keep], notes)
            for j, c in zip(keep, res):
                out[poses[j]] = c(program.targets[poses[j]], base)
    if joints:
        targets = [program.targets[i] for i in joints]
        q = np.stack([t.q for t in targets])
        res = _compensate(nominal, accurate, tcp, q, None, notes)
        for i, c in zip(joints, res):
            out[i] = c(program.targets[i], base)
    corrections = [out[i] for i in range(len(program.targets))]
    _round_trip(nominal, accurate, tcp, corrections, base)
    largest = max((c for c in corrections if c.corrected), key=lambda c: c.moved_mm, default=None)
    check = ("check that --nominal is the model this controller runs and that the calibrated model is of the same "
             "robot, with the same tool")
    if largest is None:
        notes.append(f"no target could be corrected: {check}")
    elif largest.moved_mm > LARGE_CORRECTION_MM:
        notes.append(f"target {largest.target.name} moves by {largest.moved_mm:.4g} mm: a calibration corrects by a "
                     f"few millimetres; {check}")
    if tool is None:  # compensation speaks of a --tool; here the TCP came from the program or the robot file
        whose = "the program's tool" if program.tool is not None else "the nominal model's tool"
        notes = [n.replace("the --tool given", whose) for n in notes]
    return corrections, notes


def _compensate(nominal: Robot, accurate: Robot, tcp: np.ndarray, q: np.ndarray, goals: np.ndarray | None,
                notes: list[str]):
    """compensate() on these goals: poses (with their nominal joints as starts) or joint sets."""
    m = len(q)
    ids = [str(i) for i in range(m)]
    if goals is None:
        g = Goals(q=q, position=None, rotation=None, ids=ids, source="program")
    else:
        g = Goals(q=q, position=goals[:, :3, 3], rotation=goals[:, :3, :3], ids=ids, source="program")
    res = compensate(nominal, accurate, g, tool=tcp)
    for w in res.warnings:
        if w not in notes:
            notes.append(w)

    def make(k):
        def build(target: Target, base: np.ndarray) -> Correction:
            status = res.status[k]
            if status != "ok":
                return Correction(target, status)
            pose = invert(base) @ invert(nominal.base) @ res.cartesian[k]
            if target.kind == "pose":
                original = homogeneous(target.rotation, target.position)
                mm, deg = _gap(pose[None], original[None])
                return Correction(target, "ok", pose=pose, q=res.q[k], moved_mm=float(mm[0]), turned_deg=float(deg[0]),
                                  joints_deg=float(np.degrees(np.max(np.abs(res.q[k] - res.q_nominal[k])))))
            return Correction(target, "ok", q=res.q[k],
                              joints_deg=float(np.degrees(np.max(np.abs(res.q[k] - target.q)))))
        return build

    return [make(k) for k in range(m)]


def _round_trip(nominal: Robot, accurate: Robot, tcp: np.ndarray, corrections: list[Correction],
                base: np.ndarray) -> None:
    """Each corrected target through the controller's view (nominal inverse on the solution's
    branch, or the joints as written) and the accurate forward model, against its intent."""
    from ..compensation.commands import with_tcp

    nominal_t, accurate_t, _ = with_tcp(nominal, accurate, None, tcp, [])
    for c in corrections:
        if not c.corrected:
            continue
        if c.target.kind == "pose":
            T = base @ c.pose
            sol = solve_ik(nominal_t, T[None, :3, 3], T[None, :3, :3], c.q[None])
            q = sol.q[0]
            intent = base @ homogeneous(c.target.rotation, c.target.position)
        else:
            q = c.q
            intent = nominal_t.fk(c.target.q[None])[0]
        reached = accurate_t.base @ invert(nominal_t.base) @ intent  # the accurate model's frame
        mm, deg = _gap(accurate_t.fk(q[None]), reached[None])
        c.check_mm, c.check_deg = float(mm[0]), float(deg[0])
        if c.check_mm > CHECK_MM or c.check_deg > CHECK_DEG:
            c.status = "check failed"
