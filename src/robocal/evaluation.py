"""Evaluating a robot model on measured data: the error metrics of MODEL §6."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from . import options as opt
from .exceptions import InputError, Note
from .io.measurements import load_measurements, robot_fields
from .io.robotfile import load_robot
from .model.candidates import FRAME_CHOICES
from .model.measurements import Measurements
from .model.metrics import Metrics
from .model.robot import Robot
from .model.terms import drift_note, missing_torques


@dataclass(frozen=True)
class Evaluation:
    """Metrics of a model on data, with the frames mode used and what robocal noticed."""

    metrics: Metrics
    frames: str
    notes: list[str]
    per_target: dict[str, Metrics]
    #: per pose, the predicted position's standard uncertainty (mm, rms radius) and its label
    sigma: np.ndarray | None = None
    poses: tuple[str, ...] = ()
    #: per pose: its errors and flags (:func:`robocal.model.metrics.per_pose`), with σ when asked
    pose_rows: list = field(default_factory=list)
    #: data whose rows touched unknown points or planes: point_spread_rms, plane_rms,
    #: distance_error_rms (mm; :meth:`robocal.model.constraints.Constraints.figures`)
    contact: dict = field(default_factory=dict)
    #: camera rows: each camera's reprojection figures (px), and what the rows are
    per_camera: dict[str, Metrics] = field(default_factory=dict)
    described: str = ""

    def uncertainty_summary(self) -> dict | None:
        if self.sigma is None:
            return None
        return {"median_mm": float(np.median(self.sigma)), "p95_mm": float(np.percentile(self.sigma, 95)),
                "max_mm": float(np.max(self.sigma))}

    def to_dict(self) -> dict:
        out = self.metrics.to_dict()
        out.update(self.contact)
        if self.frames != "none":
            out["frames"] = self.frames
        if len(self.per_target) > 1:
            out["per_target"] = {t: m.to_dict() for t, m in self.per_target.items()}
        if self.per_camera:
            out["per_camera"] = {c: m.to_dict() for c, m in self.per_camera.items()}
        if self.sigma is not None:
            out["uncertainty"] = {**self.uncertainty_summary(), "per_pose": [
                {"pose": p, "sigma_mm": float(s)} for p, s in zip(self.poses, self.sigma)]}
        return out


def evaluate(robot: str | Path | Robot, data: str | Path | Measurements, *, columns: Mapping[str, str] | None = None,
             frames: str = "none", joint_unit: str | None = None, length_unit: str | None = None,
             payload: float | None = None, uncertainty: bool = False, delimiter: str = ",", decimal: str = ".",
             euler: str = "xyz", point_distance=(), distance_sigma: float = 0.05, cameras=(),
             markers: str | None = None) -> Evaluation:
    """Error metrics of ``robot`` (file, built-in name or Robot) on ``data`` (file or Measurements).

    frames: ``none`` evaluates the model as it is (a calibrated model carries its frames);
    ``base``/``base+tool`` first fit those frames to the data (nominal joints, closed form and
    LM), which is how a nominal model is judged on tracker data; ``auto`` fits them when the
    data are not in the robot's frame.  With ``none`` and data far from the robot's frame, a
    note names the frames option.  The whole model is evaluated: its joint terms (on the data's
    ``tau1..tauN`` and ``payload`` columns; payload: kg where the file has no such column)
    and its residual correction.  Rows that touched unknown points or planes are judged by how
    well the model's tool points meet (``point_spread_rms``, ``plane_rms``) and, with
    ``point_distance`` (``"A,B=MM"``), how far the points' means miss the stated distances
    (``distance_error_rms``); a held-out setup is the honest test, its points being new unknowns.
    Camera rows are judged by their reprojection error (px) with the model's cameras (a
    calibration's export carries their poses): ``cameras`` gives each one's intrinsics
    (``NAME=FILE`` items), ``markers`` a markers file for markers the model does not carry.
    """
    from .calibration.config import point_distances
    from .calibration.fit.registration import choose_frames, fit_frames
    from .calibration.judge.checks import check_units

    opt.choice(frames, FRAME_CHOICES, "frames", "frames mode")
    r = load_robot(robot)
    if uncertainty and r.uncertainty is None:
        raise InputError("the model carries no parameter covariance ([uncertainty]): export it from a calibration "
                         "with calibrate --export", source=r.source or r.name, option="uncertainty")
    meas = data if isinstance(data, Measurements) else load_measurements(
        data, columns=columns, joint_unit=joint_unit, length_unit=length_unit,
        delimiter=delimiter, decimal=decimal, euler=euler, **robot_fields(r))
    if meas.camera is not None and any(meas.camera):
        if not all(meas.camera):
            raise InputError("has camera rows beside tracker rows: evaluate each kind in a file of its own",
                             source=meas.source)
        if frames in ("base", "base+tool"):
            raise InputError("camera rows are judged with the cameras the calibration found, in its frames: "
                             "evaluate them with frames none (or auto)", source=meas.source, option="frames")
        frames = "none"
    from .calibration.fit.cameras import attach_known

    r, meas = attach_known(r, meas, cameras, markers)
    distances = point_distances(point_distance)
    if distances or meas.constraints is not None:
        meas = meas.with_distances(distances, opt.number(distance_sigma, "distance_sigma", minimum=0.0, strict=True))
    contact = meas.constraints
    tracker = meas if contact is None else meas.subset(~contact.rows)
    if contact is not None and contact.only and frames in ("base", "base+tool"):
        raise InputError("the base frame is not observable from rows that touched points or planes whose place is "
                         "unknown: evaluate with frames none", source=meas.source, option="frames")
    seen = meas.views is not None  # camera rows: judged in the model's own frames, in px
    if length_unit is None and tracker.n_poses and not seen:
        check_units(r, tracker, frames)
    if payload is not None and meas.payload is None:
        meas = replace(meas, payload=np.full(meas.n_poses, opt.number(payload, "payload", minimum=0.0)))
    from .model.uncertainty import known_targets, predicted_sigma, region_note

    notes: list[str] = [w for w in (missing_torques(r.terms, meas.torques, meas.source),
                                    drift_note(r.terms, meas.inputs, meas.source),
                                    region_note(r, meas.q, known_targets(r, meas), meas.inputs, meas.chain)) if w]
    mode = frames
    missing = [t for t in meas.target_names if t and t not in r.targets]
    if missing and frames == "none" and not seen:
        # a reflector without a tool frame cannot be evaluated as given: its offset must be fitted
        notes.append(f"reflector '{missing[0]}' has no tool frame in the robot {r.source or r.name}: base and tools "
                     "fitted to these data (frames base+tool) before evaluating")
        frames = "base+tool"
    if (contact is not None and contact.only) or seen:
        mode = "none"  # points and planes stand in any frame; cameras are where the calibration found them
    elif frames in ("none", "auto"):
        choice = choose_frames(r, tracker)
        if frames == "none" and choice.mode != "none":
            notes.append(f"{choice.sentence()}; evaluated as given: fit the frames first with frames auto or "
                         f"{choice.mode}")
        elif frames == "auto" and choice.mode != "none":
            notes.append(Note(f"frames auto: {choice.sentence()}"))
        mode = choice.mode if frames == "auto" else "none"
        if mode != "none":
            r = choice.robot
    else:
        if missing and frames == "base":
            raise InputError(f"reflector '{missing[0]}' has no tool frame in the robot {r.source or r.name}: fit it "
                             "with frames base+tool", source=meas.source, option="frames")
        mode = frames
        r = fit_frames(r, tracker, mode)
    per_target = {t or "(default)": Metrics.of(r, meas.subset([i for i, x in enumerate(meas.targets) if x == t]))
                  for t in meas.target_names} if meas.targets is not None else {}
    sigma = None
    if uncertainty:
        sigma = predicted_sigma(r, meas.q, known_targets(r, meas), meas.inputs, meas.chain)
    from .model.metrics import per_pose

    rows = per_pose(r, meas, "evaluated")
    if sigma is not None:
        for row, s in zip(rows, sigma):
            row["sigma_mm"] = float(s)
    figures = {} if contact is None else contact.figures(r.positions(meas.q, meas.targets, meas.inputs, meas.chain))
    per_camera = {c: Metrics.of(r, meas.subset([i for i, x in enumerate(meas.camera) if x == c]))
                  for c in dict.fromkeys(meas.camera)} if seen else {}
    return Evaluation(Metrics.of(r, meas), mode, notes, {} if seen else per_target, sigma,
                      tuple(meas.label(i) for i in range(meas.n_poses)) if uncertainty else (), rows, figures,
                      per_camera, meas.describe())
