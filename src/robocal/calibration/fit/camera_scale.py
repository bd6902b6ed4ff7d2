"""What camera rows know of lengths and of their markers (MODEL §10): a pinhole sees directions, so
the lengths' common scale comes from markers of known offsets, known camera poses or tracker rows,
else from the prior (:func:`scale_note` says which, with its σ); and each camera row's marker
position σ in its camera's frame from the posterior (:func:`marker_sigma`)."""

from __future__ import annotations

import numpy as np

from ...exceptions import Note
from .cameras import gauge, tracked


def length_values(problem, x: np.ndarray) -> np.ndarray:
    """The value (mm) of each estimated length at x, 0 for the other parameters: a uniform scale of
    the cell about the measuring frame's origin moves each length by its value, and leaves every
    pixel where it was (the pinhole sees directions only)."""
    from ...model.kinematics import joint_kinds
    from ...model.parameters import is_frame, is_term, unit

    robot = problem.space.apply(problem.full(x))
    kinds = joint_kinds(robot.convention)
    out = np.zeros(problem.n_params)
    for i, name in enumerate(problem.names):
        if is_term(name):
            continue
        if is_frame(name):
            prefix, axis = name.rsplit("_", 1)
            if axis not in ("x", "y", "z"):
                continue
            if prefix == "base":
                T = robot.base
            elif prefix.startswith("camera["):
                T = robot.cameras[prefix[len("camera["):-1]].pose
            else:
                T = robot.tool if prefix == "tool" else robot.targets[prefix[len("tool["):-1]]
            out[i] = T["xyz".index(axis), 3]
            continue
        kind = name.rstrip("0123456789")
        if kind in kinds and unit(name) == "mm":
            out[i] = robot.geometry[int(name[len(kind):]) - 1, kinds.index(kind)]
    return out


def scale_sources(problem) -> list[str]:
    """What gives camera rows a scale: the known geometry of two markers or more (fixed offsets on
    the flange, not estimated), or a camera's known pose beside the measuring frame's (a baseline)."""
    robot, names = problem.space.robot, set(problem.names)
    from ...model.parameters import tool_prefix

    known = {t for t in problem.meas.target_names if not any(f"{tool_prefix(t)}_{a}" in names for a in "xyz")}
    points = {tuple(np.round(robot.tool_frames([t])[0][:3, 3], 6)) for t in known}
    out = []
    if len(points) >= 2:
        out.append("the markers' known offsets")
    if problem.n_shapes:
        out.append("the markers' known sizes")
    first = gauge(robot, problem.meas)
    if any(m.known for c, m in robot.cameras.items() if c != first):
        out.append("the cameras' known poses")
    if tracked(problem.meas):
        out.append("the tracker rows")
    return out


def scale_note(problem, x: np.ndarray, covariance: np.ndarray | None) -> str | None:
    """What fixes the cell's scale where cameras saw the data, and how well it is known: the
    coefficient ε of the estimated lengths' uniform stretch x = ε·v (about the measuring frame's
    origin, or the cameras' link), whose posterior σ is √(v̂ᵀCv̂)/|v|.  A pinhole sees directions:
    without a known length among the markers or the cameras (:func:`scale_sources`) only the
    lengths' prior holds it, and that is a warning."""
    if problem.views is None or covariance is None:
        return None
    v = length_values(problem, x)
    norm = float(np.linalg.norm(v))
    if norm == 0.0:
        return None
    u = v / norm
    post = float(np.sqrt(max(u @ covariance @ u, 0.0))) / norm
    reach = float(np.median(np.linalg.norm(problem.space.points(problem.full(x), problem.meas.q, problem.target_idx,
                                                                 problem.joints, chain=problem.chain_index), axis=1)))
    sources = scale_sources(problem)
    where = f"±{100 * post:.2g} %, {post * reach:.3g} mm at the markers' {reach:.0f} mm from the frame's origin"
    if not sources:
        return (f"the pixels do not fix the scale: the lengths' common scale is held by their prior ({where}): "
                "give markers of known offsets (--markers), or tracker rows")
    return Note(f"scale: from {' and '.join(sources)} ({where})")


def marker_sigma(problem, x: np.ndarray, covariance: np.ndarray | None) -> np.ndarray | None:
    """Each camera row's predicted σ (mm, rms radius) of its marker's position in its camera's frame,
    from the posterior covariance of the estimate x: what the model knows of where the markers are
    as the cameras see them (a joint's zero and a link camera's turn trade off, and only their sum
    reaches the pixels: in the robot's base frame it is the prior that holds it).  None without a
    covariance or camera rows."""
    views = problem.views
    if views is None or covariance is None or not np.all(np.isfinite(covariance)):
        return None
    full = problem.full(x)
    meas = problem.meas
    Jc, _, p = problem.space.jacobian_columns(full, meas.q, problem.target_idx, joints=problem.joints,
                                              active=problem.active, chain=problem.chain_index)
    frames, Jf = problem.space.camera_frame_columns(full, meas.q, problem._camera_index, problem.joints,
                                                    active=problem.active)
    d = p - frames[:, :3, 3]
    moved = Jc[..., :3] - Jf[..., :3] + np.cross(d[None], Jf[..., 3:])
    dpc = np.einsum("mji,kmj->kmi", frames[:, :3, :3], moved)  # (k, m, 3) in the camera's axes
    variance = np.einsum("kma,kl,lma->m", dpc, covariance, dpc)
    return np.where(views.rows, np.sqrt(np.maximum(variance, 0.0)), np.nan)
