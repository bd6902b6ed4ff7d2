"""Step 1 of a calibration: the nominal robot, the measurements and validation data, checked
against each other; the frames mode in effect and what was noticed on the way.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from ..exceptions import InputError, Note
from ..io.measurements import load_measurements
from ..io.robotfile import load_robot
from ..model.kinematics import joint_parameter_names
from ..model.measurements import Measurements, concatenate
from ..model.prior import unknown_names
from ..model.robot import Robot
from .config import CalibrationConfig
from .fit import cameras
from .fit.instrument import Instrument, with_instrument
from .fit.registration import choose_frames
from .judge import checks


@dataclass(frozen=True)
class Inputs:
    """The nominal robot, the measurements, validation data, the frames mode in effect, and what
    was noticed on the way (the frames chosen, degenerate data)."""

    nominal: Robot
    meas: Measurements
    validation: Measurements | None
    frames: str
    notes: tuple[str, ...] = ()
    #: the sessions' tracker rows each have a measuring frame (and tools) of their own: the frames
    #: are registered per session, the geometry shared (:func:`session_frames`)
    session_frames: bool = False



def _measurements(data, nominal: Robot, config: CalibrationConfig, columns) -> Measurements:
    """One measurements file (or object), or several: each then a session of its own (its stem), or
    the sessions its own session column names."""
    if isinstance(data, (list, tuple)):
        parts = [_measurements(d, nominal, config, columns) for d in data]
        if not parts:
            raise InputError("no data file given")
        if len(parts) == 1:
            return parts[0]
        stems, sources = [Path(p.source).stem for p in parts], [p.source for p in parts]
        labels = stems if len(set(stems)) == len(stems) else sources if len(set(sources)) == len(sources) else \
            [f"session {i + 1}" for i in range(len(parts))]
        parts = [p if p.session is not None else p.in_session(label) for p, label in zip(parts, labels)]
        cameras.check_parts(parts, config, nominal)
        return concatenate(parts)
    if isinstance(data, Measurements):
        if data.n_joints != nominal.n_joints:
            raise InputError(f"data have {data.n_joints} joints, the robot has {nominal.n_joints}", source=data.source)
        return data
    return load_measurements(data, **config.read_options(nominal, columns))


def load_inputs(robot, data, validate, config: CalibrationConfig, columns=None) -> Inputs:
    """Step 1: the nominal robot and the measurements, position-only when asked, checked; the
    frames mode (``auto`` decides here, and says what it decided, in the inputs' notes)."""
    notes: list[str] = []
    nominal = load_robot(robot)
    if nominal.residual is not None:  # a calibration learns its own correction from what its fit leaves
        notes.append(Note(f"the residual model of {nominal.source or nominal.name} is not used as a starting point: a "
                          "calibration fits its own (with --model residual or auto)"))
        nominal = nominal.replace(residual=None)
    if nominal.region is not None:  # a new calibration finds its own
        nominal = nominal.replace(region=None)
    _check_prior(nominal, config)
    meas = _tree_rows(_measurements(data, nominal, config, columns), nominal)
    val = None if validate is None else _tree_rows(_measurements(validate, nominal, config, columns), nominal)
    if val is not None and meas.session is not None and val.session is None:  # one more session
        val = val.in_session("validation")
    if not (meas.full_pose and config.use_orientation):
        meas = meas.position_only()
        val = None if val is None else val.position_only()
    if config.point_distance:  # stated here; measurements given as objects may carry their own
        meas = meas.with_distances(config.point_distance, config.distance_sigma)
        if val is not None and val.constraints is not None:
            val = val.with_distances(config.point_distance, config.distance_sigma)
    nominal, meas, said = cameras.attach(nominal, meas, config)
    notes += said
    covered = cameras.coverage_note(meas)
    notes += [] if covered is None else [covered]
    if val is not None and val.camera is not None and any(val.camera):  # the same cameras and markers, seen again
        val = replace(val, intrinsics=meas.intrinsics)
        cameras.check_pixels(val, meas.intrinsics)
        cameras.check_markers(val, set(meas.target_names) | set(nominal.targets), "no calibration row")
    if nominal.tree is not None:  # parameters are numbered by the tree's joints: say which is which
        notes.append(Note(f"a tree of {len(nominal.tree.chains)} chains; its joints, as the parameters number "
                          f"them (x14 is joint 14's): {nominal.tree.describe(nominal.joint_names)}"))
    meas = _instrument_sigmas(meas, config, notes)
    meas = _excluded(meas, config.exclude, notes)
    if config.payload is not None:  # a stated payload where the files have no column
        meas = meas if meas.payload is not None else replace(meas, payload=np.full(meas.n_poses, config.payload))
        if val is not None and val.payload is None:
            val = replace(val, payload=np.full(val.n_poses, config.payload))
    frames = config.frames
    # the rows a tracker measured (neither contact nor camera rows)
    tracker = meas if meas.constraints is None else meas.subset(~meas.constraints.rows)
    tracker = tracker.subset(tracker.length_rows)
    if meas.views is not None and not tracker.n_poses:
        frames, said = cameras.frames_of(frames, nominal, meas)
        notes += said
    elif meas.constraints is not None:
        frames, said = _contact_frames(frames, meas)
        notes += said
    elif frames in ("auto", "none") and len(tracker.sessions) >= 2:  # each session's own frames judged
        frames, said = _session_frames_choice(frames, nominal, tracker)
        notes += said
    elif frames in ("auto", "none"):
        choice = choose_frames(nominal, tracker)
        if frames == "auto" and choice.mode != "none":  # it changed what is calibrated: say so
            notes.append(Note(f"frames auto: {choice.sentence()}"))
        elif frames == "none" and choice.mode != "none":
            notes.append(f"frames none, but {choice.sentence()}: calibrate with frames auto or {choice.mode}")
        frames = choice.mode if frames == "auto" else "none"
    if meas.views is not None and tracker.n_poses:  # beside the tracker's rows: its frame, the markers
        frames, said = cameras.frames_of(frames, nominal, meas)
        notes += said
    if tracker.n_poses:
        checks.check_targets(nominal, tracker, frames)
        checks.check_validation_targets(nominal, tracker, val)
        if config.length_unit is None:  # a stated unit overrides the spread check
            checks.check_units(nominal, tracker, frames)
    apart = frames in ("base", "base+tool") and len(meas.sessions) >= 2 and meas.views is None \
        and meas.constraints is None
    if apart:
        meas, said = session_frames(meas, frames)
        notes += said
    return Inputs(nominal, meas, val, frames, tuple(notes + checks.degeneracy_warnings(nominal, meas)), apart)


def _session_frames_choice(frames: str, nominal: Robot, tracker: Measurements) -> tuple[str, list[str]]:
    """``auto`` (or ``none``) for tracker rows of several sessions: each session's frames judged on its
    own rows (one measuring frame across sessions whose instrument moved would be no answer), the
    richest mode any session needs taken for all."""
    modes = ("none", "base", "base+tool")
    labels = np.asarray(tracker.session, dtype=object)
    choices = {s: choose_frames(nominal, tracker.subset(labels == s)) for s in tracker.sessions}
    needed = max((c.mode for c in choices.values()), key=lambda m: modes.index(m) if m in modes else 0)
    if frames == "none":
        if needed == "none":
            return "none", []
        return "none", [f"frames none, but session {next(s for s, c in choices.items() if c.mode != 'none')}: "
                        f"{next(c for c in choices.values() if c.mode != 'none').sentence()}: calibrate with frames "
                        f"auto or {needed}"]
    if needed == "none":
        return "none", []
    worst = max(choices, key=lambda s: modes.index(choices[s].mode) if choices[s].mode in modes else 0)
    return needed, [Note(f"frames auto: session {worst}: {choices[worst].sentence()}; each session's frames are "
                         f"registered (frames {needed})")]


def _tree_rows(meas: Measurements, robot: Robot) -> Measurements:
    """A tree robot's rows: each names its chain (a ``chain`` column, one of the tree's), and a row
    without a target measured its chain's own tool (the target named after the chain)."""
    tree = robot.tree
    if tree is None:
        if meas.chain is not None:
            raise InputError(f"has a chain column, but {robot.source or robot.name} is a serial robot (a tree names "
                             "its chains: a URDF with several tips, or [chains] in a robot file)", source=meas.source)
        return meas
    if meas.chain is None:
        raise InputError(f"{robot.source or robot.name} is a tree of chains {', '.join(tree.chains)}: each row names "
                         "its chain (a chain column)", source=meas.source)
    for i, c in enumerate(meas.chain):
        if c not in tree.chains:
            raise InputError(f"chain {c!r} is not one of {', '.join(tree.chains)}", source=meas.source,
                             where=f"row {int(meas.rows[i])}")
    targets = meas.targets or ("",) * meas.n_poses
    return replace(meas, targets=tuple(t or c for t, c in zip(targets, meas.chain)))


def session_label(target: str, session: str) -> str:
    """The name a target takes in a session whose frames are its own (``m1@monday``)."""
    return f"{target}@{session}"


def session_frames(meas: Measurements, frames: str) -> tuple[Measurements, list[str]]:
    """Tracker rows of several sessions: each session's measuring frame (the instrument may have
    moved) and, with ``base+tool``, its tools (a reflector remounted) are its own, the geometry and
    joint terms shared.  The first session's frames keep their names (``base``, ``tool[m1]``); a later
    session's tool of target m1 is ``m1@LABEL`` (:func:`session_label`) and its base ``base[LABEL]``."""
    first = meas.sessions[0]
    if frames == "base+tool":
        targets = meas.targets or ("",) * meas.n_poses
        meas = replace(meas, targets=tuple(t if s == first else session_label(t, s)
                                           for t, s in zip(targets, meas.session)))
    others = ", ".join(meas.sessions[1:])
    what = "measuring frame and tools" if frames == "base+tool" else "measuring frame"
    return meas, [Note(f"sessions: each of the {len(meas.sessions)} sessions has its own {what} (the instrument "
                       f"{'and the reflectors ' if frames == 'base+tool' else ''}may have moved between them), the "
                       f"geometry is shared; {first}'s are the robot's, {others}'s are named with the session")]


def _check_prior(nominal: Robot, config: CalibrationConfig) -> None:
    """A prior that names a parameter the robot has not is an error: a typo would leave the
    parameter it meant at its default width, unsaid."""
    if config.prior is None:
        return
    names = [n for joint in joint_parameter_names(nominal.convention, nominal.geometry) for n in joint]
    if nominal.convention == "dh":  # β is offered on parallel axes
        names += [f"beta{i + 1}" for i in range(nominal.n_joints)]
    unknown = unknown_names(config.prior, names, nominal.n_joints)
    if unknown:
        raise InputError(f"names parameter {unknown[0]!r}, which this {nominal.convention} robot of "
                         f"{nominal.n_joints} joints has not (its geometry: {', '.join(names[:6])}, …)",
                         option="prior")


def _contact_frames(frames: str, meas: Measurements) -> tuple[str, list[str]]:
    """The frames of data whose rows touched unknown points or planes: those can stand anywhere,
    so they cannot see the base frame; the tool point they see.  Tracker rows beside them see
    the base as ever."""
    c = meas.constraints
    if c.only and frames in ("base", "base+tool"):
        raise InputError(f"the base frame is not observable from {meas.source}: its rows touched points or planes "
                         "whose place is unknown (use frames tcp, or auto)", option="frames")
    if frames != "auto":
        return frames, []
    if c.only:
        return "tcp", [Note("frames auto: the rows touched points or planes whose place is unknown, so the base "
                             "frame is not observable from them; the tool point is identified (frames tcp)")]
    return "base+tool", [Note("frames auto: tracker rows beside rows that touched points or planes: base and tool are "
                              "identified (frames base+tool)")]


def _excluded(meas: Measurements, exclude: tuple[str, ...], notes: list[str]) -> Measurements:
    """The measurements without the poses ``exclude`` names (pose ids, or ``row N``); a name the
    data do not have is an error (a typo would otherwise leave a bad pose in)."""
    if not exclude:
        return meas
    ids = [meas.pose_ids[i] if meas.pose_ids is not None else f"row {int(meas.rows[i])}" for i in range(meas.n_poses)]
    unknown = [e for e in exclude if e not in set(ids)]
    if unknown:
        what = "pose_id" if meas.pose_ids is not None else "row (written 'row N')"
        raise InputError(f"excluded pose {unknown[0]!r} is not in the data (no such {what})", source=meas.source,
                         option="exclude")
    keep = [i for i, x in enumerate(ids) if x not in set(exclude)]
    if not keep:
        raise InputError(f"leaves none of the {meas.n_poses} poses to calibrate on", source=meas.source,
                         option="exclude")
    notes.append(Note(f"{meas.n_poses - len(keep)} pose(s) left out as asked (--exclude): {', '.join(exclude[:10])}"
                      + (" …" if len(exclude) > 10 else "")))
    return meas.subset(keep)


def _instrument_sigmas(meas: Measurements, config: CalibrationConfig, notes: list[str]) -> Measurements:
    """The instrument's σ per point the fit weighs by: the file's columns, or the statement of
    ``instrument``; a stated noise σ of a block replaces its columns (and says so)."""
    if config.instrument is not None:
        statement = Instrument.parse(config.instrument)
        if meas.sigma_position is not None:
            notes.append(Note(f"the sx, sy, sz columns of {meas.source} are replaced by {statement.sentence()}"))
        return replace(with_instrument(meas, statement), sigma_source=statement.sentence(),
                       sigma_orientation=meas.sigma_orientation)
    for block, stated, columns in (("sigma_position", config.noise, "sx, sy, sz"),
                                   ("sigma_orientation", config.angle_noise if config.k is None else 0.0,
                                    "srx, sry, srz")):
        if stated is not None and getattr(meas, block) is not None:
            notes.append(Note(f"the noise stated replaces the {columns} columns of {meas.source}"))
            meas = replace(meas, **{block: None})
    return meas
