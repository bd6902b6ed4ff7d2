"""Pose errors of a model on measurements and their summary figures (MODEL §2, §6)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..math.so3 import orientation_error
from .measurements import Measurements
from .robot import Robot


def pose_errors(robot: Robot, meas: Measurements) -> tuple[np.ndarray, np.ndarray | None]:
    """Position errors δp = p_measured − p_model (m, 3) in mm, and for full-pose data the
    orientation errors δ = log(R_measured · R_modelᵀ) (m, 3) in rad about the measuring
    frame's axes (None for position-only data).  Rows a camera saw have their measured less predicted
    pixel (px) in the first two slots (:mod:`robocal.model.views`).  Rows that touched an unknown point or plane
    (:mod:`robocal.model.constraints`) have the offset of their predicted point from that
    point's (plane's) best fit."""
    T = robot.in_sessions(robot.fk(meas.q, meas.targets, meas.inputs, meas.chain), meas.session)
    dp = meas.position - T[:, :3, 3]
    c = meas.constraints
    if c is not None:  # rows that touched an unknown point or plane: the offset from its best fit
        dp = np.where(c.rows[:, None], c.errors(T[:, :3, 3]), dp)
    v = meas.views
    if v is not None:  # rows a camera saw: measured less predicted pixel
        dp = np.where(v.rows[:, None], v.errors(T[:, :3, 3], camera_frames(robot, meas)), dp)
    if meas.rotation is None:
        return dp, None
    return dp, orientation_error(meas.rotation, T[:, :3, :3])


def camera_frames(robot: Robot, meas: Measurements) -> np.ndarray:
    """Each row's camera frame (m, 4, 4) in the measuring frame (the identity at rows no camera saw)."""
    out = np.broadcast_to(np.eye(4), (meas.n_poses, 4, 4)).copy()
    rows = meas.views.rows
    sub = meas.subset(rows)
    out[rows] = robot.camera_frames(sub.camera, sub.q, sub.inputs)
    return out


def pixel_scale(robot: Robot, meas: Measurements) -> np.ndarray:
    """Each camera row's millimetres per pixel at its marker (m,): the marker's depth along its
    camera's optical axis (mm, with ``robot``'s model) over the camera's focal length (px, the
    mean of fx and fy); NaN at other rows.  A pixel error times it is the error at the marker,
    across the camera's view."""
    out = np.full(meas.n_poses, np.nan)
    views = meas.views
    if views is None:
        return out
    frames = camera_frames(robot, meas)
    p = robot.positions(meas.q, meas.targets, meas.inputs, meas.chain)
    depth = np.einsum("mj,mj->m", frames[:, :3, 2], p - frames[:, :3, 3])
    focal = np.array([(c.fx + c.fy) / 2.0 for c in views.cameras] + [np.nan])[views.index]
    return np.where(views.rows, depth / focal, np.nan)


def camera_figures(robot: Robot, meas: Measurements) -> dict[str, float]:
    """The camera rows' reprojection RMS (px), over all of them and per camera (``…[NAME]``)."""
    dp, _ = pose_errors(robot, meas)
    seen = ~meas.length_rows
    e = np.linalg.norm(dp[:, :2], axis=1)
    names = np.asarray(meas.camera, dtype=object)
    out = {"reprojection_rms_px": float(np.sqrt(np.mean(e[seen] ** 2)))}
    for name in dict.fromkeys(meas.camera):
        if name:
            out[f"reprojection_rms_px[{name}]"] = float(np.sqrt(np.mean(e[names == name] ** 2)))
    return out


def _stats(x: np.ndarray) -> dict[str, float]:
    return {
        "mean": float(np.mean(x)),
        "std": float(np.std(x, ddof=1)) if x.size > 1 else 0.0,
        "max": float(np.max(x)),
    }


