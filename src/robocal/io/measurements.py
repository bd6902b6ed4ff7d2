"""Measurement files (CSV, MODEL §5): joint values and measured poses.

Columns: ``q1 … qn`` (deg; mm for a prismatic joint), ``x, y, z`` (mm), optionally ``rx, ry, rz`` (deg, rpy with
``R = Rz(rz) Ry(ry) Rx(rx)``) for full-pose data, ``pose_id`` (rows sharing one are one pose: its
reflectors, and repeated measurements of each, which are averaged), ``target`` (which point on
the flange), ``cycle`` (repeated measuring cycles of a pose_id: each cycle is its own
measurement, with its own joint read-back) and ``session`` (any label: the rows measured in one
session, between which the instrument, the markers or the cameras may have been moved;
cross-validation then holds out whole sessions).  Positions and orientations are in the measuring
device's frame.
"""

from __future__ import annotations

import csv
import io
import math
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from .. import options as opt
from ..exceptions import InputError
from ..math.so3 import matrix_to_rpy, project_to_so3, rpy_to_matrix
from ..model import coupled as coupled_
from ..model.measurements import Measurements
from .atomic import atomic_write, read_text
from .table import DECIMALS, DELIMITERS, CsvTable, numbers, read_csv, strings

POSITION = ("x", "y", "z")
ORIENTATION = ("rx", "ry", "rz")
OPTIONAL = ("pose_id", "target", "payload", "cycle", "time", "temperature", "session", "chain")
#: rows without a measured position: the tool point touched an unknown point or plane, one of a setup's
CONSTRAINT = ("point", "plane", "setup")
#: rows a camera saw: the pixel (px) where the camera named saw the marker named (a target on the tool)
CAMERA = ("u", "v", "camera", "marker")
#: the instrument's standard deviation of each measured value: mm, and deg about the measuring frame's axes
POSITION_SIGMA = ("sx", "sy", "sz")
ORIENTATION_SIGMA = ("srx", "sry", "srz")
_JOINT = re.compile(r"^q(\d+)$")
_TORQUE = re.compile(r"^tau(\d+)$")
_DIRECTION = re.compile(r"^dir(\d+)$")

#: repeated rows of one pose_id that spread further than this (mm) are an error
REPEAT_TOLERANCE_MM = 1.0
#: largest magnitudes a measurement file may hold, in its units: a hundred turns of a joint,
#: ten kilometres, and torques and payloads no robot sees; beyond them a value is a typo or garbage
MAX_JOINT_DEG, MAX_LENGTH_MM, MAX_TORQUE_NM, MAX_PAYLOAD_KG = 36_000.0, 1e7, 1e7, 1e5
#: a campaign's time stamps (s; a century, epoch seconds of this one fit) and temperatures (°C)
MAX_TIME_S, MAX_TEMPERATURE_C = 1e10, 1000.0
#: rows of one pose_id (and cycle) whose joints differ by more than this (deg) are not one pose: a
#: repeated commanded pose reads back within a few thousandths of a degree
JOINT_TOLERANCE_DEG = 0.05


@dataclass
class PoseTable:
    """The validated numeric content of a measurement-style CSV (deg and mm as in the file)."""

    q: np.ndarray | None
    position: np.ndarray | None
    rpy: np.ndarray | None
    pose_ids: list[str] | None
    targets: list[str] | None
    rows: np.ndarray
    torques: np.ndarray | None = None
    payload: np.ndarray | None = None
    cycles: list[str] | None = None
    directions: np.ndarray | None = None
    time: np.ndarray | None = None
    temperature: np.ndarray | None = None
    sigma_position: np.ndarray | None = None
    sigma_orientation: np.ndarray | None = None
    point: list[str] | None = None
    plane: list[str] | None = None
    setup: list[str] | None = None
    camera: list[str] | None = None
    pixels: np.ndarray | None = None
    session: list[str] | None = None
    chain: list[str] | None = None


def _per_joint_columns(table: CsvTable, n_joints: int, pattern: re.Pattern, what: str) -> list[str] | None:
    """Columns NAME1..NAMEN (one per joint, all or none), e.g. tau1..tauN."""
    found = sorted((int(m.group(1)), h) for h in table.header if (m := pattern.match(h)))
    if not found:
        return None
    if [k for k, _ in found] != list(range(1, n_joints + 1)):
        have = ", ".join(h for _, h in found)
        stem = pattern.pattern[1:].split("(")[0]
        raise InputError(f"{what} columns come as {stem}1..{stem}{n_joints}, one per joint; the file has {have}",
                         source=table.source)
    return [h for _, h in found]


def _torque_columns(table: CsvTable, n_joints: int) -> list[str] | None:
    """tau1..tauN (N·m), all or none, matching the joints."""
    return _per_joint_columns(table, n_joints, _TORQUE, "torque")


def _directions(table: CsvTable, n_joints: int) -> np.ndarray | None:
    """dir1..dirN: the sign of each joint's move into the pose, +1, −1 or 0 (unknown)."""
    cols = _per_joint_columns(table, n_joints, _DIRECTION, "direction")
    if cols is None:
        return None
    values = numbers(table, cols)
    bad = ~np.isin(values, (-1.0, 0.0, 1.0))
    if bad.any():
        r, j = np.unravel_index(int(np.argmax(bad)), values.shape)
        raise InputError(f"{values[r, j]:g} is not a direction (expected +1, −1 or 0 for unknown)",
                         source=table.source, where=f"row {int(table.lines[r])}, column '{cols[j]}'")
    return values


