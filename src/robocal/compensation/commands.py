"""Compensated commands: joints and Cartesian goals that make the real robot land on its goals.

The controller still runs its nominal model.  For each goal robocal finds joints q_c with
``FK_calibrated(q_c) = goal`` by damped least squares (batched over all goals), started
from the nominal solution so the arm stays on the same configuration branch, inside the
joint limits.  It returns q_c and, for controllers that take Cartesian goals, the pose the
*nominal* model gives for q_c: sending that pose makes the controller's own inverse
kinematics produce q_c.

Goals are joint sets (go where the nominal model says these joints go) or poses in the
robot base frame (see :mod:`robocal.io.goals`).  A calibrated model with an identified base
is in the measuring frame; goals are moved there with ``base_calibrated · base_nominal⁻¹``.

The calibrated model is used whole: joint compliance (under gravity, or on the goals'
``tau1..tauN`` columns), harmonics and the residual correction all act in the solve.
"""

from __future__ import annotations

import csv
import io
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .. import options as opt
from ..cell.frames import make_cell
from ..exceptions import InputError, Note
from ..inverse.local import ROT_WEIGHT, SINGULAR_CONDITION, solve_ik
from ..inverse.solve import all_solutions, controller_joints
from ..io.atomic import atomic_write
from ..io.goals import Goals
from ..io.measurements import joints_to_file
from ..math.se3 import homogeneous, invert
from ..math.so3 import matrix_to_rpy, orientation_error
from ..model.jointspace import condition_numbers, ready_configurations
from ..model.measurements import move_directions
from ..model.metrics import Metrics
from ..model.robot import Robot
from ..model.terms import JointInputs, drift_note, missing_torques
from ..model.uncertainty import region_note

#: the Cartesian command's columns beside an ISO 9283 plan's commanded pose (``send_x`` …)
ISO_SENT = ("x", "y", "z", "rx", "ry", "rz")