@dataclass(frozen=True)
class Metrics:
    """Summary of pose errors over n poses.

    position: rms, mean, std (n−1), max of |δp| in mm; axis_max: max |δp_x|, |δp_y|,
    |δp_z| in mm; orientation: per axis mean, std, max of |δ| in deg (full pose only).
    """

    n: int
    position: dict[str, float]
    axis_max: dict[str, float]
    orientation: dict[str, dict[str, float]] | None = None
    #: the unit of the position figures: mm, or px where every row is a camera's (the
    #: reprojection error: ``axis_max`` then holds u, v and a zero)
    unit: str = "mm"
    #: camera rows: the reprojection error at the marker, mm (rms, mean, max: each row's pixel error
    #: times its mm per px, :func:`pixel_scale`), None for other figures
    at_marker: dict[str, float] | None = None

    @classmethod
    def from_errors(cls, dp: np.ndarray, drot: np.ndarray | None = None, unit: str = "mm",
                    mm_per_px: np.ndarray | None = None) -> Metrics:
        """The figures of errors dp (m, 3) (and orientations (m, 3) rad); ``mm_per_px`` (m,): camera
        rows' scale at their marker, which adds :attr:`at_marker`."""
        norm = np.linalg.norm(dp, axis=1)
        position = {"rms": float(np.sqrt(np.mean(norm**2))), **_stats(norm)}
        axis_max = {ax: float(np.abs(dp[:, k]).max()) for k, ax in enumerate("xyz")}
        orientation = None
        if drot is not None:
            deg = np.degrees(np.abs(drot))
            orientation = {ax: _stats(deg[:, k]) for k, ax in enumerate("xyz")}
        at_marker = None
        if mm_per_px is not None and unit == "px" and np.all(np.isfinite(mm_per_px)):
            mm = norm * mm_per_px
            at_marker = {"rms": float(np.sqrt(np.mean(mm ** 2))), "mean": float(np.mean(mm)),
                         "max": float(np.max(mm))}
        return cls(len(dp), position, axis_max, orientation, unit, at_marker)

    @classmethod
    def of(cls, robot: Robot, meas: Measurements) -> Metrics:
        """The figures of ``robot`` on ``meas``: of every row, or, where camera rows stand beside rows
        measured in mm, of those (the pixels' figures are apart: :func:`camera_figures`)."""
        dp, dr = pose_errors(robot, meas)
        if meas.unit == "mm" and meas.camera is not None:
            keep = meas.length_rows
            dp, dr = dp[keep], None if dr is None else dr[keep]
        return cls.from_errors(dp, dr, unit=meas.unit,
                               mm_per_px=pixel_scale(robot, meas) if meas.unit == "px" else None)

    def rows(self) -> list[tuple[str, float]]:
        """(label, value) pairs in the order tables show them (mm, deg)."""
        if self.unit == "px":
            out = [(f"reprojection {k} (px)", self.position[k]) for k in ("rms", "mean", "std", "max")]
            out += [(f"max |δ{ax}| (px)", self.axis_max[k]) for k, ax in zip("xy", "uv")]
            if self.at_marker is not None:  # what the pixels mean where the markers were
                out += [(f"at the markers {k} (mm)", self.at_marker[k]) for k in ("rms", "max")]
            return out
        out = [(f"position {k} (mm)", self.position[k]) for k in ("rms", "mean", "std", "max")]
        out += [(f"max |δp{ax}| (mm)", self.axis_max[ax]) for ax in "xyz"]
        if self.orientation is not None:
            out += [(f"orientation {ax} {k} (deg)", self.orientation[ax][k]) for ax in "xyz"
                    for k in ("mean", "std", "max")]
        return out

    def to_dict(self) -> dict:
        out = {"n": self.n, "position": dict(self.position), "axis_max": dict(self.axis_max)}
        if self.unit != "mm":
            out["unit"] = self.unit
        if self.at_marker is not None:
            out["at_marker_mm"] = dict(self.at_marker)
        if self.orientation is not None:
            out["orientation"] = {k: dict(v) for k, v in self.orientation.items()}
        return out


def table_rows(columns: dict[str, Metrics]) -> list[tuple[str, list[str]]]:
    """(label, one cell per column) for each figure any column has, "—" where one lacks it (a
    position-only prediction beside full-pose figures)."""
    values = [dict(m.rows()) for m in columns.values()]
    labels = list(dict.fromkeys(label for m in columns.values() for label, _ in m.rows()))
    return [(label, [f"{v[label]:.4f}" if label in v else "—" for v in values]) for label in labels]


#: the columns of a per-pose table (mm and deg)
POSE_COLUMNS = ("set", "pose_id", "row", "reflector", "contact", "setup", "dx_mm", "dy_mm", "dz_mm", "error_mm",
                "rx_deg", "ry_deg", "rz_deg", "angle_deg", "outlier", "outside_region_deg",
                "outside_joint")