def _joint_columns(table: CsvTable, n_joints: int | None, required: bool, robot_label: str,
                   n_coupled: int = 0) -> list[str]:
    joints = sorted((int(m.group(1)), h) for h in table.header if (m := _JOINT.match(h)))
    if not joints and required:
        raise InputError("no joint columns (q1, q2, …)", source=table.source)
    numbers_ = [k for k, _ in joints]
    if numbers_ and numbers_ != list(range(1, len(numbers_) + 1)):
        # a q0 (numbered from 0) or the same joint twice (q1 and q01) leaves no gap to name
        if numbers_[0] == 0:
            raise InputError(f"joint column '{joints[0][1]}': joints are numbered from 1 (q1, q2, …)",
                             source=table.source)
        twice = next(((a, b) for (k, a), (m, b) in zip(joints, joints[1:]) if k == m), None)
        if twice is not None:
            raise InputError(f"joint columns '{twice[0]}' and '{twice[1]}' name the same joint", source=table.source)
        missing = sorted(set(range(1, max(numbers_) + 1)) - set(numbers_))
        raise InputError(f"joint column 'q{missing[0]}' is missing", source=table.source)
    if numbers_ and n_joints is not None and len(numbers_) not in (n_joints, n_joints - n_coupled):
        robot = f" ({Path(robot_label).name})" if robot_label else ""
        hint = ("; a URDF's joints are those of the chain between `base_link` and `tip_link`: check that chain"
                if robot_label.lower().endswith(".urdf") else "")
        free = f" ({n_joints - n_coupled} free, the {n_coupled} coupled ones computed)" if n_coupled else ""
        raise InputError(f"file has {len(numbers_)} joint columns (q1..q{len(numbers_)}) but the robot{robot} "
                         f"has {n_joints} joints{free}{hint}", source=table.source)
    return [h for _, h in joints]


def _pose_columns(table: CsvTable, has_joints: bool, require_position: bool) -> tuple[bool, bool]:
    """Whether the file has a position and an orientation; checks they come complete."""
    have_pos = [c in table for c in POSITION]
    if require_position or any(have_pos):
        table.require(POSITION)
    elif not has_joints:
        raise InputError("needs joint columns (q1..qn) or a position (x, y, z)", source=table.source)
    have_rot = table.together(ORIENTATION, "orientation")
    if have_rot and not all(have_pos):
        raise InputError("orientation columns rx, ry, rz need x, y, z too", source=table.source)
    return all(have_pos), have_rot


#: units a file may state instead of robocal's degrees and millimetres
JOINT_UNITS = ("deg", "rad")
LENGTH_UNITS = ("mm", "m")


@dataclass(frozen=True)
class ReadOptions:
    """How to read a measurement-style file.

    n_joints: the robot's joint count, checked against the q-columns; robot_label names the
    robot in that message.  columns: file column → robocal column (``{"A1": "q1"}``).
    joint_unit / length_unit: ``deg``/``rad`` and ``mm``/``m`` as the file has them; None
    means robocal's degrees and millimetres, with a check that rejects joints that all look
    like radians.  prismatic: per joint, True where it slides: its column holds a length (mm,
    or the length unit), not an angle.  delimiter (``,``, ``;``, ``tab``, ``space``) and
    decimal (``.``, ``,``): how the file writes its cells.  euler: the sequence of the
    orientation angles rx, ry, rz in scipy's notation (upper case intrinsic, ``XYZ``: about x,
    then the new y, then the new z; lower case extrinsic); default robocal's own, ``xyz``
    (R = Rz(rz) Ry(ry) Rx(rx)).  With a column mapping, columns robocal does not use are
    ignored (and listed in a note); without one an unknown column is an error (it catches typos).
    """

    n_joints: int | None = None
    columns: Mapping[str, str] | None = None
    joint_unit: str | None = None
    length_unit: str | None = None
    robot_label: str = ""
    prismatic: tuple[bool, ...] | None = None
    delimiter: str = ","
    decimal: str = "."
    euler: str = "xyz"
    #: the robot's chains: a tree's names, each row naming one in a chain column; () a serial robot's
    #: (no chain column); None: not known (a chain column read as it is)
    chains: tuple[str, ...] | None = None
    #: the robot's coupled joints (:class:`robocal.model.coupled.CoupledJoint` as (joint, sources,
    #: factors, offset) tuples): a file gives every joint or only the free ones
    coupled: tuple = ()
    #: the robot's joint limits ((low, high) per joint, rad; mm where a joint slides), for the unit check
    limits: tuple | None = None

    def __post_init__(self) -> None:
        if self.joint_unit is not None:
            opt.choice(self.joint_unit, JOINT_UNITS, "joint_unit", "joint unit")
        if self.length_unit is not None:
            opt.choice(self.length_unit, LENGTH_UNITS, "length_unit", "length unit")
        opt.choice(self.delimiter, tuple(DELIMITERS), "delimiter", "cell separator")
        opt.choice(self.decimal, DECIMALS, "decimal", "decimal mark")
        if not (isinstance(self.euler, str) and re.fullmatch(r"[XYZ]{3}|[xyz]{3}", self.euler)
                and all(self.euler[i] != self.euler[i + 1] for i in range(2))):
            raise InputError(f"expected three axes, upper case intrinsic (XYZ, ZYX, ZYZ, …) or lower case extrinsic "
                             f"(xyz, …), no axis twice in a row; got {self.euler!r}", option="euler")


