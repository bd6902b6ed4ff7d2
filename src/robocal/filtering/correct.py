"""Program filtering: the corrected value of every target of a program.

The controller keeps its nominal model.  A Cartesian target is the TCP pose the programmer wants,
in the program's user frame.  robocal finds the joints the controller would go to (its nominal
inverse, on the solution the target's configuration data name, else the one nearest the joints it
was taught at or the previous target's: :func:`~robocal.inverse.solve.controller_joints`), then
from there the joints q with which the calibrated robot puts the TCP on the target, and writes the
pose the nominal model gives for q, with the configuration data of q: the controller, inverting its
model on that configuration, then commands exactly q.  A joint target keeps its intent, the pose
the nominal model gives for the taught joints: it is replaced by the joints that make the
calibrated robot reach that pose.  Frames come from :mod:`robocal.cell.frames`, one chain for
every target.

Every corrected target is checked as a controller would take it: the written program is read
again, each target's new numbers go through the nominal inverse on the configuration it now names
(nearest the taught joints where it names none) and the calibrated forward model, and must land on
the original within CHECK_MM and CHECK_DEG.  A target that cannot be corrected (a frame not given,
out of reach, singular, at a limit, in no solution of its configuration, a failed check) keeps its
numbers and is flagged with its reason and numbers.
"""

from __future__ import annotations

from collections import defaultdict
from dataclasses import dataclass, field

import numpy as np

from ..cell.frames import Cell, frame_gap, make_cell
from ..exceptions import Note
from ..inverse.configuration import arm_configuration
from ..inverse.local import SINGULAR_CONDITION, solve_ik
from ..inverse.solve import controller_joints
from ..math.se3 import homogeneous
from ..model.jointspace import condition_numbers
from ..model.robot import Robot
from .language import Language
from .program import Program, Target

#: the round trip (nominal inverse, calibrated forward) must land within these (mm, deg)
CHECK_MM, CHECK_DEG = 0.01, 0.001
#: an offset motion that lands farther than this from where the program means is flagged (mm): the correction
#: it takes along is its target's, and the calibration's error changes over the offset
OFFSET_FLAG_MM = 0.01
#: a correction beyond this (mm) is not a calibration's: two different robots or tools
LARGE_CORRECTION_MM = 20.0
#: a joint target's correction that turns a joint by more than this (deg) is not a calibration's
#: either: near a singularity (a wrist nearly straight) a hundredth of a degree of the pose needs
#: degrees of the wrist, and the target is left as taught and said, never moved by degrees
LARGE_JOINT_MOVE_DEG = 3.0


@dataclass
class Correction:
    """A target's outcome: ``status`` (``ok``, or why it was left as it was) and ``reason`` (what
    the status means, with its numbers); the corrected pose (4×4 mm, in its user frame) or joints;
    the controller's joints before (``q_nominal``) and the calibrated robot's (``q``), both as the
    controller states them (rad); how much it moved (mm, deg; joints: deg); what the round trip
    shows (mm, deg); the configuration data before and after; the tool and user frame it is in."""

    target: Target
    status: str
    reason: str
    pose: np.ndarray | None = None
    q: np.ndarray | None = None
    q_nominal: np.ndarray | None = None
    moved_mm: float | None = None
    turned_deg: float | None = None
    joints_deg: float | None = None
    check_mm: float | None = None
    check_deg: float | None = None
    config_before: dict = field(default_factory=dict)
    config_after: dict = field(default_factory=dict)
    tool: str | None = None
    user: str | None = None
    #: the TCP the target was solved for (:attr:`robocal.cell.frames.Cell.label`), None where none was
    tcp: str | None = None
    #: the motions that reach it through a literal offset (:class:`~.program.Offset`), each with where it lands
    #: on the calibrated robot once the target is corrected: ``line``, ``text``, ``remaining_mm``, ``remaining_deg``
    #: (from where the program means) and ``uncorrected_mm`` (the same without the correction)
    offsets: list = field(default_factory=list)

    @property
    def corrected(self) -> bool:
        return self.status == "ok"

    def to_dict(self) -> dict:
        t = self.target

        def num(x):
            return None if x is None or not np.isfinite(x) else float(x)

        def deg(q):
            return None if q is None or not np.isfinite(q).all() else [float(v) for v in np.degrees(q)]

        return {"target": t.name, "line": t.line, "kind": t.kind, "status": self.status, "reason": self.reason,
                "tool": self.tool, "tcp": self.tcp, "user_frame": self.user,
                "correction": {"mm": num(self.moved_mm), "deg": num(self.turned_deg),
                               "joints_deg": num(self.joints_deg)},
                "check": {"mm": num(self.check_mm), "deg": num(self.check_deg)},
                "config_before": _plain(self.config_before), "config_after": _plain(self.config_after),
                "joints_before_deg": deg(self.q_nominal), "joints_after_deg": deg(self.q),
                **({"offset_motions": list(self.offsets)} if self.offsets else {})}