#: the columns of a camera row's error in a per-pose table (px), after ``setup``
CAMERA_COLUMNS = ("camera", "du_px", "dv_px", "error_px")


def pose_columns(rows: list[dict], sigma: bool = False) -> tuple[str, ...]:
    """The columns of a per-pose table of ``rows``: camera columns where a camera saw any, σ where given."""
    columns = POSE_COLUMNS
    if any(r.get("camera") for r in rows):
        at = columns.index("setup") + 1
        columns = columns[:at] + CAMERA_COLUMNS + columns[at:]
    return columns + (("sigma_mm",) if sigma else ())


def per_pose(robot: Robot, meas: Measurements, label: str = "", outlier_rows=frozenset()) -> list[dict]:
    """One row per pose: its id (the file's ``pose_id``, else ``row N`` as messages name it) and
    file row, reflector, for a row that touched a point or plane that contact and its setup,
    position error δp (mm, measuring frame; a contact row's offset from its point or plane) and
    its norm, orientation error about x, y, z and its angle (deg; empty for position data),
    whether it was left out as an outlier (``outlier_rows``: file rows), and how far (deg, mm for
    a sliding joint) it lies outside the region the model was calibrated on, and by which joint most."""
    dp, dr = pose_errors(robot, meas)
    far, worst = np.zeros(meas.n_poses), np.zeros(meas.n_poses, int)
    if robot.region is not None:  # degrees for a turning joint, mm for a sliding one
        d = np.where(robot.prismatic, *(lambda x: (x, np.degrees(x)))(robot.region.outside(meas.q)))
        far, worst = np.max(d, axis=1), np.argmax(d, axis=1)
    rows = []
    c = meas.constraints
    seen = np.zeros(meas.n_poses, bool) if meas.camera is None else np.array([bool(x) for x in meas.camera])
    for i in range(meas.n_poses):
        touched = c is not None and c.group[i] >= 0
        if seen[i]:  # a pixel, not a length
            rows.append({
                "set": label, "pose_id": f"row {int(meas.rows[i])}" if meas.pose_ids is None else meas.pose_ids[i],
                "row": int(meas.rows[i]), "reflector": meas.targets[i], "contact": "", "setup": "",
                "camera": meas.camera[i], "du_px": float(dp[i, 0]), "dv_px": float(dp[i, 1]),
                "error_px": float(np.linalg.norm(dp[i, :2])), "dx_mm": "", "dy_mm": "", "dz_mm": "", "error_mm": "",
                "rx_deg": "", "ry_deg": "", "rz_deg": "", "angle_deg": "", "outlier": int(meas.rows[i]) in outlier_rows,
                "outside_region_deg": float(far[i]), "outside_joint": int(worst[i]) + 1 if far[i] > 0 else ""})
            continue
        rows.append({
            "set": label, "pose_id": f"row {int(meas.rows[i])}" if meas.pose_ids is None else meas.pose_ids[i],
            "row": int(meas.rows[i]), "reflector": "" if meas.targets is None else meas.targets[i],
            "contact": f"{c.kind[c.group[i]]} {c.label[c.group[i]]}" if touched else "",
            "setup": c.setup[c.group[i]] if touched else "",
            "dx_mm": float(dp[i, 0]), "dy_mm": float(dp[i, 1]), "dz_mm": float(dp[i, 2]),
            "error_mm": float(np.linalg.norm(dp[i])),
            **({"rx_deg": "", "ry_deg": "", "rz_deg": "", "angle_deg": ""} if dr is None else {
                "rx_deg": float(np.degrees(dr[i, 0])), "ry_deg": float(np.degrees(dr[i, 1])),
                "rz_deg": float(np.degrees(dr[i, 2])), "angle_deg": float(np.degrees(np.linalg.norm(dr[i])))}),
            "outlier": int(meas.rows[i]) in outlier_rows, "outside_region_deg": float(far[i]),
            "outside_joint": int(worst[i]) + 1 if far[i] > 0 else "",
            **({"camera": "", "du_px": "", "dv_px": "", "error_px": ""} if seen.any() else {})})
    return rows