def robot_fields(robot) -> dict:
    """What reading a file takes from the robot it is for: its joints (sliding, coupled), its chains,
    its name for messages (the keywords of :class:`ReadOptions`)."""
    slide = tuple(bool(p) for p in robot.prismatic)
    return dict(n_joints=robot.n_joints, robot_label=robot.source, prismatic=slide if any(slide) else None,
                chains=() if robot.tree is None else robot.tree.names,
                coupled=tuple((c.joint, c.sources, c.factors, c.offset) for c in robot.coupled),
                limits=tuple((float(lo), float(hi)) for lo, hi in robot.limits))


def euler_rotation(angles_deg: np.ndarray, sequence: str = "xyz") -> np.ndarray:
    """Rotations (m, 3, 3) of the angles rx, ry, rz (deg) in an Euler sequence (scipy's notation)."""
    if sequence == "xyz":  # robocal's own rpy, exactly as everywhere else
        return rpy_to_matrix(np.radians(angles_deg))
    from scipy.spatial.transform import Rotation

    return Rotation.from_euler(sequence, angles_deg, degrees=True).as_matrix()


def euler_sigma(angles_deg: np.ndarray, sigma_deg: np.ndarray, sequence: str, step: float = 1e-4) -> np.ndarray:
    """σ (m, 3) deg of an orientation as a rotation vector about the measuring frame's axes, from
    the σ of its Euler angles: δω = E δφ, E's columns the rotation vectors of a small change
    of each angle, Σ_ω = E diag(σ²) Eᵀ, taken per axis."""
    from scipy.spatial.transform import Rotation

    R0 = Rotation.from_euler(sequence, angles_deg, degrees=True)
    E = np.stack([(Rotation.from_euler(sequence, angles_deg + step * np.eye(3)[k], degrees=True) * R0.inv()).as_rotvec()
                  / np.radians(step) for k in range(3)], axis=-1)
    return np.sqrt(np.einsum("mik,mk,mik->mi", E, np.asarray(sigma_deg, float) ** 2, E))


def _without(table: CsvTable, drop: list[str]) -> CsvTable:
    """The table without the columns ``drop`` (kept in ``ignored``, for the note that lists them)."""
    from dataclasses import replace as _replace

    keep = [i for i, h in enumerate(table.header) if h not in drop]
    return _replace(table, header=tuple(table.header[i] for i in keep),
                    rows=tuple(tuple(r[i] for i in keep) for r in table.rows), ignored=tuple(drop))


