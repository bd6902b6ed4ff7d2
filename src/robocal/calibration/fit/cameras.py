"""Camera rows in a calibration (MODEL §10): the cameras' files and markers read and checked
against the rows, the frames a camera can see, and where each camera starts.

What a camera sees fixes what is identified:

- A fixed camera and the base frame trade off (only their relation reaches the pixels): without
  tracker rows the first fixed camera's frame is the measuring frame, and the base is found in
  it; every other camera's pose is found in that frame.
- A camera on the robot sees the chain from its link to the marker: the base does not reach its
  pixels, nor do the joints up to its link.
- A camera sees no scale: markers with known offsets on the flange give it against the robot's
  lengths; unknown markers leave the lengths' common scale to their prior.
"""

from __future__ import annotations

import csv
import io
from dataclasses import dataclass, replace

import numpy as np

from ...exceptions import InputError, Note
from ...io.atomic import read_text
from ...io.camera import load_camera
from ...math.se3 import homogeneous
from ...model.camera import CameraMount
from ...model.measurements import Measurements
from ...model.robot import Robot
from ..config import CalibrationConfig

#: fewest rows a camera must see for its pose to be found from them (six unknowns, two values a row)
MIN_ROWS = 6


#: an ArUco marker's corners in its own frame (x right, y up as printed, z out of its face), in
#: OpenCV's order, as multiples of its side: top-left, top-right, bottom-right, bottom-left
SQUARE_CORNERS = np.array([[-0.5, 0.5, 0.0], [0.5, 0.5, 0.0], [0.5, -0.5, 0.0], [-0.5, -0.5, 0.0]])


@dataclass(frozen=True)
class MarkerFile:
    """What a markers file says: the markers whose offsets are known (name → 4 × 4 on the flange) and
    the bodies of known shape whose place is not (a square of known size, a board: their markers'
    names and places (N, 3) mm in the body's own frame, :mod:`robocal.model.shapes`)."""

    points: dict
    shapes: tuple[tuple[tuple[str, ...], np.ndarray], ...] = ()

    @property
    def shaped(self) -> set[str]:
        """The markers of the bodies whose place is unknown."""
        return {n for names, _ in self.shapes for n in names}


def load_markers(path: str) -> MarkerFile:
    """A markers file: ``marker, x, y, z`` (mm, in the flange frame), one row a marker; with ``rx, ry,
    rz`` (deg, the marker's frame: z out of its face) and ``size`` (its side, mm) a square marker, whose
    corners ``NAME:0`` … ``NAME:3`` (OpenCV's order, as :mod:`robocal.io.detect` names them) are markers
    too.  A square whose x … rz are left empty stands where the calibration finds it: its corners are
    identified, held to the square's size by their known sides and diagonals.  With a ``body``
    column, the rows of one body give their places in that body's own frame (a marker cube, a ChArUco
    board as ``robocal detect --markers-out`` writes it): the body stands where the calibration finds
    it, its markers identified and held to their known distances, every pair of them."""
    from ...math.se3 import frame_from_values

    text = read_text(path, "markers file")
    rows = list(csv.reader(io.StringIO(text)))
    header = [h.strip() for h in rows[0]] if rows else []
    rest = header[4:]
    body = bool(rest) and rest[-1] == "body"
    square = (rest[:-1] if body else rest) == ["rx", "ry", "rz", "size"]
    if header[:4] != ["marker", "x", "y", "z"] or (rest[:-1] if body else rest) not in ([], ["rx", "ry", "rz", "size"]):
        raise InputError("expected the columns marker, x, y, z (mm, in the flange frame), then rx, ry, rz (deg), size "
                         "(mm) for square markers, then body for markers of a body whose place is unknown",
                         source=path)
    out: dict[str, np.ndarray] = {}
    shapes: list[tuple[tuple[str, ...], np.ndarray]] = []
    bodies: dict[str, dict[str, np.ndarray]] = {}
    named: set[str] = set()
    for line, row in enumerate(rows[1:], start=2):
        if not any(c.strip() for c in row):
            continue
        name = row[0].strip()
        if len(row) != len(header):
            raise InputError(f"has {len(row)} cells, the header {len(header)}", source=path, where=f"row {line}")
        if not name:
            raise InputError("needs a marker name", source=path, where=f"row {line}")
        if name in named:
            raise InputError(f"marker {name!r} is given twice", source=path, where=f"row {line}")
        named.add(name)
        owner = row[-1].strip() if body else ""
        numbers = row[1:-1] if body else row[1:]
        free = square and not owner and not any(c.strip() for c in numbers[:6])
        cells = numbers[6:] if free else numbers
        try:
            values = np.array([float(c) for c in cells])
        except ValueError:
            raise InputError("x, y, z (and rx, ry, rz, size) must be numbers; a square of unknown place leaves x … rz "
                             "empty", source=path, where=f"row {line}") from None
        if not np.all(np.isfinite(values)):
            raise InputError("needs finite numbers", source=path, where=f"row {line}")
        side = values[-1] if square else None
        if square and not side > 0:
            raise InputError(f"a marker's size must be > 0 mm, got {side:g}", source=path,
                             where=f"row {line}, column 'size'")
        corners = [f"{name}:{k}" for k in range(4)]
        if free:  # its corners identified, held to the square of its size
            shapes.append((tuple(corners), SQUARE_CORNERS * side))
            continue
        T = frame_from_values([*values[:3], *np.radians(values[3:6])])
        points = {name: T[:3, 3]}
        if square:
            points.update({corners[k]: T[:3, :3] @ c + T[:3, 3] for k, c in enumerate(SQUARE_CORNERS * side)})
        if owner:  # places in the body's frame: only their distances are known
            bodies.setdefault(owner, {}).update(points)
        else:
            out.update({k: homogeneous(np.eye(3), v) for k, v in points.items()})
    for points in bodies.values():
        shapes.append((tuple(points), np.array(list(points.values()))))
    if not named:
        raise InputError("names no marker", source=path)
    return MarkerFile(out, tuple(shapes))