def _plain(config: dict) -> dict:
    return {k: (int(v) if isinstance(v, (int, np.integer)) else v) for k, v in config.items()}


def _facts_rows(arm, n: int) -> list[dict | None]:
    """Each of the n rows' configuration facts (``front``, ``elbow``, ``lower``) as Python ints, None for
    every row of an arm whose facts are not defined (``arm`` None)."""
    if arm is None:
        return [None] * n
    return [{"front": a, "elbow": b, "lower": c} for a, b, c in zip(arm.front.tolist(), arm.elbow.tolist(),
                                                                     arm.lower.tolist())]


@dataclass
class Frames:
    """The frames a filter is given beside the program's own: ``tcp`` for every target (an unnamed
    --tool), named tools and user frames (``--tool N=…``, ``--user-frame N=…``), ``user`` for every
    target (an unnamed --user-frame); 4×4 mm.  ``calibrated``: the tools the calibration measured
    (``--tool N=calibrated``; "" for every target's), whose calibrated model's tool stands in for
    them on the calibrated robot (MODEL §1.1)."""

    tcp: np.ndarray | None = None
    tools: dict[str, np.ndarray] = field(default_factory=dict)
    users: dict[str, np.ndarray] = field(default_factory=dict)
    user: np.ndarray | None = None
    calibrated: frozenset[str] = frozenset()

    def measured(self, tool: str | None) -> bool:
        """Whether the calibrated model's tool stands in for the target's tool ``tool``."""
        return "" in self.calibrated or (tool is not None and tool in self.calibrated)


def _resolve(program: Program, frames: Frames, t: Target, nominal: Robot):
    """(tool key, TCP, source, the calibrated tool stands in) and (user frame or None), or the
    reason one is unknown."""
    measured = frames.measured(t.tool)
    if frames.tcp is not None:
        tool = ("--tool", frames.tcp, "the --tool given", measured)
    elif t.tool is None:
        tool = ("", None, "the nominal model's tool", measured)
    elif t.tool in frames.tools:
        tool = (t.tool, frames.tools[t.tool], f"tool {t.tool} (given)", measured)
    elif t.tool in program.tools:
        tool = (t.tool, program.tools[t.tool], f"the program's tool {t.tool}", measured)
    else:
        said = (f"; --tool {t.tool}=calibrated says the calibration measured it, but the controller's data for it "
                f"are needed all the same (--tool {t.tool}=x,y,z,rx,ry,rz,calibrated)") if measured else ""
        return None, None, f"its tool {t.tool} is unknown: " + _missing(
            program, "tool", t.tool, f"the program does not declare it (give --tool {t.tool}=x,y,z,rx,ry,rz)") + said
    if t.kind == "joints":  # a joint target is where its joints put the TCP: no user frame moves it
        return tool, None, None
    if frames.user is not None:
        return tool, frames.user, None
    if t.user is None:
        return tool, None, None
    if t.user in frames.users:
        return tool, frames.users[t.user], None
    if t.user in program.users:
        return tool, program.users[t.user], None
    return None, None, f"its user frame {t.user} is unknown: " + _missing(
        program, "user", t.user, f"the program does not declare it (give --user-frame {t.user}=x,y,z,rx,ry,rz)")