def read_pose_table(text: str, *, source: str, options: ReadOptions = ReadOptions(), require_joints: bool = True,
                    require_position: bool = True) -> PoseTable:
    """Read and validate a CSV with columns q1..qn, x, y, z, rx, ry, rz, pose_id, target.

    Joints come back in degrees (prismatic ones in mm) and lengths in mm, whatever units the
    options state.
    """
    known = set(POSITION) | set(ORIENTATION) | set(OPTIONAL) | set(POSITION_SIGMA) | set(ORIENTATION_SIGMA) | \
        set(CONSTRAINT) | set(CAMERA)
    for old, new in (options.columns or {}).items():  # a name robocal does not read would be dropped unseen
        if new not in known and not any(p.match(new) for p in (_JOINT, _TORQUE, _DIRECTION)):
            raise InputError(f"{old}={new}: '{new}' is not a column robocal reads (expected q1..qn, x, y, z, rx, ry, "
                             f"rz, sx, sy, sz, srx, sry, srz, {', '.join(OPTIONAL + CONSTRAINT + CAMERA)}, tau1..taun, "
                             "dir1..dirn)",
                             option="column")
    table = read_csv(text, source=source, columns=options.columns, delimiter=options.delimiter,
                     decimal=options.decimal)
    unused = [h for h in table.header if h not in known and not any(p.match(h) for p in (_JOINT, _TORQUE, _DIRECTION))]
    if unused and options.columns:  # a mapped export: what it does not map is not robocal's
        import warnings

        from ..exceptions import RobocalWarning

        table = _without(table, unused)
        warnings.warn(f"{source}: {len(unused)} column(s) not used by robocal were ignored: {', '.join(unused)}",
                      RobocalWarning, stacklevel=2)
    for h in table.header:
        if h not in known and not any(p.match(h) for p in (_JOINT, _TORQUE, _DIRECTION)):
            raise InputError(f"unknown column '{h}' (expected q1..qn, x, y, z, optional rx, ry, rz, pose_id, "
                             "target, cycle, session, chain, tau1..taun, payload, dir1..dirn, time, temperature, sx, "
                             "sy, sz, "
                             "srx, sry, srz, point, plane, setup, u, v, camera, marker; map other names with a column "
                             "mapping)",
                             source=source)
    qcols = _joint_columns(table, options.n_joints, require_joints, options.robot_label, len(options.coupled))
    coupled = [coupled_.CoupledJoint(*c) for c in options.coupled]
    short = bool(coupled and qcols) and len(qcols) == options.n_joints - len(coupled)
    full_options = options
    if short:  # the free joints' columns: their own units, the coupled ones filled in below
        if any(c in table for c in table.header if _TORQUE.match(c) or _DIRECTION.match(c)):
            raise InputError("torque or direction columns with the coupled joints left out: give every joint's "
                             f"q1..q{options.n_joints}", source=source)
        if options.prismatic is not None:
            options = replace(options, prismatic=tuple(np.array(options.prismatic)[coupled_.free(coupled,
                                                                                               options.n_joints)]))
    labels = _constraint_labels(table) if require_position else None
    touched = None if labels is None else np.array([bool(a or b) for a, b in zip(labels[0], labels[1])])
    if not require_position and any(c in table for c in CAMERA):
        raise InputError(f"column '{next(c for c in CAMERA if c in table)}' belongs to camera rows of a measurement "
                         "file, not here", source=source)
    seen = _camera_labels(table) if require_position else None
    if seen is not None:
        for i, (cam, label) in enumerate(zip(seen, labels[0] if labels else [""] * len(seen))):
            if cam and (label or (labels and labels[1][i])):
                raise InputError(f"was seen by camera {cam!r} and touched a point or plane: a row is one or the other",
                                 source=source, where=f"row {int(table.lines[i])}")
        cams = np.array([bool(c) for c in seen])
        touched = cams if touched is None else touched | cams
    has_pos, has_rot = _pose_columns(table, bool(qcols), require_position and labels is None and seen is None)
    if touched is not None:
        if has_rot:
            import warnings

            from ..exceptions import RobocalWarning

            if seen is not None:
                raise InputError("rows a camera saw have no orientation: give rx, ry, rz rows in another file",
                                 source=source)
            warnings.warn(f"{source}: rows that touched a point or plane have no orientation: rx, ry, rz are left "
                          "out, and the data are read as positions", RobocalWarning, stacklevel=2)
            has_rot = False
        if any(h in table for h in POSITION_SIGMA + ORIENTATION_SIGMA):
            raise InputError("σ columns (sx..srz) with point or plane rows are not read: state the tracker's and "
                             "the contacts' σ with --noise, or give the rows in two files", source=source)
        if not has_pos and not touched.all():
            row = int(table.lines[int(np.argmin(touched))])
            what = "a camera, " if seen is not None else ""
            raise InputError(f"has neither {what}a point or plane label nor x, y, z", source=source, where=f"row {row}")
    for names, present, what in ((POSITION_SIGMA, has_pos, "x, y, z"), (ORIENTATION_SIGMA, has_rot, "rx, ry, rz")):
        if not present and any(h in table for h in names):
            raise InputError(f"σ columns {', '.join(names)} without the {what} columns they are the σ of",
                             source=source)
    scale = 1000.0 if options.length_unit == "m" else 1.0
    q = numbers(table, qcols) if qcols else None
    if q is not None:
        _check_joint_magnitudes(table, q, qcols, options, scale)
    if q is not None:
        slide = np.zeros(q.shape[1], bool) if options.prismatic is None else np.array(options.prismatic, bool)
        turn = q[:, ~slide]
        if options.joint_unit == "rad":
            q[:, ~slide] = np.degrees(turn)
        elif options.joint_unit is None and len(q) >= 3 and turn.size and 0 < np.abs(turn).max() <= math.pi + 1e-9:
            raise InputError("all joint values lie within ±π: they look like radians; files give joints in degrees "
                             "(state the joint unit with `joint_unit` rad if they are)", source=source)
        _check_unit_against_limits(table, q, slide, options)
        q[:, slide] *= scale
        if coupled:
            q = _coupled_joints(table, q, coupled, full_options, short)
    taus = _torque_columns(table, len(qcols)) if qcols else None
    payload = numbers(table, ["payload"], MAX_PAYLOAD_KG, "kg")[:, 0] if "payload" in table else None
    if payload is not None and np.any(payload < 0):
        row = int(table.lines[int(np.argmax(payload < 0))])
        raise InputError("payload must be ≥ 0 kg", source=source, where=f"row {row}, column 'payload'")
    if touched is not None:
        position = np.full((len(table.rows), 3), np.nan)
        if has_pos:
            position[~touched] = scale * _tracker_positions(table, touched, MAX_LENGTH_MM / scale,
                                                             "m" if scale != 1 else "mm")
    else:
        position = scale * numbers(table, POSITION, MAX_LENGTH_MM / scale, "m" if scale != 1 else "mm") \
            if has_pos else None
    return PoseTable(
        q=q,
        position=position,
        rpy=numbers(table, ORIENTATION, MAX_JOINT_DEG, "deg") if has_rot else None,
        pose_ids=strings(table, "pose_id", required=True) if "pose_id" in table else None,
        targets=_targets(table),
        rows=table.lines,
        torques=numbers(table, taus, MAX_TORQUE_NM, "N·m") if taus else None,
        payload=payload,
        cycles=strings(table, "cycle", required=True) if "cycle" in table else None,
        session=strings(table, "session", required=True) if "session" in table else None,
        chain=_chains(table, options, source),
        directions=_directions(table, len(qcols)) if qcols else None,
        time=numbers(table, ["time"], MAX_TIME_S, "s")[:, 0] if "time" in table else None,
        temperature=numbers(table, ["temperature"], MAX_TEMPERATURE_C, "°C")[:, 0] if "temperature" in table else None,
        sigma_position=_sigmas(table, POSITION_SIGMA, scale, "m" if scale != 1 else "mm") if has_pos else None,
        sigma_orientation=_sigmas(table, ORIENTATION_SIGMA, 1.0, "deg") if has_rot else None,
        point=None if labels is None or "point" not in table else labels[0],
        plane=None if labels is None or "plane" not in table else labels[1],
        setup=None if labels is None or "setup" not in table else labels[2],
        camera=seen,
        pixels=None if seen is None else _pixels(table, np.array([bool(c) for c in seen])),
    )


def _targets(table: CsvTable) -> list[str] | None:
    """Each row's target: its marker where a camera saw it, else its target column."""
    target = strings(table, "target") if "target" in table else None
    if "marker" not in table:
        return target
    marker = strings(table, "marker")
    return [m or (target[i] if target else "") for i, m in enumerate(marker)]