def resolve_link(robot: Robot, link: int | str, camera: str) -> tuple[int, np.ndarray]:
    """(k, T) of a camera's link: a number k (T the identity), a URDF link's name
    (:func:`robocal.io.urdf.link_frame`), or a joint's name (the link after it)."""
    if isinstance(link, int) or str(link).isdigit():
        k = int(link)
        if k > robot.n_joints:
            raise InputError(f"camera {camera!r} is on link {k}, but the robot has {robot.n_joints} joints",
                             option="camera")
        return k, np.eye(4)
    names = tuple(robot.joint_names or ())
    if robot.urdf is not None:
        from ...io.urdf import link_frame

        try:
            return link_frame(robot, str(link))
        except InputError:
            if link not in names:
                raise
    if link in names:
        return names.index(link) + 1, np.eye(4)
    raise InputError(f"camera {camera!r} is on link {link!r}, which the robot has not (joints: "
                     f"{', '.join(names) or 'unnamed'}; or give the link's number)", option="camera")


def mount_of(robot: Robot, camera: str, link: int | str, pose: np.ndarray | None = None,
             known: bool = False) -> CameraMount:
    """A camera's mounting on ``link`` (see :func:`resolve_link`), ``pose`` (4 × 4) in that link's
    frame when given (else the link's own frame, a start the pixels replace)."""
    k, T = resolve_link(robot, link, camera)
    return CameraMount(k, T if pose is None else T @ pose, known)


