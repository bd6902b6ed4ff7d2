"""What a calibration hands its receivers, and the files that hand it: the whole model as a robot
TOML, its geometry and frames as a URDF or a UR kinematics YAML (the whole model beside it where
they cannot hold it all), each chain of a tree as its own robot file; and what each kind of file
gives its reader, on the same poses (:class:`ExportFigures`)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from ..exceptions import InputError
from ..io.atomic import atomic_write


@dataclass(frozen=True)
class ExportFigures:
    """What each kind of export hands its receiver, on the same poses: the whole model (a robot
    TOML, which every robocal command reads) and its geometry and frames alone (what a URDF or a
    kinematics YAML can hold: a controller or ROS gets no joint terms and no learned correction).
    figure: ``validation`` (the validation poses), ``predicted`` (cross-validation of the
    calibration data, as ``held_out`` says) or ``fit``; RMS and max position errors in mm."""

    figure: str
    whole_rms_mm: float
    whole_max_mm: float
    geometry_rms_mm: float
    geometry_max_mm: float
    #: the model holds no more than geometry and frames: every export carries it whole
    geometric: bool
    #: what the held-out figure predicts and how: "new poses (5-fold cross-validation of the calibration
    #: poses)", "a new session (leave-one-session-out, 10 sessions)", …
    held_out: str = "new poses (5-fold cross-validation of the calibration poses)"
    #: whose geometry a URDF or YAML carries: "the model's own", or "the geometric calibration's"
    #: where the model holds joint terms (its own geometry was fitted beside them)
    geometry_of: str = "the model's own"
    #: the unit of the figures: mm, or px where every row is a camera's (the fields keep their names)
    unit: str = "mm"
    #: camera rows: what the whole model's figure means at the tool: its reprojection RMS at the
    #: markers (mm), and the markers' predicted position σ in the robot's frame (mm, the median over
    #: the calibration poses)
    at_marker_rms_mm: float | None = None
    tool_sigma_mm: float | None = None
    #: camera rows: the markers' predicted position σ in their camera's frame (mm, median over the rows)
    seen_sigma_mm: float | None = None
    #: the model holds cameras' poses: a URDF or YAML has them not (a robot TOML beside a URDF has)
    cameras: bool = False
    #: the measuring frame is a fixed camera's: the robot's frame is found in it, one σ says both
    measured_in_camera: bool = False

    @property
    def at_tool(self) -> str:
        """" (1.21 mm at the markers; their position known to σ 0.05 mm in the cameras' frame, 5.4 mm in the
        robot's)", or "" where the figures are mm."""
        said = [] if self.at_marker_rms_mm is None else [f"{self.at_marker_rms_mm:.3g} mm at the markers"]
        known = ([] if self.seen_sigma_mm is None else [f"{self.seen_sigma_mm:.3g} mm in the cameras' frames"]) + \
            ([] if self.tool_sigma_mm is None or self.measured_in_camera else [f"{self.tool_sigma_mm:.3g} mm in the "
                                                                               "robot's"])
        if known:
            said.append(f"their position known to σ {', '.join(known)}")
        return f" ({'; '.join(said)})" if said else ""

    @property
    def where(self) -> str:
        return {"validation": "on the validation poses",
                "predicted": f"predicted on {self.held_out}"}.get(
            self.figure, "on the calibration poses (in-sample)")

    def sentence(self, path, sidecar=None) -> str:
        """What the file at ``path`` holds, and how accurate that is: "PATH: …", one line."""
        suffix = Path(path).suffix.lower()
        whole = f"{self.whole_rms_mm:.4f} {self.unit} RMS{self.at_tool} {self.where}"
        if suffix not in (".urdf", ".yaml", ".yml"):
            return f"{path}: the whole model, {whole}"
        whose = "" if self.geometry_of == "the model's own" else "the geometric calibration's "
        frames = f"{whose}joint geometry (its frames are in" if suffix != ".urdf" else \
            f"{whose}geometry and frames (the whole model is in"
        if self.geometric and self.cameras:
            beside = f"; the cameras' poses are in {sidecar}" if sidecar else \
                "; the cameras' poses are in a robot TOML (export one too)"
            return f"{path}: the geometry and frames, {whole}{beside}"
        if self.geometric and suffix != ".urdf":  # a kinematics YAML holds the joints alone
            return f"{path}: the joint geometry, {whole} with the frames in {sidecar or 'the robot TOML beside it'}"
        if self.geometric:
            return f"{path}: the whole model (geometry and frames), {whole}"
        held = f"{frames} {sidecar or 'the robot TOML beside it'})"
        return (f"{path}: {held}; a controller or ROS reading it gets {self.geometry_rms_mm:.4f} {self.unit} RMS "
                f"{self.where}, where the whole model gets {self.whole_rms_mm:.4f} {self.unit}: its joint terms and "
                "learned correction reach the robot only through robocal filter and compensate")

    def to_dict(self) -> dict:
        rms, top = ("position_rms_mm", "position_max_mm") if self.unit == "mm" else \
            ("reprojection_rms_px", "reprojection_max_px")
        return {"figure": self.figure, "whole_model": {rms: self.whole_rms_mm, top: self.whole_max_mm,
                                                       "held_by": ["robot TOML"]},
                "geometry_and_frames": {rms: self.geometry_rms_mm, top: self.geometry_max_mm,
                                        "geometry_of": self.geometry_of,
                                        "held_by": ["URDF", "kinematics YAML (geometry only)"]},
                "reaches_the_robot": "the whole model through robocal filter and compensate; a URDF or YAML "
                                     "alone carries geometry and frames",
                **({} if self.at_marker_rms_mm is None else {"at_marker_rms_mm": self.at_marker_rms_mm}),
                **({} if self.tool_sigma_mm is None else {"marker_position_sigma_mm": self.tool_sigma_mm}),
                **({} if self.seen_sigma_mm is None else {"marker_sigma_in_camera_mm": self.seen_sigma_mm})}