@dataclass
class CompensationResult:
    """Per goal: nominal commands, compensated joints and Cartesian goal, residual, status.

    q_nominal, q: (m, n) rad; cartesian: (m, 4, 4) the nominal FK of q, in the nominal base
    frame (mm); residual_mm / residual_deg: how far the calibrated model's pose at q is from
    the goal.  With a simulated true robot: its position errors (m, 3) mm and orientation
    errors (m, 3) rad at the nominal and at the compensated commands.
    """

    goals: Goals
    q_nominal: np.ndarray
    q: np.ndarray
    cartesian: np.ndarray
    residual_mm: np.ndarray
    residual_deg: np.ndarray
    status: list[str]
    full_pose: bool
    true_before: np.ndarray | None = None
    true_after: np.ndarray | None = None
    true_rot_before: np.ndarray | None = None
    true_rot_after: np.ndarray | None = None
    warnings: list[str] = field(default_factory=list)
    prismatic: np.ndarray | None = None
    #: per goal, what its status means with its numbers
    reasons: list[str] = field(default_factory=list)

    def counts(self) -> dict[str, int]:
        return {s: self.status.count(s) for s in dict.fromkeys(self.status)}

    @property
    def reached(self) -> int:
        return self.status.count("ok")

    def validation(self) -> dict[str, Metrics] | None:
        """True-robot errors at the nominal and at the compensated commands.

        ``nominal_commands`` and ``compensated_commands`` cover the rows with status ok;
        ``compensated_commands_all_rows`` covers every row, whatever its status.
        """
        if self.true_before is None:
            return None
        rows = np.array([s == "ok" for s in self.status])

        def rot(a, sel):
            return None if a is None else a[sel]

        out = {}
        if rows.any():
            out["nominal_commands"] = Metrics.from_errors(self.true_before[rows], rot(self.true_rot_before, rows))
            out["compensated_commands"] = Metrics.from_errors(self.true_after[rows], rot(self.true_rot_after, rows))
        out["compensated_commands_all_rows"] = Metrics.from_errors(self.true_after, self.true_rot_after)
        return out

    def summary(self) -> dict:
        """Counts per status and, with a true robot, its metrics: the JSON summary."""
        out = {"goals": self.goals.n, "status": self.counts(), "full_pose": self.full_pose,
               "warnings": list(self.warnings)}
        val = self.validation()
        if val is not None:
            out["validation"] = {k: v.to_dict() for k, v in val.items()}
        return out

    def to_csv(self) -> str:
        n = self.q.shape[1]
        # an ISO 9283 plan's commands keep its poses, cycles and commanded poses (cx…, what the test is
        # judged against); the Cartesian commands to send are then send_x…
        iso = self.goals.cycles is not None
        header = (["pose", "cycle"] if iso else ["pose_id"]) + [f"q{i + 1}" for i in range(n)] + \
            ["cx", "cy", "cz", "crx", "cry", "crz"] + ([f"send_{a}" for a in ISO_SENT] if iso else [])
        header += ["residual_mm", "residual_deg", "dq_max_deg", "status", "reason"]
        if self.true_before is not None:
            header += ["true_error_before_mm", "true_error_after_mm"]
        out = io.StringIO()
        w = csv.writer(out, lineterminator="\n")
        w.writerow(header)
        qd = joints_to_file(self.q, self.prismatic)
        rpy = np.degrees(matrix_to_rpy(self.cartesian[:, :3, :3]))
        goal_rpy = None if not iso or self.goals.rotation is None else np.degrees(matrix_to_rpy(self.goals.rotation))
        dq = np.abs(joints_to_file(self.q - self.q_nominal, self.prismatic)).max(axis=1)
        for j in range(len(qd)):
            row = [self.goals.ids[j]] + ([self.goals.cycles[j]] if iso else []) + [repr(float(v)) for v in qd[j]]
            if iso:
                row += [repr(float(v)) for v in self.goals.position[j]] + [repr(float(v)) for v in goal_rpy[j]]
            row += [repr(float(v)) for v in self.cartesian[j, :3, 3]] + [repr(float(v)) for v in rpy[j]]
            row += [f"{self.residual_mm[j]:.3e}", f"{self.residual_deg[j]:.3e}", f"{dq[j]:.6f}", self.status[j],
                    self.reasons[j] if self.reasons else ""]
            if self.true_before is not None:
                row += [f"{np.linalg.norm(self.true_before[j]):.6f}", f"{np.linalg.norm(self.true_after[j]):.6f}"]
            w.writerow(row)
        return out.getvalue()

    def save(self, path: str | Path) -> None:
        atomic_write(path, self.to_csv())


def _nominal_commands(nominal: Robot, goals: Goals, position_only: bool | None, rot_weight: float,
                      targets: list[str] | None = None):
    """Desired poses (m, 4, 4) in the controller's world, the nominal joints, whether full pose,
    and the nominal solve's status and reason per goal (None: joint goals need no solve)."""
    m = goals.n
    if goals.position is None:
        return nominal.fk(goals.q, targets), goals.q, True, None
    R = goals.rotation if goals.rotation is not None else np.broadcast_to(np.eye(3), (m, 3, 3))
    T_des = homogeneous(R, goals.position)
    full = goals.rotation is not None
    if full and not position_only and targets is None:
        q, status, reasons, _ = controller_joints(nominal, T_des, goals.q)
        return T_des, q, full, (status, reasons)
    # a position alone (or a reflector's) leaves the arm free: the nearest solution to the start
    start = goals.q if goals.q is not None else np.tile(ready_configurations(nominal)[0], (m, 1))
    sol = solve_ik(nominal, T_des[:, :3, 3], T_des[:, :3, :3] if full and not position_only else None, start,
                   rot_weight=rot_weight, targets=targets)
    reached = [s in ("ok", "branch") for s in sol.status]
    return T_des, sol.q, full, (["ok" if r else s for r, s in zip(reached, sol.status)],
                                ["reached" if r else sol.reason(i) for i, r in enumerate(reached)])


def _check_goal_targets(calibrated: Robot, goals: Goals) -> list[str] | None:
    """Reflectors named by the goals: each must be one the calibrated model knows."""
    if goals.targets is None or all(t == "" for t in goals.targets):
        return None
    unknown = sorted({t for t in goals.targets if t and t not in calibrated.targets})
    if unknown:
        known = ", ".join(repr(t) for t in calibrated.targets) or "none"
        raise InputError(f"reflector {unknown[0]!r} was never calibrated (the calibrated model's reflectors: {known})",
                         source=goals.source)
    return list(goals.targets)