def attach(nominal: Robot, meas: Measurements, config: CalibrationConfig) -> tuple[Robot, Measurements, list]:
    """The robot with the markers file's markers as its targets and the measurements with their
    cameras' intrinsics, each checked against the rows: a camera the rows name and no file gives,
    a camera file no row sees, a pixel off its image, a marker the markers file does not name."""
    notes: list = []
    if meas.camera is None or not any(meas.camera):
        if config.cameras:
            raise InputError(f"camera {config.cameras[0].name!r} is given, but {meas.source} has no camera rows "
                             "(columns u, v, camera, marker)", option="camera")
        return nominal, meas, notes
    if meas.constraints is not None:
        raise InputError("has camera rows beside rows that touched points or planes: calibrate camera rows alone or "
                         "beside tracker rows", source=meas.source)
    rows = np.asarray(meas.camera, dtype=object)
    intrinsics = {}
    for spec in config.cameras:
        if spec.name not in set(meas.camera):
            raise InputError(f"camera {spec.name!r} ({spec.path}) is seen in no row of {meas.source}",
                             option="camera")
        intrinsics[spec.name] = load_camera(spec.path, spec.name)
        seen = rows == spec.name
        if seen.sum() < MIN_ROWS:
            raise InputError(f"camera {spec.name!r} sees {int(seen.sum())} rows: its pose needs at least {MIN_ROWS}",
                             source=meas.source)
    check_pixels(meas, intrinsics)
    robot = nominal
    if config.markers is not None:
        markers = load_markers(config.markers)
        named = set(markers.points) | markers.shaped
        check_markers(meas, named | set(nominal.targets), f"no markers file ({config.markers})")
        robot = nominal.replace(targets={**nominal.targets, **markers.points})
        meas = replace(meas, shapes=markers.shapes)
    from ...math.se3 import frame_from_values

    given = nominal.cameras  # a robot object may carry mountings, known ones among them
    mounts = {}
    rig = {k.partition("@")[0]: (k.partition("@")[2], v) for k, v in config.camera_poses.items() if "@" in k}
    for spec in config.cameras:
        values = config.camera_poses.get(spec.name)
        mounts[spec.name] = mount_of(nominal, spec.name, spec.link, None if values is None else
                                     frame_from_values(values), known=values is not None)
        if spec.name in given and values is None:
            if given[spec.name].link != mounts[spec.name].link:
                raise InputError(f"camera {spec.name!r} is on link {mounts[spec.name].link}, but the robot has it on "
                                 f"link {given[spec.name].link}", option="camera")
            mounts[spec.name] = given[spec.name]
    for name, (of, values) in rig.items():  # fixed to another camera: its pose in that one's frame, known
        mounts[name] = CameraMount(mounts[of].link, frame_from_values(values), known=True, of=of)
    robot = robot.replace(cameras=mounts)
    return robot, replace(meas, intrinsics=intrinsics), notes


def attach_known(robot: Robot, meas: Measurements, specs, markers: str | None) -> tuple[Robot, Measurements]:
    """Camera rows judged with a model whose cameras are known (a calibration's export, which
    carries their poses, ``[cameras.NAME]``): each camera's intrinsics from ``specs`` (``NAME=FILE``
    items, a link given must be the model's), the markers from the model's targets or a markers file;
    one line naming what is missing or does not match."""
    from ..config import camera_specs

    specs = camera_specs(specs)
    if meas.camera is None or not any(meas.camera):
        if specs:
            raise InputError(f"camera {specs[0].name!r} is given, but {meas.source} has no camera rows (columns u, v, "
                             "camera, marker)", option="camera")
        return robot, meas
    intrinsics = {}
    for spec in specs:
        mount = robot.cameras.get(spec.name)
        if mount is None:
            raise InputError(f"camera {spec.name!r}: the model {robot.source or robot.name} has no pose for it (a "
                             "calibration's export carries its cameras: [cameras.NAME])", option="camera")
        link = mount_of(robot, spec.name, spec.link).link if spec.link != 0 else None
        if link is not None and link != (robot.cameras[mount.of].link if mount.of else mount.link):
            raise InputError(f"camera {spec.name!r} is on link {link}, but the model has it on link {mount.link}",
                             option="camera")
        intrinsics[spec.name] = load_camera(spec.path, spec.name)
    check_pixels(meas, intrinsics)
    if markers is not None:
        found = load_markers(markers)
        if found.shapes:
            raise InputError("gives markers of unknown place: a model judged on camera rows needs each marker's "
                             "offset (the calibration's export carries the ones it found)", source=markers)
        robot = robot.replace(targets={**robot.targets, **found.points})
    check_markers(meas, set(robot.targets), f"neither the model {robot.source or robot.name} nor a markers file")
    meas = replace(meas, intrinsics=intrinsics)
    check_in_front(robot, meas, f"the model {robot.source or robot.name}")
    return robot, meas


def check_parts(parts: list[Measurements], config: CalibrationConfig, nominal: Robot) -> None:
    """Each file's camera rows checked on its own, before the files are joined (so that a message
    names the file and its row): the pixels on their camera's image, the markers known."""
    seen = [p for p in parts if p.camera is not None and any(p.camera)]
    if not seen or not config.cameras:
        return
    intrinsics = {spec.name: load_camera(spec.path, spec.name) for spec in config.cameras}
    named = set(nominal.targets)
    if config.markers is not None:
        markers = load_markers(config.markers)
        named |= set(markers.points) | markers.shaped
    for part in seen:
        check_pixels(part, intrinsics)
        if config.markers is not None:
            check_markers(part, named, f"no markers file ({config.markers})")


