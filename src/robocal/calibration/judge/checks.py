"""Checks of the data before a calibration: wrong units are errors, degenerate data warnings."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from ...exceptions import InputError
from ...model.jointspace import condition_numbers
from ...model.measurements import Measurements
from ...model.robot import Robot

#: joint Jacobian condition number above which a pose is called near-singular
NEAR_SINGULAR = 1e4
#: a joint whose values span less than this (rad) never moved: its own geometry acts as one fixed
#: transform, which a fitted frame absorbs
STILL_SPAN = math.radians(0.05)
#: a robot whose points spread further than this (mm) is not a robot in millimetres
ROBOT_TOO_LARGE_MM = 100_000.0
#: weight of rotation rows (mm per rad) when judging a pose's conditioning
ROT_WEIGHT = 1000.0


def check_units(robot: Robot, meas: Measurements, frames: str) -> None:
    """Catch metres-for-millimetres and similar: compare the spread of the measured points with
    the spread the nominal model predicts for the same joints."""
    known = meas.targets is not None and all(t == "" or t in robot.targets for t in meas.target_names)
    model = robot.positions(meas.q, meas.targets if known and frames == "none" else None, meas.inputs,
                             meas.chain)
    spread_m = np.linalg.norm(meas.position - meas.position.mean(0), axis=1).max()
    spread_n = np.linalg.norm(model - model.mean(0), axis=1).max()
    robot_file = robot.source or robot.name
    if spread_n > ROBOT_TOO_LARGE_MM or (spread_n < 10 and spread_m > 100):
        # the robot, not the data, is off: a robot file in metres (or a URDF in mm)
        raise InputError(f"the robot's points spread over {spread_n:.4g} mm for these joints, the measured ones over "
                         f"{spread_m:.4g} mm: the robot's lengths look wrong (robot files give mm, URDF files "
                         "metres)", source=robot_file)
    if spread_n > 10 and spread_m < spread_n / 100:
        raise InputError(f"measured points spread over {spread_m:.4g} but the robot predicts {spread_n:.4g} mm: "
                         "positions look like metres; measurement files give mm "
                         "(or state the file's unit with `length_unit` m)",
                         source=meas.source)
    if spread_n > 10 and spread_m > spread_n * 100:
        raise InputError(f"measured points spread over {spread_m:.4g} but the robot predicts {spread_n:.4g} mm: "
                         "positions look like µm or wrong units; measurement files give mm (or state the file's "
                         "unit with `length_unit`)",
                         source=meas.source)


def check_targets(robot: Robot, meas: Measurements, frames: str) -> None:
    """Every target of the data needs a tool frame, from the robot file or identified."""
    if frames == "base+tool":
        return
    missing = [t for t in meas.target_names if t and t not in robot.targets]
    if missing:
        raise InputError(f"target '{missing[0]}' has no tool frame in the robot; identify it with frames base+tool "
                         "or add [targets.NAME] to the robot file", source=meas.source)


def check_validation_targets(robot: Robot, meas: Measurements, validation: Measurements | None) -> None:
    """Validation poses can only be predicted for reflectors the calibration measured or the robot file knows."""
    if validation is None:
        return
    unseen = [t for t in validation.target_names if t and t not in meas.target_names and t not in robot.targets]
    if unseen:
        known = ", ".join(repr(t) for t in meas.target_names)
        raise InputError(f"reflector {unseen[0]!r} of the validation data was never measured for the calibration "
                         f"(calibration reflectors: {known})", source=validation.source)


def still_joints(meas: Measurements) -> list[int]:
    """Indices of the joints that never move in the data (span below :data:`STILL_SPAN`)."""
    if meas.n_poses < 2:
        return []
    return [int(i) for i in np.flatnonzero(np.ptp(meas.q, axis=0) < STILL_SPAN)]


def held_still(meas: Measurements) -> Measurements:
    """The measurements with every still joint at its mean value: what identifiability is judged
    on, so that a joint's read-back jitter of a few thousandths of a degree does not make its
    geometry look separable from the frame that absorbs it (it would be fitted to the jitter)."""
    still = still_joints(meas)
    if not still or len(still) == meas.n_joints:
        return meas
    q = meas.q.copy()
    q[:, still] = q[:, still].mean(axis=0)
    return replace(meas, q=q)


def degeneracy_warnings(robot: Robot, meas: Measurements) -> list[str]:
    """Degenerate but valid data: say what is off; identifiability then drops what it must."""
    out = []
    q = meas.q
    if meas.n_poses > 1 and np.all(np.ptp(q, axis=0) < 1e-9):
        out.append(f"all {meas.n_poses} poses command the same joints: only what a single pose shows can be "
                   "identified")
    else:
        still = [i + 1 for i in still_joints(meas)]
        if still:
            many = len(still) > 1
            out.append(f"joint{'s' if many else ''} {', '.join(map(str, still))} never move{'' if many else 's'} "
                       f"in these data: parameters that need {'their' if many else 'its'} motion are dropped")
    bad = np.flatnonzero(condition_numbers(robot, q, meas.full_pose, ROT_WEIGHT) > NEAR_SINGULAR)
    if bad.size:
        out.append(f"{meas.labels(bad)} are near-singular configurations (joint Jacobian condition > "
                   f"{NEAR_SINGULAR:.0e}): they pin down little")
    return out