def _missing(program: Program, kind: str, name: str, default: str) -> str:
    """Why the program does not say a frame: by kind and name (``tool:2``; FANUC's UT 2 and UF 2 are
    not one frame), else by name."""
    return program.missing.get(f"{kind}:{name}", program.missing.get(name, default))


def _check_unnamed(program: Program, frames: Frames) -> None:
    """An unnamed --tool or --user-frame stands for every target's: refused where the program's
    targets name several (which one is it?)."""
    from ..exceptions import InputError

    for given, attr, option in ((frames.tcp, "tool", "tool"), (frames.user, "user", "user_frame")):
        named = sorted({str(getattr(t, attr)) for t in program.targets if not t.unsupported}, key=str)
        if given is not None and len(named) > 1:
            flag = "--" + option.replace("_", "-")
            raise InputError(f"the program's targets are taught in {len(named)} {attr}s ({', '.join(named)}): "
                             f"name the one given ({flag} NAME=x,y,z,rx,ry,rz)", option=option)


def plan(program: Program, language: Language, nominal: Robot, accurate: Robot, frames: Frames,
         seed: int = 0) -> tuple[list[Correction], list[str]]:
    """The correction of every target of ``program`` (see the module docstring), before the
    check; the notes."""
    notes = list(program.notes)
    _check_unnamed(program, frames)
    out: dict[int, Correction] = {}
    groups: dict[str, list] = defaultdict(list)
    cells: dict[str, Cell] = {}
    hints = _order_hints(program, nominal)
    for i, t in enumerate(program.targets):
        if t.unsupported:
            out[i] = Correction(t, "unsupported", t.unsupported, tool=t.tool, user=t.user)
            continue
        tool, user, why = _resolve(program, frames, t, nominal)
        if why:
            out[i] = Correction(t, "frame", why, tool=t.tool, user=t.user)
            continue
        key = tool[0], tool[3]
        if key not in cells:
            cells[key] = make_cell(nominal, accurate, *tool[1:])
            notes += [n for n in cells[key].notes if n not in notes]
            if tool[0] == "":
                notes.append("the program names no tool: the TCP is the nominal model's tool (give --tool)")
        groups[key].append((i, user))
    for key, members in groups.items():
        cell = cells[key]
        poses = [(i, u) for i, u in members if program.targets[i].kind == "pose"]
        joints = [(i, u) for i, u in members if program.targets[i].kind == "joints"]
        if poses:
            out.update(_poses(program, language, cell, poses, hints, seed))
        if joints:
            out.update(_joints(program, language, cell, joints))
    return [out[i] for i in range(len(program.targets))], notes


def _order_hints(program: Program, nominal: Robot) -> np.ndarray:
    """Per target, the model's joints to solve it near: its own (taught, qnear), else those of a
    joint target just before it in the program; NaN where none (it follows the previous target)."""
    n = nominal.n_joints
    out = np.full((len(program.targets), n), np.nan)
    previous = None
    for i, t in enumerate(program.targets):
        if t.kind == "joints":
            previous = nominal.from_controller(t.q) if t.q is not None and len(t.q) == n else None
            continue
        if t.hint is not None and len(t.hint) == n:
            out[i] = nominal.from_controller(t.hint)
        elif previous is not None:
            out[i] = previous
        previous = None if t.kind == "pose" else previous
    return out


