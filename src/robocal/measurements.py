"""Measurement files (CSV, SPEC §6): joint values and measured poses.

Columns: ``q1 … qn`` (deg), ``x, y, z`` (mm), optionally ``rx, ry, rz`` (deg, rpy with
``R = Rz(rz) Ry(ry) Rx(rx)``) for full-pose data, ``pose_id`` (rows sharing one are
repeated measurements of one pose and are averaged) and ``target`` (which point on
the flange).  Positions and orientations are in the measuring device's frame.

The loader validates everything and raises :class:`~robocal.errors.InputError`
naming the file, the row (line number in the file, header = line 1) and the column.
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

from .errors import InputError, atomic_write
from .transforms import matrix_to_rpy, project_to_so3, rpy_to_matrix

POSITION = ("x", "y", "z")
ORIENTATION = ("rx", "ry", "rz")
OPTIONAL = ("pose_id", "target")
_JOINT = re.compile(r"^q(\d+)$")

#: repeated rows of one pose_id that spread further than this (mm) are an error
REPEAT_TOLERANCE_MM = 1.0


@dataclass(frozen=True, eq=False)
class Measurements:
    """Measured poses.

    q: (m, n) commanded joint values, rad.  position: (m, 3) measured point, mm, in
    the measuring frame.  rotation: (m, 3, 3) measured orientation or None for
    position-only data.  targets: target name per pose or None.  rows: line number
    in the source file of each pose (first line of an averaged group).
    """

    q: np.ndarray
    position: np.ndarray
    rotation: np.ndarray | None = None
    targets: tuple[str, ...] | None = None
    pose_ids: tuple[str, ...] | None = None
    rows: np.ndarray | None = None
    source: str = "<data>"
    n_raw: int = 0

    def __post_init__(self) -> None:
        object.__setattr__(self, "q", np.atleast_2d(np.asarray(self.q, dtype=float)))
        object.__setattr__(self, "position", np.atleast_2d(np.asarray(self.position, dtype=float)))
        if self.rows is None:
            object.__setattr__(self, "rows", np.arange(2, 2 + len(self.q)))
        if not self.n_raw:
            object.__setattr__(self, "n_raw", len(self.q))

    @property
    def n_poses(self) -> int:
        return self.q.shape[0]

    @property
    def n_joints(self) -> int:
        return self.q.shape[1]

    @property
    def full_pose(self) -> bool:
        return self.rotation is not None

    @property
    def target_names(self) -> tuple[str, ...]:
        return ("",) if self.targets is None else tuple(dict.fromkeys(self.targets))

    def subset(self, index) -> Measurements:
        index = np.asarray(index)
        if index.dtype == bool:
            index = np.flatnonzero(index)

        def pick(seq):
            return None if seq is None else tuple(seq[i] for i in index)

        return replace(
            self,
            q=self.q[index],
            position=self.position[index],
            rotation=None if self.rotation is None else self.rotation[index],
            targets=pick(self.targets),
            pose_ids=pick(self.pose_ids),
            rows=self.rows[index],
            n_raw=len(index),
        )

    def position_only(self) -> Measurements:
        return replace(self, rotation=None)


def _float(cell: str, source: str, row: int, col: str) -> float:
    text = cell.strip()
    try:
        value = float(text)
    except ValueError:
        hint = " (decimal comma? use '.' for decimals)" if re.fullmatch(r"[-+]?\d+,\d+", text) else ""
        raise InputError(f"{cell!r} is not a number{hint}", source=source, where=f"row {row}, column '{col}'") from None
    if not math.isfinite(value):
        raise InputError(f"value is not finite ({text})", source=source, where=f"row {row}, column '{col}'")
    return value


@dataclass
class Table:
    """The validated numeric content of a measurement-style CSV (deg and mm as in the file)."""

    q: np.ndarray | None
    position: np.ndarray | None
    rpy: np.ndarray | None
    pose_ids: list[str] | None
    targets: list[str] | None
    rows: np.ndarray


def read_table(
    text: str,
    *,
    source: str,
    n_joints: int | None = None,
    columns: Mapping[str, str] | None = None,
    require_joints: bool = True,
    require_position: bool = True,
    robot_label: str = "",
) -> Table:
    """Read and validate a CSV with columns q1..qn, x, y, z, rx, ry, rz, pose_id, target.

    Every problem is an :class:`InputError` naming the file, row and column.
    """
    if not text.strip():
        raise InputError("file is empty", source=source)
    reader = csv.reader(io.StringIO(text.lstrip("\ufeff")))
    try:
        rows = [(reader.line_num, r) for r in reader]
    except csv.Error as exc:
        raise InputError(f"not a valid CSV file ({exc})", source=source) from None
    rows = [(ln, r) for ln, r in rows if any(c.strip() for c in r)]
    if not rows:
        raise InputError("file has no header row (only empty cells)", source=source)
    header_line, header = rows[0]
    header = [h.strip() for h in header]
    if len(header) == 1 and (";" in header[0] or "\t" in header[0]):
        sep = ";" if ";" in header[0] else "tab"
        raise InputError(
            f"header is separated by {sep}; robocal reads comma-separated files",
            source=source,
            where=f"row {header_line}",
        )
    mapping = dict(columns or {})
    for old in mapping:
        if old not in header:
            raise InputError(f"column '{old}' named in the column mapping is not in the file", source=source)
    header = [mapping.get(h, h) for h in header]
    seen: dict[str, int] = {}
    for i, h in enumerate(header):
        if h == "":
            raise InputError(f"column {i + 1} has an empty name", source=source, where=f"row {header_line}")
        if h in seen:
            raise InputError(f"column '{h}' appears twice", source=source, where=f"row {header_line}")
        seen[h] = i
    joint_cols = sorted((int(m.group(1)), h) for h in header if (m := _JOINT.match(h)))
    known = set(POSITION) | set(ORIENTATION) | set(OPTIONAL)
    for h in header:
        if h not in known and not _JOINT.match(h):
            raise InputError(
                f"unknown column '{h}' (expected q1..qn, x, y, z, optional rx, ry, rz, pose_id, target;"
                " map other names with a column mapping)",
                source=source,
            )
    if not joint_cols and require_joints:
        raise InputError("no joint columns (q1, q2, …)", source=source)
    numbers = [k for k, _ in joint_cols]
    if numbers and numbers != list(range(1, len(numbers) + 1)):
        missing = sorted(set(range(1, max(numbers) + 1)) - set(numbers))
        raise InputError(f"joint column 'q{missing[0]}' is missing", source=source)
    if numbers and n_joints is not None and len(numbers) != n_joints:
        raise InputError(
            f"file has {len(numbers)} joint columns (q1..q{len(numbers)}) but the robot"
            f"{f' ({Path(robot_label).name})' if robot_label else ''} has {n_joints} joints",
            source=source,
        )
    have_pos = [c in seen for c in POSITION]
    if require_position or any(have_pos):
        for c in POSITION:
            if c not in seen:
                raise InputError(f"missing column '{c}'", source=source)
    elif not numbers:
        raise InputError("needs joint columns (q1..qn) or a position (x, y, z)", source=source)
    have_rot = [c in seen for c in ORIENTATION]
    if any(have_rot) and not all(have_rot):
        missing = [c for c, h in zip(ORIENTATION, have_rot) if not h]
        raise InputError(f"orientation columns rx, ry, rz come together; '{missing[0]}' is missing", source=source)
    if all(have_rot) and not all(have_pos):
        raise InputError("orientation columns rx, ry, rz need x, y, z too", source=source)
    data = rows[1:]
    if not data:
        raise InputError("file has a header but no data rows", source=source)
    qcols = [seen[h] for _, h in joint_cols]
    pcols = [seen[c] for c in POSITION] if all(have_pos) else []
    rcols = [seen[c] for c in ORIENTATION] if all(have_rot) else []
    m = len(data)
    q = np.empty((m, len(qcols))) if qcols else None
    pos = np.empty((m, 3)) if pcols else None
    rpy = np.empty((m, 3)) if rcols else None
    line_numbers = np.empty(m, dtype=int)
    pose_ids: list[str] | None = [] if "pose_id" in seen else None
    targets: list[str] | None = [] if "target" in seen else None
    for r, (ln, cells) in enumerate(data):
        line_numbers[r] = ln
        if len(cells) != len(header):
            extra = " (decimal commas? use '.' for decimals)" if len(cells) > len(header) else ""
            raise InputError(
                f"has {len(cells)} cells, the header has {len(header)}{extra}", source=source, where=f"row {ln}"
            )
        for arr, cols in ((q, qcols), (pos, pcols), (rpy, rcols)):
            for j, c in enumerate(cols):
                arr[r, j] = _float(cells[c], source, ln, header[c])
        if pose_ids is not None:
            pid = cells[seen["pose_id"]].strip()
            if not pid:
                raise InputError("empty pose_id", source=source, where=f"row {ln}, column 'pose_id'")
            pose_ids.append(pid)
        if targets is not None:
            targets.append(cells[seen["target"]].strip())
    if q is not None and m >= 3 and np.abs(q).max() <= math.pi + 1e-9 and np.abs(q).max() > 0:
        raise InputError(
            "all joint values lie within ±π: they look like radians; files give joints in degrees",
            source=source,
        )
    return Table(q, pos, rpy, pose_ids, targets, line_numbers)


def parse_measurements(
    text: str,
    *,
    source: str = "<data>",
    n_joints: int | None = None,
    columns: Mapping[str, str] | None = None,
    average: bool = True,
    repeat_tolerance: float = REPEAT_TOLERANCE_MM,
    robot_label: str = "",
) -> Measurements:
    """Parse CSV text; see :func:`load_measurements`."""
    t = read_table(text, source=source, n_joints=n_joints, columns=columns, robot_label=robot_label)
    meas = Measurements(
        q=np.radians(t.q),
        position=t.position,
        rotation=None if t.rpy is None else rpy_to_matrix(np.radians(t.rpy)),
        targets=None if t.targets is None else tuple(t.targets),
        pose_ids=None if t.pose_ids is None else tuple(t.pose_ids),
        rows=t.rows,
        source=source,
        n_raw=len(t.rows),
    )
    if average and t.pose_ids is not None:
        meas = average_repeats(meas, repeat_tolerance)
    return meas


def average_repeats(meas: Measurements, tolerance: float = REPEAT_TOLERANCE_MM) -> Measurements:
    """Average rows sharing (pose_id, target): mean position, chordal mean rotation.

    Rows of one group must command the same joints, and their positions must agree
    within ``tolerance`` mm of the group mean (a gross disagreement is a mislabelled
    row or a lost beam, not noise).
    """
    keys = list(zip(meas.pose_ids, meas.targets or ("",) * meas.n_poses))
    groups: dict[tuple[str, str], list[int]] = {}
    for i, k in enumerate(keys):
        groups.setdefault(k, []).append(i)
    if all(len(g) == 1 for g in groups.values()):
        return meas
    order = list(groups.values())
    first = np.array([g[0] for g in order])
    q = meas.q[first].copy()
    pos = np.empty((len(order), 3))
    rot = None if meas.rotation is None else np.empty((len(order), 3, 3))
    for k, g in enumerate(order):
        rows = [int(meas.rows[i]) for i in g]
        dq = np.abs(meas.q[g] - meas.q[g[0]]).max()
        if dq > 1e-9:
            raise InputError(
                f"pose_id {keys[g[0]][0]!r}: repeated rows {rows} command different joint values "
                f"(differ by {math.degrees(dq):.4g} deg)",
                source=meas.source,
            )
        mean = meas.position[g].mean(0)
        spread = np.linalg.norm(meas.position[g] - mean, axis=1)
        if spread.max() > tolerance:
            bad = rows[int(np.argmax(spread))]
            raise InputError(
                f"pose_id {keys[g[0]][0]!r}: repeated rows {rows} disagree by {spread.max():.4g} mm "
                f"(row {bad} furthest from their mean; tolerance {tolerance:g} mm)",
                source=meas.source,
            )
        pos[k] = mean
        if rot is not None:
            rot[k] = project_to_so3(meas.rotation[g].sum(0))
    return replace(
        meas,
        q=q,
        position=pos,
        rotation=rot,
        targets=None if meas.targets is None else tuple(keys[g[0]][1] for g in order),
        pose_ids=tuple(keys[g[0]][0] for g in order),
        rows=meas.rows[first],
    )


def read_text(path: str | Path, what: str) -> str:
    """A text file's content, or an InputError naming it."""
    path = Path(path)
    if not path.is_file():
        raise InputError(f"no such {what}", source=path)
    try:
        return path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"cannot read {what} ({exc.__class__.__name__})", source=path) from None