def _camera_labels(table: CsvTable) -> list[str] | None:
    """The camera that saw each row ("" where none), or None: no camera column.  A camera row
    names its marker (or target) and gives u, v; the marker is the row's target."""
    if "camera" not in table:
        for c in ("u", "v", "marker"):
            if c in table:
                raise InputError(f"a {c} column belongs to rows a camera saw: it needs a camera column",
                                 source=table.source)
        return None
    table.require(("u", "v"))
    seen = strings(table, "camera")
    marker = strings(table, "marker") if "marker" in table else strings(table, "target") if "target" in table \
        else None
    for i, cam in enumerate(seen):
        if cam and (marker is None or not marker[i]):
            raise InputError(f"was seen by camera {cam!r} but names no marker (a marker column, or target)",
                             source=table.source, where=f"row {int(table.lines[i])}")
    return seen


def _pixels(table: CsvTable, seen: np.ndarray) -> np.ndarray:
    """u, v (px) of the rows a camera saw (NaN elsewhere; those must leave them empty)."""
    from dataclasses import replace as _replace

    idx = table.index
    for r in np.flatnonzero(~seen):
        filled = [c for c in ("u", "v") if table.rows[r][idx[c]].strip()]
        if filled:
            raise InputError(f"has a pixel {filled[0]} but no camera", source=table.source,
                             where=f"row {int(table.lines[r])}")
    out = np.full((len(table.rows), 2), np.nan)
    keep = np.flatnonzero(seen)
    sub = _replace(table, rows=tuple(table.rows[i] for i in keep), lines=table.lines[keep])
    out[keep] = numbers(sub, ("u", "v"), 1e7, "px")
    return out


def _constraint_labels(table: CsvTable) -> tuple[list[str], list[str], list[str]] | None:
    """The point, plane and setup label of each row ("" where none), or None: no point or plane
    column.  A row touches a point or a plane, not both; a setup names the artefact's placement."""
    if "point" not in table and "plane" not in table:
        if "setup" in table:
            raise InputError("a setup column numbers the placements of the points or planes the rows touched: it "
                             "needs a point or plane column", source=table.source)
        return None
    m = len(table.rows)
    point = strings(table, "point") if "point" in table else [""] * m
    plane = strings(table, "plane") if "plane" in table else [""] * m
    setup = strings(table, "setup") if "setup" in table else [""] * m
    for i, (a, b) in enumerate(zip(point, plane)):
        if a and b:
            raise InputError(f"touches point {a!r} and plane {b!r}: a row touches one", source=table.source,
                             where=f"row {int(table.lines[i])}")
    return point, plane, setup


def _tracker_positions(table: CsvTable, touched: np.ndarray, limit: float, unit: str) -> np.ndarray:
    """x, y, z of the rows that did not touch a point or plane (a tracker's); the others must
    leave them empty (a row is one or the other)."""
    idx = table.index
    for r in np.flatnonzero(touched):
        filled = [c for c in POSITION if table.rows[r][idx[c]].strip()]
        if filled:
            raise InputError(f"touches a point or plane and has a measured {filled[0]}: a row is a contact (x, y, z "
                             "empty) or a tracker row (no label)", source=table.source,
                             where=f"row {int(table.lines[r])}")
    from dataclasses import replace as _replace

    keep = np.flatnonzero(~touched)
    sub = _replace(table, rows=tuple(table.rows[i] for i in keep), lines=table.lines[keep])
    return numbers(sub, POSITION, limit, unit)


def _sigmas(table: CsvTable, names: tuple[str, ...], scale: float, unit: str) -> np.ndarray | None:
    """The instrument's σ columns of one block (all three or none), each > 0; in mm or deg."""
    present = [h for h in names if h in table]
    if not present:
        return None
    if len(present) != len(names):
        missing = next(h for h in names if h not in table)
        raise InputError(f"σ columns come as {', '.join(names)}, all three; '{missing}' is missing",
                         source=table.source)
    values = numbers(table, list(names), MAX_LENGTH_MM / scale, unit)
    bad = ~(values > 0)
    if bad.any():
        r, j = np.unravel_index(int(np.argmax(bad)), values.shape)
        raise InputError(f"a standard deviation must be > 0, got {values[r, j]:g}", source=table.source,
                         where=f"row {int(table.lines[r])}, column '{names[j]}'")
    return scale * values


def _chains(table: CsvTable, options: ReadOptions, source: str) -> list[str] | None:
    """Each row's chain, one of the tree robot's (before rows of one pose are grouped: two arms'
    rows of a pose are two measurements, not repeats of one)."""
    robot = options.robot_label or "the robot"
    if options.chains is None:
        return strings(table, "chain", required=True) if "chain" in table else None
    if not options.chains:
        if "chain" in table:
            raise InputError(f"has a chain column, but {robot} is a serial robot (a tree names its chains: a URDF "
                             "with several tips, or [chains] in a robot file)", source=source)
        return None
    if "chain" not in table:
        raise InputError(f"{robot} is a tree of chains {', '.join(options.chains)}: each row names its chain (a chain "
                         "column)", source=source)
    chain = strings(table, "chain", required=True)
    for line, c in zip(table.lines, chain):
        if c not in options.chains:
            raise InputError(f"chain {c!r} is not one of {', '.join(options.chains)}", source=source,
                             where=f"row {int(line)}, column 'chain'")
    return chain


#: a campaign's joint values, read in degrees, that all lie within this (deg) are radians read as degrees
RADIAN_LIKE_DEG = 2 * math.pi + 1e-9
#: a joint whose limits span more than this (deg) would be moved further than RADIAN_LIKE_DEG by any campaign
ROOMY_JOINT_DEG = 90.0