def tracked(meas: Measurements) -> bool:
    """Whether tracker rows stand beside the camera rows: their frame is then the measuring frame."""
    return meas.camera is not None and not all(meas.camera)


def check_pixels(meas: Measurements, intrinsics) -> None:
    """Every camera row names a camera of ``intrinsics`` and lies on its image (one line naming the row)."""
    rows = np.asarray(meas.camera, dtype=object)
    for name in dict.fromkeys(c for c in meas.camera if c):
        if name not in intrinsics:
            first = int(meas.rows[int(np.argmax(rows == name))])
            raise InputError(f"camera {name!r} has no camera file (give it with --camera {name}=FILE)",
                             source=meas.source, where=f"row {first}")
        camera = intrinsics[name]
        off = ~camera.in_image(meas.pixels) & (rows == name)
        if off.any():
            i = int(np.argmax(off))
            raise InputError(f"pixel ({meas.pixels[i, 0]:g}, {meas.pixels[i, 1]:g}) lies outside the "
                             f"{camera.width} × {camera.height} image of camera {name!r}", source=meas.source,
                             where=f"row {int(meas.rows[i])}")


def check_markers(meas: Measurements, known: set, where: str) -> None:
    """Every camera row's marker is one of ``known`` (else one line naming the row and ``where`` it is not)."""
    for i, (camera, marker) in enumerate(zip(meas.camera, meas.targets or ())):
        if camera and marker not in known:
            raise InputError(f"marker {marker!r} is named in {where}", source=meas.source,
                             where=f"row {int(meas.rows[i])}")


def frames_of(frames: str, robot: Robot, meas: Measurements) -> tuple[str, list]:
    """The frames mode of camera rows, and what it says: the base where a fixed camera sees it,
    the markers where their offsets are unknown.  Beside tracker rows, theirs (the caller's
    choice, ``frames``), with the markers' offsets where they are unknown."""
    fixed = [c for c, m in robot.cameras.items() if m.link == 0]
    unknown = [t for t in meas.target_names if t and t not in robot.targets]
    if tracked(meas):
        notes = [Note("tracker rows beside camera rows: the tracker's frame is the measuring frame, every camera's "
                      "pose is found in it, and each kind of rows is weighed by its own σ (mm, px)")]
        seen = {t for t, c in zip(meas.targets or (), meas.camera) if c}
        if any(t not in robot.targets for t in seen if t) and frames in ("none", "base"):
            frames = {"none": "tcp", "base": "base+tool"}[frames]
            notes.append(Note(f"the markers' offsets are unknown, so they are identified (frames {frames})"))
        return frames, notes
    if not fixed and frames in ("base", "base+tool"):
        raise InputError("the base frame is not observable from cameras on the robot: they see the chain from their "
                         "link on (use frames tcp, none or auto)", option="frames")
    notes = []
    if frames == "auto":
        frames = ("base+tool" if unknown else "base") if fixed else ("tcp" if unknown else "none")
        said = "the markers' offsets are identified" if unknown else "the markers stand where the markers file says"
        notes.append(Note(f"frames auto: {said} (frames {frames})"))
    if fixed:
        first = gauge(robot)
        others = [c for c in fixed if c != first]
        notes.append(Note(f"camera {first!r} is the measuring frame: a fixed camera and the base frame trade off, "
                          f"so the base is found in its frame" + (f" and cameras {', '.join(map(repr, others))} "
                                                                   "against it" if others else "")))
    rigs = [f"{c!r} to {m.of!r}" for c, m in robot.cameras.items() if m.of]
    if rigs:
        notes.append(Note(f"camera{'s' if len(rigs) > 1 else ''} {', '.join(rigs)} fixed as given (a calibrated rig): "
                          "found with the camera it is fixed to"))
    linked = [c for c, m in robot.cameras.items() if m.link > 0]
    if linked and not fixed:
        notes.append(Note(f"the base frame is not seen: camera{'s' if len(linked) > 1 else ''} "
                          f"{', '.join(map(repr, linked))} ride{'' if len(linked) > 1 else 's'} on the robot"))
    return frames, notes


def gauge(robot: Robot, meas: Measurements | None = None) -> str | None:
    """The camera whose frame is the measuring frame (not estimated): the first fixed one, unless
    tracker rows stand beside the camera rows (the tracker's frame is then the measuring frame)."""
    if meas is not None and tracked(meas):
        return None
    return next((c for c, m in robot.cameras.items() if m.link == 0 and not m.of), None)