def load_measurements(
    path: str | Path,
    *,
    n_joints: int | None = None,
    columns: Mapping[str, str] | None = None,
    average: bool = True,
    repeat_tolerance: float = REPEAT_TOLERANCE_MM,
    robot_label: str = "",
) -> Measurements:
    """Load and validate a measurement CSV.

    n_joints: the robot's joint count, checked against the q-columns.  columns: map
    of file column name → robocal column name (e.g. ``{"A1": "q1"}``).  average:
    average repeated rows by pose_id.
    """
    text = read_text(path, "measurement file")
    return parse_measurements(
        text,
        source=str(path),
        n_joints=n_joints,
        columns=columns,
        average=average,
        repeat_tolerance=repeat_tolerance,
        robot_label=robot_label,
    )


def _fmt(x: float) -> str:
    return repr(float(x))


def measurements_to_csv(meas: Measurements, *, extra: Mapping[str, Sequence] | None = None) -> str:
    n = meas.n_joints
    header = []
    if meas.pose_ids is not None:
        header.append("pose_id")
    if meas.targets is not None:
        header.append("target")
    header += [f"q{i + 1}" for i in range(n)] + list(POSITION)
    if meas.rotation is not None:
        header += list(ORIENTATION)
    extra = dict(extra or {})
    header += list(extra)
    qdeg = np.degrees(meas.q)
    rpy = None if meas.rotation is None else np.degrees(matrix_to_rpy(meas.rotation))
    out = io.StringIO()
    w = csv.writer(out, lineterminator="\n")
    w.writerow(header)
    for j in range(meas.n_poses):
        row = []
        if meas.pose_ids is not None:
            row.append(meas.pose_ids[j])
        if meas.targets is not None:
            row.append(meas.targets[j])
        row += [_fmt(v) for v in qdeg[j]] + [_fmt(v) for v in meas.position[j]]
        if rpy is not None:
            row += [_fmt(v) for v in rpy[j]]
        row += [extra[k][j] for k in extra]
        w.writerow(row)
    return out.getvalue()


def save_measurements(meas: Measurements, path: str | Path) -> None:
    atomic_write(path, measurements_to_csv(meas))