def _check_unit_against_limits(table: CsvTable, q: np.ndarray, slide: np.ndarray, options: ReadOptions) -> None:
    """Joint values (deg as read) in the wrong unit, told by the robot's limits (one line naming the joint
    unit): radians read as degrees (every value within ±2π "degrees" where the joints' limits span far
    more), degrees read as radians (most rows beyond the limits, every one within them as degrees)."""
    if options.limits is None or len(q) < 5 or options.n_joints is None or q.shape[1] != options.n_joints:
        return
    turn = ~slide
    lim = np.degrees(np.array(options.limits, float))[turn]
    values = q[:, turn]
    if not values.size:
        return
    roomy = np.isfinite(lim).all(axis=1) & (lim[:, 1] - lim[:, 0] > ROOMY_JOINT_DEG)
    if options.joint_unit is None and roomy.any() and np.abs(values).max() <= RADIAN_LIKE_DEG:
        raise InputError(f"every joint value lies within ±{RADIAN_LIKE_DEG:.4f}, where the robot's joints turn "
                         f"through {np.max(lim[roomy, 1] - lim[roomy, 0]):.0f}°: they look like radians read as "
                         "degrees; state the joint unit (`joint_unit` rad, or deg where a campaign really keeps "
                         "every joint that near zero)", source=table.source)
    if options.joint_unit == "rad":
        margin = 5.0  # deg: a pose taught at a limit, read back a little beyond it
        beyond = np.any((values < lim[:, 0] - margin) | (values > lim[:, 1] + margin), axis=1)
        written = np.radians(values)  # the numbers as the file has them, read as degrees
        fits = np.all((written >= lim[:, 0] - margin) & (written <= lim[:, 1] + margin), axis=1)
        if beyond.mean() > 0.5 and fits.mean() > 0.95:
            raise InputError(f"{int(beyond.sum())} of {len(values)} rows lie beyond the robot's joint limits read as "
                             "radians, and every one within them read as degrees: they look like degrees; leave "
                             "`joint_unit` rad out", source=table.source)


def _coupled_joints(table: CsvTable, q: np.ndarray, coupled, options: ReadOptions, short: bool) -> np.ndarray:
    """Every joint's values (deg; mm where it slides): the coupled ones computed from the free joints' where the
    file leaves them out; where it gives them, its own (a coupled joint's encoder), and a row that strays
    from its coupling is said."""
    n = options.n_joints
    slide = np.zeros(n, bool) if options.prismatic is None else np.array(options.prismatic, bool)
    unit = np.where(slide, 1.0, 180.0 / math.pi)  # an offset is stored in rad (mm)
    if short:
        return coupled_.expand(coupled, q, n, unit)
    for joint, row, d in coupled_.strays(coupled, q, unit):
        import warnings

        from ..exceptions import RobocalWarning

        c = next(c for c in coupled if c.joint == joint)
        warnings.warn(f"{table.source}: q{joint + 1} strays from its coupling ({c.describe()}) by up to "
                      f"{d:.4g}{' mm' if slide[joint] else '°'} (row {int(table.lines[row])}): the file's values are "
                      "used", RobocalWarning, stacklevel=3)
    return q


def _check_joint_magnitudes(table: CsvTable, q: np.ndarray, columns: list[str], options: ReadOptions,
                            scale: float) -> None:
    """Turning joints within ±MAX_JOINT_DEG (in radians when the file says so), sliding ones
    within MAX_LENGTH_MM."""
    slide = np.zeros(q.shape[1], bool) if options.prismatic is None else np.array(options.prismatic, bool)
    turn_limit = np.radians(MAX_JOINT_DEG) if options.joint_unit == "rad" else MAX_JOINT_DEG
    limit = np.where(slide, MAX_LENGTH_MM / scale, turn_limit)
    bad = np.abs(q) > limit
    if bad.any():
        r, j = np.unravel_index(int(np.argmax(bad)), q.shape)
        unit = ("m" if scale != 1 else "mm") if slide[j] else (options.joint_unit or "deg")
        raise InputError(f"{q[r, j]:.6g} is not a plausible joint value (beyond ±{limit[j]:g} {unit})",
                         source=table.source, where=f"row {int(table.lines[r])}, column '{columns[j]}'")


def parse_measurements(text: str, *, source: str = "<data>", average: bool = True,
                       repeat_tolerance: float = REPEAT_TOLERANCE_MM, **options) -> Measurements:
    """Parse CSV text; see :func:`load_measurements`."""
    read = ReadOptions(**options)
    t = read_pose_table(text, source=source, options=read)
    q = joints_from_file(t.q, read.prismatic)
    # without dir columns, Measurements works them out from the time column's order or the rows'
    directions, order = t.directions, "dir columns" if t.directions is not None else ""
    meas = Measurements(
        q=q,
        position=t.position,
        rotation=None if t.rpy is None else euler_rotation(t.rpy, read.euler),
        targets=None if t.targets is None else tuple(t.targets),
        pose_ids=None if t.pose_ids is None else tuple(t.pose_ids),
        rows=t.rows,
        source=source,
        n_raw=len(t.rows),
        torques=t.torques,
        payload=t.payload,
        directions=directions,
        time=t.time,
        temperature=t.temperature,
        order=order,
        sigma_position=t.sigma_position,
        sigma_orientation=None if t.sigma_orientation is None else np.radians(
            t.sigma_orientation if read.euler == "xyz" or t.rpy is None else
            euler_sigma(t.rpy, t.sigma_orientation, read.euler)),
        sigma_source=f"the sx..{'srz' if t.sigma_orientation is not None else 'sz'} columns of {source}"
        if t.sigma_position is not None or t.sigma_orientation is not None else "",
        point=None if t.point is None else tuple(t.point),
        plane=None if t.plane is None else tuple(t.plane),
        setup=None if t.setup is None else tuple(t.setup),
        pixels=t.pixels,
        camera=None if t.camera is None else tuple(t.camera),
        session=None if t.session is None else tuple(t.session),
        chain=None if t.chain is None else tuple(t.chain),
    )
    if t.cycles is not None and t.pose_ids is None:
        raise InputError("a cycle column numbers the measuring cycles of each pose: it needs a pose_id column",
                         source=source)
    if average and t.pose_ids is not None and meas.constraints is None and t.camera is None:  # a contact
        # or camera row is its own
        meas = average_repeats(meas, repeat_tolerance, t.cycles)
    return meas