def _poses(program: Program, language: Language, cell: Cell, members, hints, seed) -> dict[int, Correction]:
    nominal, accurate = cell.nominal, cell.accurate
    idx = [i for i, _ in members]
    targets = [program.targets[i] for i in idx]
    users = [u for _, u in members]
    T_prog = homogeneous(np.stack([t.rotation for t in targets]), np.stack([t.position for t in targets]))
    goals = cell.goal(users, T_prog)
    requests = [language.request(t) for t in targets]
    q_nom, status, reasons, _ = controller_joints(nominal, goals, hints[idx], requests, seed)
    out: dict[int, Correction] = {}
    ok = [k for k, s in enumerate(status) if s == "ok"]
    for k, s in enumerate(status):
        if s != "ok":
            out[idx[k]] = Correction(targets[k], f"{s} (nominal)", reasons[k], config_before=targets[k].config,
                                     tool=targets[k].tool, user=targets[k].user, tcp=cell.label)
    if not ok:
        return out
    g = cell.to_accurate(goals[ok])
    sol = solve_ik(accurate, g[:, :3, 3], g[:, :3, :3], q_nom[ok])
    singular = condition_numbers(nominal, q_nom[ok], True, 1000.0) > SINGULAR_CONDITION
    q_acc = sol.q
    new_world = nominal.fk(q_acc)
    new_prog = cell.in_user([users[k] for k in ok], new_world)
    moved_mm, turned_deg = frame_gap(new_prog, T_prog[ok])
    arm_nom, arm_acc = arm_configuration(nominal, q_nom[ok]), arm_configuration(nominal, q_acc)
    J_nom, J_acc = nominal.to_controller(q_nom[ok]), nominal.to_controller(q_acc)
    moved_deg = np.degrees(np.max(np.abs(q_acc - q_nom[ok]), axis=1))
    # per target, Python values taken once (ten thousand targets: numpy's scalars a row cost more than the rest)
    facts_nom, facts_acc, singular = _facts_rows(arm_nom, len(ok)), _facts_rows(arm_acc, len(ok)), singular.tolist()
    mm_l, deg_l, joints_l = moved_mm.tolist(), turned_deg.tolist(), moved_deg.tolist()
    for j, k in enumerate(ok):
        t, i = targets[k], idx[k]
        before = t.config or language.encode(J_nom[j], facts_nom[j], {})
        common = dict(q_nominal=J_nom[j], config_before=before, tool=t.tool, user=t.user, tcp=cell.label)
        st = "singular" if singular[j] and sol.status[j] in ("ok", "branch") else sol.status[j]
        # (a Cartesian target's joints are the controller's to find: near a wrist singularity its own
        # inverse swings axes 4 and 6 for the pose written, corrected or not)
        why = sol.reason(j) if st == sol.status[j] else "the nominal model is singular at its joints"
        if st != "ok":
            out[i] = Correction(t, st, why, **common)
            continue
        out[i] = Correction(t, "ok", "corrected", pose=new_prog[j], q=J_acc[j], moved_mm=mm_l[j],
                            turned_deg=deg_l[j], joints_deg=joints_l[j],
                            config_after=language.encode(J_acc[j], facts_acc[j], t.config),
                            offsets=_offset_motions(cell, users[k], T_prog[k], new_prog[j], q_acc[j], q_nom[k],
                                                    t.offsets) if t.offsets else [], **common)
    return out


def _offset_motions(cell: Cell, user, intended: np.ndarray, written: np.ndarray, q_target: np.ndarray,
                    q_taught: np.ndarray, offsets: list) -> list[dict]:
    """Where each offset motion of a corrected target lands on the calibrated robot: the controller goes to
    the offset of the written (corrected) target, by its own inverse from the target's joints; the
    distance from the offset of the intended one is what the correction, the target's, leaves there
    (mm, deg).  Beside it, the same without the correction."""
    n = len(offsets)
    users = [user] * n
    want = cell.goal(users, np.stack([o.apply(intended) for o in offsets]))
    sent = cell.goal(users, np.stack([o.apply(written) for o in offsets]))
    out = []
    for goal, start in ((sent, q_target), (want, q_taught)):
        sol = solve_ik(cell.nominal, goal[:, :3, 3], goal[:, :3, :3], np.tile(start, (n, 1)))
        out.append((frame_gap(cell.from_accurate(cell.accurate.fk(sol.q)), want), sol.status))
    (mm, deg), status = out[0]
    before = out[1][0][0]
    return [{"line": o.line, "text": o.text, "remaining_mm": float(mm[k]), "remaining_deg": float(deg[k]),
             "uncorrected_mm": float(before[k]), "solved": status[k]} for k, o in enumerate(offsets)]