def register(robot: Robot, meas: Measurements) -> Robot:
    """Where each camera starts, with the nominal joints and the markers as the robot has them
    (the flange point for an unknown one, a body of known shape laid out as it about that point):
    from its rows' points and pixels (:meth:`robocal.model.camera.Camera.pose_of`).  The first fixed
    camera's frame becomes the measuring frame: the base is its pose's inverse; the other fixed
    cameras are placed in it."""
    unknown = {t: robot.tool.copy() for t in meas.target_names if t and t not in robot.targets}
    for names, template in meas.shapes:  # a body of known shape starts as its shape, about the tool point
        for name, place in zip(names, np.asarray(template, float) - np.mean(template, axis=0)):
            if name in unknown:
                unknown[name] = robot.tool @ homogeneous(np.eye(3), place)
    robot = robot.replace(targets={**robot.targets, **unknown})
    views = meas.views
    qe = robot.effective_joints(meas.q, meas.inputs)
    R_f, p_f = robot.flange_frames(qe, meas.chain)
    p = p_f + np.einsum("mij,mj->mi", R_f, robot.tool_frames(meas.targets)[:, :3, 3])
    mounts, poses = dict(robot.cameras), {}
    for c, name in enumerate(views.names):
        rows = views.index == c
        link = mounts[name].link
        points = p[rows]
        if link > 0:  # the points in the frame of the camera's link
            Rk, pk = robot.link_frames(qe[rows], link)
            points = np.einsum("mji,mj->mi", Rk, points - pk)
        try:
            poses[name] = views.cameras[c].pose_of(points, meas.pixels[rows])
        except ValueError as exc:
            raise InputError(f"camera {name!r}: its rows' markers, placed by the nominal robot, {exc} (they must "
                             "span the camera's view: more poses, or markers off one line)", source=meas.source) \
                from None
    first = gauge(robot, meas)
    base = robot.base
    if first is not None:  # the measuring frame is this camera's, or the world its known pose is in
        base = (mounts[first].pose if mounts[first].known else np.eye(4)) @ np.linalg.inv(poses[first])
    for name, mount in mounts.items():
        if mount.known:
            continue
        pose = poses[name] if mount.link > 0 else base @ poses[name]
        mounts[name] = mount.moved(np.eye(4) if name == first else pose)
    robot = robot.replace(base=base, cameras=mounts)
    check_in_front(robot, meas, "the cameras' start (their poses from the nominal robot's markers)")
    return robot


def check_in_front(robot: Robot, meas: Measurements, where: str = "the nominal robot") -> None:
    """Every camera row's marker lies in front of its camera for ``robot`` (one line naming the
    first row that does not: a camera on the wrong link, a wrong camera file or marker name)."""
    views = meas.views
    if views is None:
        return
    from ...model.metrics import camera_frames

    p = robot.positions(meas.q, meas.targets, meas.inputs, meas.chain)
    behind = views.behind(p, camera_frames(robot, meas))
    if behind.any():
        i = int(np.argmax(behind))
        raise InputError(f"marker {meas.targets[i]!r} lies behind camera {meas.camera[i]!r} for {where}: check the "
                         "camera's link and file, and the row's camera and marker", source=meas.source,
                         where=f"row {int(meas.rows[i])}")


def frame_names(robot: Robot, meas: Measurements | None = None) -> list[str]:
    """The camera frame parameters a calibration estimates: every camera's but the measuring frame's."""
    from ...model.parameters import FRAME_AXES, camera_prefix

    first = gauge(robot, meas)
    return [f"{camera_prefix(c)}_{ax}" for c, m in robot.cameras.items() if c != first and not m.known
            for ax in FRAME_AXES]


def coverage_note(meas: Measurements) -> Note | None:
    """What part of each camera's image the rows covered (:meth:`robocal.model.views.Views.coverage`):
    the lens model is the user's calibration, and these rows test it only where markers fell."""
    found = meas.views.coverage() if meas.views is not None else {}
    if not found:
        return None
    from ...model.views import COVERAGE_GRID

    parts = ", ".join(f"{c!r} {100 * share:.0f} %" for c, (share, _) in found.items())
    return Note(f"the markers fell in {parts} of the image{'s' * (len(found) > 1)} (cells of a "
                f"{COVERAGE_GRID[0]} × {COVERAGE_GRID[1]} grid): the lens is untested where none fell, and the model "
                "knows it only from its calibration file there")