def export(result, path: str | Path) -> list[Path]:
    """Write the calibrated robot as a robot file (loadable again), with its residual model in
    a sibling file when it has one; the paths written.  A ``.urdf`` path writes a URDF (see
    :mod:`robocal.io.urdf`); joint terms and a residual model cannot live in one, so the
    whole model goes to a robot TOML beside it, ``NAME.robocal.toml``, as well."""
    from ..io.robotfile import save_robot

    comment = (f"Calibrated by robocal ({result.method}, objective {result.objective}, seed {result.seed}) from "
               f"{result.data or 'measurements'}; {len(result.names)} parameters identified, "
               f"{len(result.identifiability.dropped)} left at nominal.")
    # what makes the model doubtful travels with it, not only on the terminal
    doubts = [w for w in result.warnings if w.startswith(("implausible", "model misfit"))]
    comment += "".join(f"\nWARNING: {w}" for w in doubts)
    if result.model != "geometric":
        comment += f"\nModel {result.model}: every robocal command uses its joint terms and residual model."
    path = Path(path)
    if result.robot.tree is not None and path.suffix.lower() in (".yaml", ".yml"):
        raise InputError("a UR kinematics file holds one arm: export a tree as .toml or .urdf (each chain gets "
                         "its own robot file beside it)", source=path)
    chains = _export_chains(result, path, comment)
    if path.suffix.lower() in (".yaml", ".yml"):
        return _export_ur(result, path, comment)
    if path.suffix.lower() != ".urdf":
        return save_robot(result.robot.without_sessions(), path, comment) + chains
    from ..io.urdf import urdf_text

    written, whole = [], None
    if not result.robot.geometric or result.robot.cameras:  # the sidecar first: the URDF alone would be an
        # incomplete model (its joint terms, its cameras' poses)
        whole = path.with_name(f"{path.stem}.robocal.toml")
        written = save_robot(result.robot.without_sessions(), whole, comment)
    probe = bool(result.contact)  # the tip link itself touched the points or planes: it is the tool
    where = "the tip link is the identified tool point" if probe else "target the tool"
    receiver = (result.receiver or result.robot).without_sessions()
    atomic_write(path, urdf_text(receiver, comment + receiver_comment(result) +
                                 "\nLengths in m, angles in rad; measuring_frame carries the identified base "
                                 f"frame, {where}.", whole_model=None if whole is None else whole.name,
                                 tool_at_tip=probe))
    return [path, *written, *chains]

def _export_chains(result, path: Path, comment: str) -> list[Path]:
    """Each chain of a tree as a serial robot file beside ``path`` (``NAME.CHAIN.toml``), for the
    commands that drive one arm (filter, compensate); none for a serial robot."""
    from ..io.robotfile import save_robot

    tree = result.robot.tree
    if tree is None:
        return []
    robot = (result.receiver or result.robot).without_sessions()
    written = []
    for name in tree.names:
        try:
            arm = robot.chain(name)
        except ValueError as exc:
            raise InputError(str(exc), source=path) from None
        text = f"{comment}\nChain {name} of the tree: its joints q1..q{arm.n_joints} are the tree's " + \
            ", ".join(arm.joint_names or ()) + "."
        if not result.robot.geometric:  # a trunk's load depends on every arm: one chain cannot hold it
            text = text.replace(f"\nModel {result.model}: every robocal command uses its joint terms and residual "
                                "model.", "") + \
                (f"\nGeometry only ({'the geometric calibration' if result.receiver is not None else 'the model'}'s): "
                 f"the tree's joint terms ({result.model}) load its trunk with every arm, which one chain cannot "
                 f"hold; {path.name if path.suffix.lower() != '.urdf' else path.stem + '.robocal.toml'} holds the "
                 "whole model.")
        written += save_robot(arm, path.with_name(f"{path.stem}.{name}.toml"), text)
    return written


def receiver_comment(result) -> str:
    """What a URDF's or a YAML's own reader gets, for its header."""
    e = result.exports
    if e is None or e.geometric:
        return ""
    return (f"\nThis file holds {e.geometry_of} geometry: {e.geometry_rms_mm:.4f} {e.unit} RMS {e.where} (the "
            f"whole model: {e.whole_rms_mm:.4f} {e.unit}; its joint terms and learned correction reach the robot "
            "through robocal filter and compensate).")

def _export_ur(result, path: Path, comment: str) -> list[Path]:
    """A UR kinematics YAML for a ROS driver (:mod:`robocal.io.ur`), and the whole model
    (frames, tool, terms) in ``NAME.robocal.toml`` beside it; what the YAML cannot hold is said."""
    import warnings

    from ..exceptions import RobocalWarning
    from ..io.robotfile import save_robot
    from ..io.ur import ur_kinematics_yaml

    text, notes = ur_kinematics_yaml((result.receiver or result.robot).without_sessions())
    whole = path.with_name(f"{path.stem}.robocal.toml")
    written = save_robot(result.robot.without_sessions(), whole, comment)
    head = "".join(f"# {line}\n" for line in (comment + receiver_comment(result) + "\nLengths in m, angles in "
                                               f"rad. The measuring frame and the tool are in {whole.name}.")
                   .splitlines())
    atomic_write(path, head + text)
    for note in notes:
        warnings.warn(f"{path}: {note}", RobocalWarning, stacklevel=2)
    return [path, *written]