def _joints(program: Program, language: Language, cell: Cell, members) -> dict[int, Correction]:
    nominal, accurate = cell.nominal, cell.accurate
    idx = [i for i, _ in members]
    targets = [program.targets[i] for i in idx]
    q = nominal.from_controller(np.stack([t.q for t in targets]))
    intent = cell.to_accurate(nominal.fk(q))
    sol = solve_ik(accurate, intent[:, :3, 3], intent[:, :3, :3], q)
    cond = condition_numbers(nominal, q, True, 1000.0)
    singular = cond > SINGULAR_CONDITION
    out = {}
    for j, (t, i) in enumerate(zip(targets, idx)):
        common = dict(q_nominal=t.q, tool=t.tool, user=t.user, tcp=cell.label)
        st = "singular" if singular[j] and sol.status[j] in ("ok", "branch") else sol.status[j]
        why = sol.reason(j) if st == sol.status[j] else "the nominal model is singular at the taught joints"
        if st == "ok" and np.degrees(np.max(np.abs(sol.q[j] - q[j]))) > LARGE_JOINT_MOVE_DEG:
            st, why = "singular", _large_move(nominal.to_controller(q[j]), nominal.to_controller(sol.q[j]), cond[j])
        if st != "ok":
            out[i] = Correction(t, st, why, **common)
            continue
        out[i] = Correction(t, "ok", "corrected", q=nominal.to_controller(sol.q[j]),
                            joints_deg=float(np.degrees(np.max(np.abs(sol.q[j] - q[j])))), **common)
    return out


def _large_move(before: np.ndarray, after: np.ndarray, condition: float) -> str:
    """Why a correction that turns a joint by degrees is not made: which joint, how far, and the
    conditioning that asks for it."""
    moved = np.degrees(np.abs(after - before))
    j = int(np.argmax(moved))
    return (f"the correction would turn joint {j + 1} by {moved[j]:.3g}° (condition number {condition:.3g} of the "
            f"nominal joint Jacobian: near a singularity, a hundredth of a degree of the pose needs degrees of the "
            f"joints); left as taught")