def _other_branches(nominal: Robot, calibrated: Robot, T_des: np.ndarray, T_cal: np.ndarray, q_nom: np.ndarray,
                    sol, rot_weight: float, inputs: JointInputs,
                    nominal_status: list[str]) -> tuple[np.ndarray, list[str]]:
    """Goals whose configuration robocal chose (no joints given) and whose correction left it (a
    jump of tens of degrees, near a branch's singular edge), ran into a singularity or failed: every
    other configuration of
    the nominal model is tried, and the one the calibrated robot reaches with the smallest joint
    correction is taken (``sol`` and the returned nominal joints updated in place of the first
    choice); the notes say how many moved to another configuration."""
    idx = [i for i, s in enumerate(sol.status) if s in ("branch", "no_convergence", "limit", "singular")
           and nominal_status[i] == "ok"]
    if not idx:
        return q_nom, []
    sols = all_solutions(nominal, T_des[idx])
    lo, hi = nominal.limits[:, 0], nominal.limits[:, 1]
    rows, seeds = [], []
    for k, i in enumerate(idx):
        for s in sols.q[k][sols.valid[k]]:
            if np.all((s >= lo) & (s <= hi)):
                rows.append(i)
                seeds.append(s)
    if not rows:
        return q_nom, []
    rows, seeds = np.array(rows), np.array(seeds)
    tried = solve_ik(calibrated, T_cal[rows, :3, 3], T_cal[rows, :3, :3], seeds, rot_weight=rot_weight,
                     inputs=inputs.subset(rows))
    q_nom = q_nom.copy()
    moved = 0
    for i in idx:
        ok = [k for k in np.flatnonzero(rows == i) if tried.status[k] == "ok"]
        if not ok:
            continue
        k = min(ok, key=lambda k: tried.moved[k])
        q_nom[i] = seeds[k]
        for name in ("q", "position_error", "rotation_error", "iterations", "condition", "limit_margin", "moved"):
            getattr(sol, name)[i] = getattr(tried, name)[k]
        sol.status[i] = "ok"
        moved += 1
    said = [f"{moved} goal(s) solved on another configuration than the one chosen first: there the calibrated robot "
            "needed a joint correction of tens of degrees (a singular edge), here a small one"] if moved else []
    return q_nom, said