def _groups(*labels: Sequence[str]) -> np.ndarray:
    """Group index per row of equal label tuples, groups numbered in order of first appearance."""
    combined = np.array(["\x1f".join(t) for t in zip(*labels)])
    _, first, inverse = np.unique(combined, return_index=True, return_inverse=True)
    rank = np.empty(len(first), dtype=int)
    rank[np.argsort(first)] = np.arange(len(first))
    return rank[inverse.reshape(-1)]


def _spread(values: np.ndarray, group: np.ndarray) -> np.ndarray:
    """Per group, the largest range over rows of any column of ``values`` (m, k)."""
    n = group.max() + 1
    hi = np.full((n, values.shape[1]), -np.inf)
    lo = np.full((n, values.shape[1]), np.inf)
    np.maximum.at(hi, group, values)
    np.minimum.at(lo, group, values)
    return (hi - lo).max(axis=1)


def _group_rows(meas: Measurements, group: np.ndarray, g: int) -> str:
    rows = [int(r) for r in meas.rows[group == g]]
    return "[" + ", ".join(map(str, rows[:8])) + (", …]" if len(rows) > 8 else "]")


def _check_one_pose(meas: Measurements, pose: np.ndarray, labels: list[str], tolerance_deg: float) -> None:
    """Rows of one pose (its reflectors, its repeated rows) must command one joint set, within
    ``tolerance_deg`` (encoder read-backs of one commanded pose differ by thousandths of a degree)."""
    spread = np.degrees(_spread(meas.q, pose))
    bad = np.flatnonzero(spread > tolerance_deg)
    if not bad.size:
        return
    g = bad[int(np.argmax(spread[bad]))]
    rows = np.flatnonzero(pose == g)
    reflectors = sorted({meas.targets[i] for i in rows}) if meas.targets is not None else []
    what = f"rows {_group_rows(meas, pose, g)} (reflectors {', '.join(reflectors)})" if len(reflectors) > 1 else \
        f"repeated rows {_group_rows(meas, pose, g)}"
    raise InputError(f"{labels[rows[0]]}: {what} command different joint values (they differ by {spread[g]:.4g} "
                     f"deg; tolerance {tolerance_deg:g} deg): the rows of one pose_id are one pose; "
                     "give each pose its own pose_id, or number repeated measuring cycles in a cycle column",
                     source=meas.source)


def average_repeats(meas: Measurements, tolerance: float = REPEAT_TOLERANCE_MM, cycles: Sequence[str] | None = None,
                    joint_tolerance: float = JOINT_TOLERANCE_DEG) -> Measurements:
    """Average the rows of one measurement: same pose_id, same cycle (when the file numbers
    its measuring cycles), same reflector (on the same chain of a tree): mean joints, position,
    torques and payload; chordal mean rotation.

    The rows of one pose_id and cycle (every reflector, every repeat) must command the same
    joints within ``joint_tolerance`` deg, and a measurement's repeated rows must agree within
    ``tolerance`` mm of their mean (a gross disagreement is a mislabelled row or a lost beam,
    not noise).  Different cycles of one pose_id stay separate measurements of that pose.
    """
    cycle = ("",) * meas.n_poses if cycles is None else tuple(cycles)
    session = meas.session or ("",) * meas.n_poses  # a pose_id names a pose of its session
    labels = [f"pose_id {p!r}" + (f", cycle {c!r}" if cycles is not None else "")
              + (f", session {s!r}" if meas.session is not None else "") for p, c, s in
              zip(meas.pose_ids, cycle, session)]
    _check_one_pose(meas, _groups(meas.pose_ids, cycle, session), labels, joint_tolerance)
    # a tree's chains each carry their own reflectors: one pose's rows on two arms are two measurements
    group = _groups(meas.pose_ids, cycle, session, meas.targets or ("",) * meas.n_poses,
                    meas.chain or ("",) * meas.n_poses)
    n = group.max() + 1
    if n == meas.n_poses:
        return meas
    count = np.bincount(group, minlength=n)

    def mean(values):
        if values is None:
            return None
        flat = values.reshape(len(values), -1)
        out = np.zeros((n, flat.shape[1]))
        np.add.at(out, group, flat)
        return (out / count[:, None]).reshape((n,) + values.shape[1:])

    position = mean(meas.position)
    spread = np.linalg.norm(meas.position - position[group], axis=1)
    if spread.max() > tolerance:
        i = int(np.argmax(spread))
        raise InputError(f"{labels[i]}: repeated rows {_group_rows(meas, group, group[i])} disagree by "
                         f"{spread[i]:.4g} mm (row {int(meas.rows[i])} furthest from their mean; tolerance "
                         f"{tolerance:g} mm)", source=meas.source)
    first = np.zeros(n, dtype=int)
    first[group[::-1]] = np.arange(meas.n_poses)[::-1]
    return replace(
        meas,
        q=mean(meas.q),
        position=position,
        rotation=None if meas.rotation is None else project_to_so3(mean(meas.rotation) * count[:, None, None]),
        torques=mean(meas.torques),
        payload=mean(meas.payload),
        # repeats approached from both sides sit between the flanks: their direction is unknown
        directions=None if meas.directions is None else np.trunc(mean(meas.directions)),
        time=mean(meas.time),
        temperature=mean(meas.temperature),
        # the mean of n independent readings: σ/√n
        sigma_position=None if meas.sigma_position is None else np.sqrt(mean(meas.sigma_position**2) / count[:, None]),
        sigma_orientation=None if meas.sigma_orientation is None else np.sqrt(
            mean(meas.sigma_orientation**2) / count[:, None]),
        targets=None if meas.targets is None else tuple(meas.targets[i] for i in first),
        pose_ids=tuple(meas.pose_ids[i] for i in first),
        rows=meas.rows[first],
        session=None if meas.session is None else tuple(meas.session[i] for i in first),
        chain=None if meas.chain is None else tuple(meas.chain[i] for i in first),
    )


