"""Poses for a camera calibration: joint sets that keep markers in view and inform the parameters
(MODEL §10).

Candidates are random joint sets inside the joint ranges; at each, every marker a camera would see
(in front of it, on its image away from the border, by the nominal model and the cameras' given or
default poses) is a camera row.  The rows' pixel Jacobian over what the calibration will estimate
(the joints' parameters, the base where a fixed camera sees it, the cameras' frames but the
measuring frame's, the markers' offsets where they are unknown), whitened by the pixel noise, gives
each candidate's information; poses are chosen greedily to maximise log det of the sum (D-optimal),
among candidates that see at least one marker.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

from .. import options as opt
from ..calibration.fit.cameras import frame_names
from ..calibration.fit.problem import Setup
from ..calibration.judge.identifiability import analyse
from ..exceptions import InputError
from ..model.camera import CameraMount
from ..model.candidates import complete, frame_candidates, joint_candidates
from ..model.measurements import Measurements
from ..model.parameters import ParameterSpace, is_angle
from ..model.robot import Robot
from ..simulation import camera_rows, facing, marker_chains, marker_points, random_joints

#: a marker counts as seen where its pixel lies this share of the image's size inside its border
MARGIN = 0.05


@dataclass
class CameraPlan:
    """Joint sets to image: q (N, n) rad; rows: the camera rows each is expected to give; value: log
    det of the information per parameter; random_values: the same for random sets of as many poses
    among the candidates that see a marker; in_view: candidates that see one, of those drawn."""

    q: np.ndarray
    rows: np.ndarray
    value: float
    names: list[str]
    predicted_std: np.ndarray
    random_values: list[float] = field(default_factory=list)
    in_view: tuple[int, int] = (0, 0)
    cameras: dict = field(default_factory=dict)

    def summary(self) -> dict:
        return {"poses": int(len(self.q)), "rows_expected": int(self.rows.sum()),
                "criterion": "log det of the information per parameter (D-optimal)", "value": self.value,
                "random_median": float(np.median(self.random_values)) if self.random_values else None,
                "candidates_in_view": {"seeing_a_marker": self.in_view[0], "drawn": self.in_view[1]},
                "parameters": [{"name": n, "predicted_std": float(s)} for n, s in zip(self.names, self.predicted_std)],
                "cameras": self.cameras}


def _logdet(M: np.ndarray) -> np.ndarray:
    sign, value = np.linalg.slogdet(M)
    return np.where(sign > 0, value, -np.inf)


def plan_camera_poses(robot: Robot, n_poses: int, cameras: Mapping, *, markers: Mapping[str, np.ndarray] | None = None,
                      markers_known: bool = False, candidates: int = 2000, pixel_noise: float = 0.5, seed: int = 0,
                      joint_range=None, random_sets: int = 20) -> CameraPlan:
    """Choose ``n_poses`` joint sets for cameras ``{name: (Camera, CameraMount or None)}`` (a fixed
    camera without a pose faces the markers' workspace, :func:`robocal.simulation.facing`; one on a link
    needs its pose) seeing ``markers`` ({name: 4 × 4 on the flange}, default one at the tool point),
    known (not estimated) or not; see the module docstring."""
    opt.number(pixel_noise, "pixel_noise", minimum=0.0, strict=True)
    if n_poses < 1 or candidates < n_poses:
        raise InputError(f"need 1 ≤ poses ≤ candidates, got {n_poses} and {candidates}", option="poses")
    rng = np.random.default_rng(seed)
    markers = {"m1": robot.tool} if not markers else dict(markers)
    robot = complete(robot).replace(targets={**robot.targets, **markers})
    q = random_joints(robot, candidates, rng, joint_range)
    on = marker_chains(robot, {n: m for n, (_, m) in cameras.items() if m is not None})
    points = marker_points(robot, q, list(markers), on).reshape(-1, 3)
    mounts, intrinsics = {}, {}
    for name, (camera, mount) in cameras.items():
        if mount is not None and mount.link > 0 and mount.link > robot.n_joints:
            raise InputError(f"camera {name!r} is on link {mount.link}, but the robot has {robot.n_joints} joints",
                             option="camera")
        if mount is None:
            mount = CameraMount(0, facing(camera, points))
        mounts[name], intrinsics[name] = mount, camera
    robot = robot.replace(cameras=mounts)
    pose, cams, names, pixels, chains = camera_rows(robot, q, intrinsics, list(markers), margin=MARGIN, chains=on)
    if not len(pose):
        raise InputError(f"no camera sees a marker at any of {candidates} candidate joint sets: check the cameras' "
                         "poses (--camera-pose)", option="camera")
    meas = Measurements(q[pose], np.full((len(pose), 3), np.nan), targets=names, camera=cams, pixels=pixels,
                        intrinsics=intrinsics, chain=None if robot.tree is None else chains)
    fixed = any(m.link == 0 for m in mounts.values())
    frames = ("base" if fixed else "none") if markers_known else ("base+tool" if fixed else "tcp")
    params = joint_candidates(robot) + frame_candidates(frames, list(markers), False) + \
        frame_names(robot, meas)
    space = ParameterSpace.of(robot, list(markers))
    problem = Setup(space, meas, sigma_position=pixel_noise, use_orientation=False).problem(params)
    J = problem.residual_jacobian(np.zeros(problem.n_params))
    ident = analyse(J, params, np.array([is_angle(n) for n in params]), len(pose), robot.reach())
    keep = [params.index(n) for n in ident.kept]
    rows = J[:, keep].reshape(len(pose), 3, len(keep))
    A = np.zeros((candidates, len(keep), len(keep)))
    np.add.at(A, pose, np.einsum("mrk,mrl->mkl", rows, rows))
    count = np.bincount(pose, minlength=candidates)
    seeing = np.flatnonzero(count > 0)
    if len(seeing) < n_poses:
        raise InputError(f"only {len(seeing)} of {candidates} candidate joint sets see a marker; {n_poses} poses "
                         "asked: draw more candidates, or place the cameras where they see the markers",
                         option="poses")
    k = len(keep)
    ridge = 1e-9 * np.trace(A.sum(0)) / k * np.eye(k)
    M, chosen = ridge.copy(), []
    free = np.zeros(candidates, bool)
    free[seeing] = True
    for _ in range(n_poses):
        scores = np.full(candidates, -np.inf)
        scores[free] = _logdet(M + A[free])
        c = int(np.argmax(scores))
        chosen.append(c)
        free[c] = False
        M = M + A[c]
    from ..calibration.judge.statistics import standard_uncertainties
    from .design import short_moves

    chosen = np.asarray(chosen)[short_moves(q[np.asarray(chosen)])]
    plan = CameraPlan(q[chosen], count[chosen], float(_logdet(M)) / k, ident.kept,
                      standard_uncertainties(information=M), in_view=(len(seeing), candidates),
                      cameras={n: {"link": m.link, "pose": m.pose.tolist()} for n, m in mounts.items()})
    for _ in range(random_sets):
        pick = rng.choice(seeing, n_poses, replace=False)
        plan.random_values.append(float(_logdet(A[pick].sum(0) + ridge)) / k)
    return plan