def compensate(nominal: Robot, calibrated: Robot, goals: Goals, *, truth: Robot | None = None,
               position_only: bool | None = None, rot_weight: float = ROT_WEIGHT,
               payload: float | None = None, tool: np.ndarray | None = None,
               calibrated_tool: bool = False) -> CompensationResult:
    """Compensated commands for every goal (see the module docstring).

    position_only: solve for the position alone (default: for pose goals without
    orientation columns; joint goals use the full nominal pose).  truth: a simulated true
    robot; its errors at the nominal and the compensated commands are returned.  payload:
    kg at every goal, where the goals file has no ``payload`` column.  tool: the TCP the
    commands are for, 4×4 mm in the nominal model's tool frame (its flange); default that frame;
    calibrated_tool: the calibration measured that tool, and the calibrated model's tool stands in
    for it (see :func:`robocal.cell.frames.make_cell`: never by how near the two are).
    Goals with a ``target`` column place that reflector of the calibrated model instead.
    """
    if nominal.n_joints != calibrated.n_joints or (truth is not None and truth.n_joints != nominal.n_joints):
        raise InputError("nominal, calibrated and true robots must have the same number of joints",
                         source=calibrated.source or "compensate")
    notes: list[str] = []
    targets = _check_goal_targets(calibrated, goals)
    if targets is None:
        cell = make_cell(nominal, calibrated, tool, "the --tool given" if tool is not None else "", calibrated_tool)
        notes += cell.notes
        nominal, calibrated, truth = cell.nominal, cell.accurate, None if truth is None else cell.on(truth)
    else:  # the nominal model places the reflectors where the calibrated one has them
        reflectors = {t: calibrated.targets[t] for t in set(targets) if t}
        nominal = nominal.replace(targets={**nominal.targets, **reflectors})
        truth = None if truth is None else truth.replace(targets={**reflectors, **truth.targets})
        cell = make_cell(nominal, calibrated)
    T_des, q_nom, full, nominal_status = _nominal_commands(nominal, goals, position_only, rot_weight, targets)
    full = full and not position_only
    solvable = np.isfinite(q_nom).all(axis=1)
    q_nom = np.where(solvable[:, None], q_nom, 0.0)
    T_cal = cell.to_accurate(T_des)
    load = goals.payload
    if load is None and payload is not None:
        load = np.full(goals.n, opt.number(payload, "payload", minimum=0.0))
    # a backlash model needs each joint's direction into each goal: the file's dir columns, else
    # the goals in the order the robot moves through them (the first one's unknown)
    directions = goals.directions
    if directions is None and calibrated.terms is not None and calibrated.terms.get("backlash") is not None:
        directions = move_directions(q_nom)
        notes.append(Note("backlash: the direction of approach to each goal is taken from the goals' order (the robot "
                          f"moves through them as listed); the first goal's ({goals.ids[0]}) is unknown and its "
                          "backlash left out"))
    inputs = JointInputs(torques=goals.torques, payload=load, directions=directions, time=goals.time,
                         clock="s" if goals.time is not None else "")
    sol = solve_ik(calibrated, T_cal[:, :3, 3], T_cal[:, :3, :3] if full else None, q_nom, rot_weight=rot_weight,
                   inputs=inputs, targets=targets)
    if goals.q is None and full and targets is None and nominal_status is not None:
        q_nom, said = _other_branches(nominal, calibrated, T_des, T_cal, q_nom, sol, rot_weight, inputs,
                                      nominal_status[0])
        notes += said
    notes += [w for w in (missing_torques(calibrated.terms, goals.torques, goals.source),
                          drift_note(calibrated.terms, inputs, goals.source),
                                              region_note(calibrated, sol.q, targets, inputs)) if w]
    # a jump at a goal where the controller's own model is singular is the singularity's doing
    nominal_cond = condition_numbers(nominal, q_nom, full, rot_weight)
    reasons = [(sol.reason(i) + (f"; the nominal model's joint Jacobian has condition number {c:.3g} there, and "
                                 "no other configuration of the goal is reached with small joint corrections"
                                 if s == "branch" else "")) if not (s == "branch" and c > SINGULAR_CONDITION) else
               f"the nominal model's joint Jacobian has condition number {c:.3g} there (a singularity): the "
               f"correction moves the joints by {np.degrees(sol.moved[i]):.3g}°" for i, (s, c) in
               enumerate(zip(sol.status, nominal_cond))]
    sol.status = ["singular" if s == "branch" and c > SINGULAR_CONDITION else s
                  for s, c in zip(sol.status, nominal_cond)]
    if nominal_status is not None:  # a goal the controller's own model cannot solve is said as such
        for i, (st, why) in enumerate(zip(*nominal_status)):
            if st != "ok":
                sol.status[i], reasons[i] = f"{st} (nominal)", why
    result = CompensationResult(
        goals=goals, q_nominal=q_nom, q=sol.q, cartesian=nominal.fk(sol.q, targets),
        residual_mm=sol.position_error,
        residual_deg=np.degrees(sol.rotation_error), status=sol.status, full_pose=full, warnings=notes,
        prismatic=nominal.prismatic, reasons=reasons,
    )
    if truth is not None:
        T_true = truth.base @ invert(nominal.base) @ T_des  # the truth's world, as the calibrated model's
        for attr, q in (("before", q_nom), ("after", sol.q)):
            Tq = truth.fk(q, targets, inputs)
            setattr(result, f"true_{attr}", T_true[:, :3, 3] - Tq[:, :3, 3])
            if full:
                setattr(result, f"true_rot_{attr}", orientation_error(T_true[:, :3, :3], Tq[:, :3, :3]))
    return result