def check(program: Program, reread: Program, language: Language, corrections: list[Correction], nominal: Robot,
          accurate: Robot, frames: Frames, seed: int = 0) -> None:
    """Each corrected target as the controller takes it from the written program (``reread``):
    its new numbers through the nominal inverse on the configuration they name, nearest the joints
    it was taught at, and the calibrated forward model, against its intent; a target that lands
    further than CHECK_MM / CHECK_DEG is ``check failed`` (and left as it was by the caller)."""
    hints = _order_hints(program, nominal)
    cells: dict[str, tuple] = {}
    for i, c in enumerate(corrections):
        if not c.corrected:
            continue
        tool, user, _ = _resolve(program, frames, c.target, nominal)
        key = tool[0], tool[3]
        if key not in cells:
            cells[key] = (make_cell(nominal, accurate, *tool[1:]), [])
        cells[key][1].append((i, user))
    for cell, members in cells.values():
        poses = [(i, u) for i, u in members if corrections[i].target.kind == "pose"]
        joints = [i for i, _ in members if corrections[i].target.kind == "joints"]
        reached, intent = [], []
        if poses:
            idx = [i for i, _ in poses]
            new = [reread.targets[i] for i in idx]
            T_new = homogeneous(np.stack([t.rotation for t in new]), np.stack([t.position for t in new]))
            T_old = homogeneous(np.stack([corrections[i].target.rotation for i in idx]),
                                np.stack([corrections[i].target.position for i in idx]))
            goals = cell.goal([u for _, u in poses], T_new)
            start = np.where(np.isnan(hints[idx]), nominal.from_controller(np.stack([corrections[i].q_nominal
                                                                                     for i in idx])), hints[idx])
            q, status, _, _ = controller_joints(cell.nominal, goals, start, [language.request(t) for t in new], seed)
            q = np.where(np.isfinite(q), q, 0.0)
            reached.append((idx, cell.accurate.fk(q), np.array([s == "ok" for s in status])))
            intent.append(cell.to_accurate(cell.goal([u for _, u in poses], T_old)))
        if joints:
            q_new = nominal.from_controller(np.stack([reread.targets[i].q for i in joints]))
            q_old = nominal.from_controller(np.stack([corrections[i].target.q for i in joints]))
            reached.append((joints, cell.accurate.fk(q_new), np.ones(len(joints), bool)))
            intent.append(cell.to_accurate(cell.nominal.fk(q_old)))
        for (idx, T, solved), want in zip(reached, intent):
            mm, deg = (v.tolist() for v in frame_gap(T, want))
            solved = solved.tolist()
            for k, i in enumerate(idx):
                c = corrections[i]
                c.check_mm, c.check_deg = mm[k], deg[k]
                if not solved[k] or mm[k] > CHECK_MM or deg[k] > CHECK_DEG:
                    c.status = "check failed"
                    c.reason = (f"sent back through the nominal inverse and the calibrated model, it lands "
                                f"{mm[k]:.3g} mm and {deg[k]:.3g}° from the original (bar {CHECK_MM} mm, "
                                f"{CHECK_DEG}°)" if solved[k] else "the nominal inverse finds no solution of the "
                                "corrected target in the configuration it names")


def summary_notes(corrections: list[Correction], notes: list[str]) -> list[str]:
    """What the corrections say as a whole: none corrected, or a correction no calibration makes."""
    largest = max((c for c in corrections if c.corrected and c.moved_mm is not None), key=lambda c: c.moved_mm,
                  default=None)
    hint = ("check that --nominal is the model this controller runs and that the calibrated model is of the same "
            "robot, with the same tool")
    moved = [(c, o) for c in corrections if c.corrected for o in c.offsets]
    flagged = [(c, o) for c, o in moved if o["remaining_mm"] > OFFSET_FLAG_MM or o["solved"] != "ok"]
    for c, o in flagged:
        notes.append(f"{c.target.name}: its offset motion {o['text']} (line {o['line']}) takes the target's correction "
                     f"and lands {o['remaining_mm']:.4f} mm, {o['remaining_deg']:.4f}° from where the program means "
                     f"(uncorrected: {o['uncorrected_mm']:.3f} mm): the calibration's error changes over the offset")
    if moved and len(flagged) < len(moved):
        largest = max(o["remaining_mm"] for c, o in moved if (c, o) not in flagged)
        notes.append(Note(f"{len(moved) - len(flagged)} offset motion(s) (Offs, RelTool, pose_trans, pose_add of "
                          f"literal values) take their targets' corrections and land within {OFFSET_FLAG_MM:g} mm of "
                          f"where the program means (largest {largest:.4f} mm)"))
    kinematic = [c for c in corrections if c.status not in ("frame", "unsupported")]
    if kinematic and not any(c.corrected for c in corrections):
        notes.append(f"no target could be corrected: {hint}")
    elif largest is not None and largest.moved_mm > LARGE_CORRECTION_MM:
        notes.append(f"target {largest.target.name} moves by {largest.moved_mm:.4g} mm: a calibration corrects by a "
                     f"few millimetres; {hint}")
    return notes


__all__ = ["CHECK_DEG", "CHECK_MM", "Correction", "Frames", "check", "plan", "summary_notes"]