def load_measurements(path: str | Path, *, average: bool = True, repeat_tolerance: float = REPEAT_TOLERANCE_MM,
                      **options) -> Measurements:
    """Load and validate a measurement CSV.

    options: those of :class:`ReadOptions` (n_joints, columns, joint_unit, length_unit,
    robot_label).  average: average repeated rows by pose_id (positions within
    ``repeat_tolerance`` mm of their mean).
    """
    return parse_measurements(read_text(path, "measurement file"), source=str(path), average=average,
                              repeat_tolerance=repeat_tolerance, **options)


def joints_from_file(q: np.ndarray, prismatic=None) -> np.ndarray:
    """Joint values as files hold them (deg; mm where a joint slides) → robocal's (rad; mm)."""
    return np.where(np.zeros(q.shape[-1], bool) if prismatic is None else np.array(prismatic, bool), q,
                    np.radians(q))


def joints_to_file(q: np.ndarray, prismatic=None) -> np.ndarray:
    """robocal's joint values (rad; mm where a joint slides) → as files hold them (deg; mm)."""
    return np.where(np.zeros(q.shape[-1], bool) if prismatic is None else np.array(prismatic, bool), q,
                    np.degrees(q))


def measurements_to_csv(meas: Measurements, *, extra: Mapping[str, Sequence] | None = None,
                        prismatic=None) -> str:
    """CSV text of measurements (deg and mm, shortest round-trip decimals); prismatic: per joint,
    True where it slides (its values stay in mm)."""
    n = meas.n_joints
    # numeric column groups after the joints: (names, values (m, k)); absent ones are left out
    groups = [(list(POSITION), meas.position),
              (list(ORIENTATION), None if meas.rotation is None else np.degrees(matrix_to_rpy(meas.rotation))),
              ([f"tau{i + 1}" for i in range(n)], meas.torques),
              (["payload"], None if meas.payload is None else meas.payload[:, None]),
              (["time"], None if meas.time is None else meas.time[:, None]),
              (["temperature"], None if meas.temperature is None else meas.temperature[:, None]),
              (list(POSITION_SIGMA), meas.sigma_position),
              (list(ORIENTATION_SIGMA), None if meas.sigma_orientation is None or meas.rotation is None
               else np.degrees(meas.sigma_orientation))]
    if np.all(np.isnan(meas.position)):  # every row touched a point or plane: nothing measured
        groups = groups[1:]
    groups = [(names, np.asarray(v, float)) for names, v in groups if v is not None]
    extra = {**{k: v for k, v in (("point", meas.point), ("plane", meas.plane), ("setup", meas.setup),
                                  ("session", meas.session), ("chain", meas.chain)) if v is not None},
             **dict(extra or {})}
    marker = meas.camera is not None and meas.targets is not None  # a camera row's target is its marker
    if meas.camera is not None:
        pixels = [("" if np.isnan(u) else repr(float(u)), "" if np.isnan(v) else repr(float(v)))
                  for u, v in meas.pixels]
        extra = {"u": [p[0] for p in pixels], "v": [p[1] for p in pixels], "camera": list(meas.camera),
                 **({"marker": list(meas.targets)} if marker else {}), **extra}
    header = (["pose_id"] if meas.pose_ids is not None else []) + (["target"] if meas.targets is not None
                                                                    and not marker else [])
    header += [f"q{i + 1}" for i in range(n)] + [h for names, _ in groups for h in names]
    header += list(extra)
    qdeg = joints_to_file(meas.q, prismatic)
    out = io.StringIO()
    w = csv.writer(out, lineterminator="\n")
    w.writerow(header)
    for j in range(meas.n_poses):
        row = [] if meas.pose_ids is None else [meas.pose_ids[j]]
        if meas.targets is not None and not marker:
            row.append(meas.targets[j])
        row += [repr(float(v)) for v in qdeg[j]]
        row += ["" if np.isnan(v) else repr(float(v)) for _, values in groups for v in values[j]]
        row += [extra[k][j] for k in extra]
        w.writerow(row)
    return out.getvalue()


def save_measurements(meas: Measurements, path: str | Path, prismatic=None) -> None:
    atomic_write(path, measurements_to_csv(meas, prismatic=prismatic))
