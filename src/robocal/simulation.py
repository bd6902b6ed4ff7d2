"""Simulated measurement campaigns: plant deviations in a robot, draw joint sets, measure with noise."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace

import numpy as np

from . import options as opt
from .exceptions import InputError
from .math.se3 import frame_from_values
from .math.so3 import exp_so3
from .model.candidates import parallel_pairs
from .model.kinematics import joint_parameter_names
from .model.measurements import Measurements, move_directions
from .model.parameters import ParameterSpace, is_angle
from .model.robot import Robot
from .model.terms import TERMS, JointInputs, JointTerms, mass_torques, nominal_masses
from .presets import wen2019

MEASURES = ("pose", "position")


def planted_deviations(robot: Robot, spec: str, rng: np.random.Generator) -> dict[str, float]:
    """Joint-geometry deviations from a spec: ``none``, ``paper`` (Wen 2019 Table 2, ER10L-C10),
    or ``uniform:LEN_MM,ANGLE_RAD`` (uniform in ±LEN on lengths — a, d; x, y, z of urdf origins
    — and ±ANGLE on angles — α, θ; rx, ry, rz — and on β of hayati joints whose axis is
    parallel to the next)."""
    spec = spec.strip().lower()
    if spec == "none":
        return {}
    if spec == "paper":
        if robot.convention != "hayati" or robot.n_joints != 6:
            raise InputError("errors 'paper' are Wen et al. Table 2, for the 6-joint hayati ER10L-C10",
                             option="errors")
        return dict(wen2019.TABLE2_DEVIATIONS)
    if spec.startswith("uniform:"):
        try:
            length, angle = (float(v) for v in spec[len("uniform:") :].split(","))
        except ValueError:
            raise InputError("expected uniform:LEN_MM,ANGLE_RAD, e.g. uniform:0.25,0.05", option="errors") from None
        if not (math.isfinite(length) and math.isfinite(angle)) or length < 0 or angle < 0:
            raise InputError("uniform bounds must be finite and ≥ 0", option="errors")
        out: dict[str, float] = {}
        for names in joint_parameter_names(robot.convention, robot.geometry):
            for name in names:
                if not name.startswith("beta"):
                    out[name] = rng.uniform(-angle, angle) if is_angle(name) else rng.uniform(-length, length)
        if robot.convention == "hayati":
            for i in parallel_pairs(robot):
                out[f"beta{i + 1}"] = rng.uniform(-angle, angle)
        return out
    raise InputError(f"unknown error spec {spec!r} (none | paper | uniform:LEN_MM,ANGLE_RAD)", option="errors")


def joint_ranges(robot: Robot, joint_range=None) -> np.ndarray:
    """(n, 2) rad sampling ranges: the joint limits (±π where a joint has none), intersected
    with ``joint_range``: (lo, hi) rad for every joint, or (n, 2) per joint."""
    lim = robot.limits.copy()
    lim[~np.isfinite(lim[:, 0]), 0] = -math.pi
    lim[~np.isfinite(lim[:, 1]), 1] = math.pi
    if joint_range is None:
        return lim
    rng = np.asarray(joint_range, dtype=float)
    if rng.ndim == 2 and rng.shape != (robot.n_joints, 2):
        raise InputError(f"expected {robot.n_joints} joint ranges, got {len(rng)}", option="limits")
    lim = np.column_stack([np.maximum(lim[:, 0], rng[..., 0]), np.minimum(lim[:, 1], rng[..., 1])])
    bad = np.flatnonzero(lim[:, 0] >= lim[:, 1])
    if bad.size:
        raise InputError(f"joint {bad[0] + 1} range does not overlap its limits",
                         option="range" if rng.ndim == 1 else "limits")
    return lim


def random_joints(robot: Robot, n: int, rng: np.random.Generator, joint_range=None) -> np.ndarray:
    """n joint sets (n, joints) in rad, uniform inside :func:`joint_ranges`; a coupled joint follows its
    joints (:mod:`robocal.model.coupled`)."""
    lim = joint_ranges(robot, joint_range)
    return robot.couple(rng.uniform(lim[:, 0], lim[:, 1], size=(n, robot.n_joints)))


@dataclass(frozen=True)
class Simulation:
    """A simulated campaign: what was measured, the true robot, and the deviations planted in it (mm, rad)."""

    measurements: Measurements
    truth: Robot
    deviations: dict[str, float]


def plant(robot: Robot, deviations: str | dict[str, float], rng: np.random.Generator) -> tuple[dict, Robot]:
    """The deviations planted (a spec of :func:`planted_deviations` or a {parameter: value} dict, mm and
    rad) and the true robot they make."""
    space = ParameterSpace.of(robot)
    planted = planted_deviations(robot, deviations, rng) if isinstance(deviations, str) else dict(deviations)
    try:
        return planted, space.apply(space.vector(planted))
    except KeyError as exc:
        raise InputError(f"unknown parameter {exc.args[0]}", option="errors") from None


def simulate(
    robot: Robot,
    n_poses: int,
    *,
    deviations: str | dict[str, float] = "none",
    noise: float = 0.0,
    angle_noise: float = 0.0,
    joint_noise: float = 0.0,
    joint_noise_uniform: float = 0.0,
    measure: str = "pose",
    seed: int | None = 0,
    joint_range=None,
    q: np.ndarray | None = None,
    base: Sequence[float] | None = None,
    tool: Sequence[float] | None = None,
    compliance: Mapping[int, float] | None = None,
    harmonics: Mapping[int, Sequence[Sequence[float]]] | None = None,
    backlash: Mapping[int, float] | None = None,
    drift: Mapping[int, float] | None = None,
    pose_interval: float = 10.0,
) -> Simulation:
    """Simulate a measurement campaign on a robot with planted deviations.

    deviations: a spec for :func:`planted_deviations` or a {parameter: value} dict (mm, rad;
    any name of :class:`ParameterSpace`).  noise: σ of the position noise per axis (mm).
    angle_noise: σ of the orientation noise per axis (rad).  joint_noise: σ (rad) of
    Gaussian differences between commanded and actual joints; joint_noise_uniform:
    half-width (rad) of uniform ones (Wen 2019 adds U(−0.1, 0.1) rad).  The file records
    the commanded joints.  base/tool: the true measuring frame → base and flange → point as
    (x, y, z[, rx, ry, rz]) in mm and rad, replacing the robot's own.  q: joint sets to use
    instead of random ones (rad); joint_range: see :func:`joint_ranges`.

    compliance: {joint (1-based): c rad/(N·m)} planted as Δq_i = c_i τ_i, with τ the gravity
    torques of a plausible mass model (:func:`robocal.model.terms.nominal_masses`) at the
    commanded joints, written to the measurements as ``tau1..tauN``.  harmonics: {joint:
    [(a_1, b_1), (a_2, b_2), …]} rad planted as Δq_i = Σ_h a_h cos(h q_i) + b_h sin(h q_i).
    backlash: {joint: b rad} planted as Δq_i = b_i · dir_i, dir_i the sign of joint i's move
    into the pose in the order the poses are drawn (the file's row order; the first pose's is
    unknown, 0).  drift: {joint: r rad/h} planted as Δq_i = r_i (t − t_end)/3600 s, the poses
    measured every ``pose_interval`` s from t = 0 (written as a ``time`` column; the joints
    stand where they end the campaign at its last pose).  The true robot carries them as joint
    terms (compliance in torque form).
    """
    opt.choice(measure, MEASURES, "measure", "measure")
    for name, value in (("noise", noise), ("angle_noise", angle_noise), ("joint_noise", joint_noise),
                        ("joint_noise_uniform", joint_noise_uniform)):
        opt.number(value, name, minimum=0.0)
    if q is None and opt.integer(n_poses, "poses") < 1:
        raise InputError(f"need at least 1 pose, got {n_poses}", option="poses")
    rng = np.random.default_rng(seed)
    planted, truth = plant(robot, deviations, rng)
    if base is not None:
        truth = truth.replace(base=frame_from_values(base))
    if tool is not None:
        truth = truth.replace(tool=frame_from_values(tool))
    terms = planted_terms(robot, compliance, harmonics, backlash, drift)
    if terms is not None:
        truth = truth.replace(terms=terms)
    q_cmd = random_joints(robot, n_poses, rng, joint_range) if q is None else np.asarray(q, float)
    torques = None
    if compliance:
        parents = None if robot.tree is None else robot.tree.parents
        masses, centres = nominal_masses(robot.convention, truth.geometry, parents)
        torques = mass_torques(robot.convention, truth.geometry, q_cmd, terms.gravity_direction, masses, centres,
                               parents)
    q_act = q_cmd.copy()
    if joint_noise > 0:
        q_act = q_act + rng.normal(0.0, joint_noise, q_cmd.shape)
    if joint_noise_uniform > 0:
        q_act = q_act + rng.uniform(-joint_noise_uniform, joint_noise_uniform, q_cmd.shape)
    directions = move_directions(q_cmd)  # the poses are measured in the order drawn
    time = None
    if drift:
        time = np.arange(len(q_cmd)) * opt.number(pose_interval, "pose_interval", minimum=0.0, strict=True)
        truth = truth.replace(terms=replace(truth.terms, clock=("s", float(time[-1]))))
    chains, pose_ids = None, None
    if robot.tree is not None:  # every pose measured on each chain's own tool, the rows of a pose together
        if tool is not None:
            raise InputError("a tree's chains carry their own tools: no tool to plant", option="tool")
        k = len(robot.tree.names)
        chains = robot.tree.names * len(q_cmd)
        pose_ids = tuple(str(i // k + 1) for i in range(k * len(q_cmd)))
        q_cmd, q_act = np.repeat(q_cmd, k, axis=0), np.repeat(q_act, k, axis=0)
        directions = np.repeat(directions, k, axis=0)
        torques = None if torques is None else np.repeat(torques, k, axis=0)
        time = None if time is None else np.repeat(time, k)
    T = truth.fk(q_act, inputs=JointInputs(torques=torques, directions=directions, time=time, clock="s"),
                 chains=chains)
    pos = T[:, :3, 3] + (rng.normal(0.0, noise, (len(q_cmd), 3)) if noise > 0 else 0.0)
    rot = None
    if measure == "pose":
        rot = T[:, :3, :3]
        if angle_noise > 0:
            rot = exp_so3(rng.normal(0.0, angle_noise, (len(q_cmd), 3))) @ rot
    return Simulation(Measurements(q=q_cmd, position=pos, rotation=rot, source="<simulated>", torques=torques,
                                   directions=directions, time=time, order="row order", chain=chains,
                                   pose_ids=pose_ids), truth, planted)


def planted_terms(robot: Robot, compliance: Mapping[int, float] | None,
                  harmonics: Mapping[int, Sequence[Sequence[float]]] | None,
                  backlash: Mapping[int, float] | None = None,
                  drift: Mapping[int, float] | None = None) -> JointTerms | None:
    """Joint terms from {joint: c}, {joint: [(a, b), …]}, {joint: b} and {joint: r} (1-based joints),
    checked; each term's arrays come from its entry of :data:`robocal.model.terms.TERMS`."""
    n = robot.n_joints

    def joint(j, option):
        j = opt.integer(j, option, minimum=1)
        if j > n:
            raise InputError(f"joint {j} does not exist (the robot has {n})", option=option)
        return j

    planted = {}
    if compliance:
        planted["compliance"] = {joint(j, "compliance"): opt.number(v, "compliance") for j, v in compliance.items()}
    if harmonics:
        planted["harmonics"] = {joint(j, "harmonic"): [opt.floats(pair, "harmonic", (2,)) for pair in pairs]
                                for j, pairs in harmonics.items()}
    if backlash:
        planted["backlash"] = {joint(j, "backlash"): opt.number(v, "backlash", minimum=0.0)
                               for j, v in backlash.items()}
    if drift:
        planted["drift"] = {joint(j, "drift"): opt.number(v, "drift") for j, v in drift.items()}
    if not planted:
        return None
    return JointTerms({k: v for name, values in planted.items() for k, v in TERMS[name].plant(values, n).items()})


#: what the probe of a contact campaign touches
CONTACTS = ("points", "planes")


def _reach(robot: Robot, targets: np.ndarray, q0: np.ndarray, lim: np.ndarray, iterations: int = 60,
           tolerance: float = 1e-7) -> tuple[np.ndarray, np.ndarray]:
    """Joints (K, n) that put ``robot``'s tool point on ``targets`` (K, 3) mm, by damped least
    squares from the starts q0 (a redundant arm keeps near its start, so varied starts give
    varied configurations); and which reached within ``tolerance`` mm inside the ranges."""
    from .model.jointspace import joint_jacobian

    q = q0.copy()
    for _ in range(iterations):
        e = targets - robot.positions(q)
        if np.max(np.abs(e)) < tolerance:
            break
        J = joint_jacobian(robot, q, False, 1.0)  # (K, 3, n)
        A = J @ np.swapaxes(J, 1, 2) + 1e-6 * np.eye(3)
        q = np.clip(q + np.einsum("kji,kj->ki", J, np.linalg.solve(A, e[..., None])[..., 0]), lim[:, 0], lim[:, 1])
    e = np.linalg.norm(targets - robot.positions(q), axis=1)
    return q, (e < tolerance) & np.all((q >= lim[:, 0]) & (q <= lim[:, 1]), axis=1)


def _setup(truth: Robot, robot: Robot, rng, middle: np.ndarray, lim: np.ndarray, joint_range, contact: str,
           per_group: int, spacing: float, noise: float, plane_size: float) -> dict[str, np.ndarray] | None:
    """One setup's contacts: {label: joints (per_group, n)}, or None when some cannot be reached."""
    centre = truth.positions(rng.uniform(middle[:, 0], middle[:, 1], (1, robot.n_joints)))[0]
    if contact == "points":
        u = rng.normal(size=3)
        u[2] *= 0.2  # a tool lying on a table: its sockets side by side
        u /= np.linalg.norm(u)
        groups = {"A": np.tile(centre, (per_group, 1)), "B": np.tile(centre + spacing * u, (per_group, 1))}
    else:
        n = rng.normal(size=3)
        n /= np.linalg.norm(n)
        a = np.cross(n, [1.0, 0.0, 0.0] if abs(n[0]) < 0.9 else [0.0, 1.0, 0.0])
        a /= np.linalg.norm(a)
        b = np.cross(n, a)
        r, t = 0.5 * plane_size * np.sqrt(rng.uniform(size=per_group)), rng.uniform(0, 2 * math.pi, per_group)
        groups = {"P": centre + (r * np.cos(t))[:, None] * a + (r * np.sin(t))[:, None] * b}
    out = {}
    for label, points in groups.items():
        found: dict[int, np.ndarray] = {}
        for _ in range(6):  # three starts a contact, until every contact of the group is reached
            pending = [k for k in range(per_group) if k not in found]
            if not pending:
                break
            goals = np.repeat(points[pending], 3, axis=0)
            goals = goals + (rng.normal(0.0, noise, goals.shape) if noise > 0 else 0.0)
            q, ok = _reach(truth, goals, random_joints(robot, len(goals), rng, joint_range), lim)
            q, ok = q.reshape(len(pending), 3, -1), ok.reshape(len(pending), 3)
            for k, row_q, row_ok in zip(pending, q, ok):
                if row_ok.any():
                    found[k] = row_q[int(np.argmax(row_ok))]
        if len(found) < per_group:
            return None
        out[label] = np.array([found[k] for k in range(per_group)])
    return out


def simulate_contacts(robot: Robot, per_group: int, *, setups: int = 4, contact: str = "points",
                      spacing: float = 50.0, deviations: str | dict[str, float] = "none", noise: float = 0.0,
                      seed: int | None = 0, tool: Sequence[float] | None = None, joint_range=None,
                      plane_size: float = 200.0) -> Simulation:
    """A campaign without a tracker on a robot with planted deviations: the tool point (a ball)
    touches points or planes whose place is unknown, and only the joints are recorded.

    ``points``: each of ``setups`` placements of a two-socket tool, sockets ``A`` and ``B``
    ``spacing`` mm apart somewhere the robot reaches, each touched in ``per_group``
    configurations.  ``planes``: each setup one plane ``P`` (a random normal, through a point
    the robot reaches) touched at ``per_group`` points spread over a disc of ``plane_size`` mm.
    noise: σ per axis (mm) of where the ball actually sits (play in the socket, the probe's
    seat), the floor such data can reach.  The joints are the true robot's (damped least
    squares from random starts inside the ranges, kept when they reach within 1e-7 mm); tool: the
    true flange → ball (x, y, z mm), replacing the robot's own.
    """
    opt.choice(contact, CONTACTS, "contact", "contact")
    per_group = opt.integer(per_group, "poses", minimum=2 if contact == "points" else 3)
    setups = opt.integer(setups, "setups", minimum=1)
    opt.number(noise, "noise", minimum=0.0)
    opt.number(spacing, "spacing", minimum=0.0, strict=True)
    rng = np.random.default_rng(seed)
    space = ParameterSpace.of(robot)
    planted = planted_deviations(robot, deviations, rng) if isinstance(deviations, str) else dict(deviations)
    truth = space.apply(space.vector(planted))
    if tool is not None:
        truth = truth.replace(tool=frame_from_values(tool))
    lim = joint_ranges(robot, joint_range)
    q_rows, labels, where = [], [], []
    middle = lim.mean(axis=1)[:, None] + 0.6 * (lim - lim.mean(axis=1)[:, None])  # places well inside the reach
    for s in range(setups):
        for _ in range(10):  # another place for a setup whose contacts the robot cannot all reach
            reached = _setup(truth, robot, rng, middle, lim, joint_range, contact, per_group, spacing, noise,
                             plane_size)
            if reached is not None:
                break
        else:
            raise InputError(f"the robot reaches no place where all {per_group} contacts of a setup fit in ten "
                             "tries: widen the joint ranges, lower --spacing or --poses", option="poses")
        for label, q in reached.items():
            q_rows.append(q)
            labels += [label] * per_group
            where += [f"S{s + 1}"] * per_group
    q = np.vstack(q_rows)
    kind = {"point": tuple(labels)} if contact == "points" else {"plane": tuple(labels)}
    meas = Measurements(q=q, position=np.full((len(q), 3), np.nan), source="<simulated contacts>", setup=tuple(where),
                        **kind)
    return Simulation(meas, truth, planted)


def look_at(eye: np.ndarray, target: np.ndarray, up=(0.0, 0.0, 1.0)) -> np.ndarray:
    """The camera frame (4 × 4) at ``eye`` whose optical axis (z) points at ``target``, its image's x
    to the right and y down (``up`` up)."""
    from .math.se3 import homogeneous

    z = np.asarray(target, float) - np.asarray(eye, float)
    z /= np.linalg.norm(z)
    x = np.cross(z, up)
    x = x / np.linalg.norm(x) if np.linalg.norm(x) > 1e-9 else np.array([1.0, 0.0, 0.0])
    return homogeneous(np.column_stack([x, np.cross(z, x), z]), np.asarray(eye, float))


def facing(camera, points: np.ndarray, fill: float = 0.7) -> np.ndarray:
    """Where a fixed camera sees ``points`` (m, 3) mm of the measuring frame whole: from above and
    outside the arm, at the distance where their spread fills ``fill`` of the image's shorter side."""
    centre = points.mean(0)
    radius = float(np.percentile(np.linalg.norm(points - centre, axis=1), 95)) + 50.0
    out = np.array([centre[0], centre[1], 0.0])
    out = out / np.linalg.norm(out) if np.linalg.norm(out) > 1e-6 else np.array([1.0, 0.0, 0.0])
    half = min((camera.width or 2 * camera.cx) / camera.fx, (camera.height or 2 * camera.cy) / camera.fy) / 2
    distance = radius / (fill * half)
    direction = out + np.array([0.0, 0.0, 0.8])
    return look_at(centre + distance * direction / np.linalg.norm(direction), centre)


def marker_chains(robot: Robot, mounts: Mapping) -> tuple[str | None, ...]:
    """The chains whose markers cameras see: a tree's every chain but those that carry a camera at
    their tip (a head's); (None,) for a serial robot."""
    if robot.tree is None:
        return (None,)
    carrying = {c for c, path in robot.tree.chains.items() for m in mounts.values() if m.link == path[-1] + 1}
    return tuple(c for c in robot.tree.names if c not in carrying)


def marker_points(robot: Robot, q: np.ndarray, markers: Sequence[str], chains: Sequence[str | None]) -> np.ndarray:
    """Each marker on each chain (chain-major) at joints q: (n, chains × markers, 3) mm."""
    n = len(q)
    return np.stack([robot.positions(q, [m] * n, chains=None if c is None else [c] * n)
                     for c in chains for m in markers], axis=1)


def camera_rows(robot: Robot, q: np.ndarray, intrinsics: Mapping, markers: Sequence[str], *, noise: float = 0.0,
                rng: np.random.Generator | None = None, margin: float | None = None,
                chains: Sequence[str | None] = (None,)):
    """Every (pose, camera, marker) the cell of ``robot`` (its cameras' poses) sees at joints q: the pose
    index, the camera, the marker, its pixel (with Gaussian ``noise``, px a coordinate) and its chain
    (``chains``: a tree's whose markers are seen, :func:`marker_chains`; None for a serial robot).  Seen:
    in front of the camera and on its image (:meth:`~robocal.model.camera.Camera.in_image`), or with
    ``margin`` that share of the image's size inside its border (an unstated size taken as 2 cx, 2 cy)."""
    pose, cams, names, pixels, on = [], [], [], [], []
    points = marker_points(robot, q, markers, chains)  # (n, chains × markers, 3)
    pairs = [(c, m) for c in chains for m in markers]
    for name, camera in intrinsics.items():
        T = robot.camera_frames([name] * len(q), q)
        width, height = camera.width or 2 * camera.cx, camera.height or 2 * camera.cy
        for k, (chain, marker) in enumerate(pairs):
            pc = np.einsum("mji,mj->mi", T[:, :3, :3], points[:, k] - T[:, :3, 3])
            uv = camera.project(pc)
            uv = uv + (rng.normal(0.0, noise, uv.shape) if noise > 0 else 0.0)
            if margin is None:
                ok = camera.in_image(uv) & (pc[:, 2] > 0)
            else:
                ok = (pc[:, 2] > 0) & np.all(np.isfinite(uv), axis=1)
                ok &= (uv[:, 0] > margin * width) & (uv[:, 0] < (1 - margin) * width)
                ok &= (uv[:, 1] > margin * height) & (uv[:, 1] < (1 - margin) * height)
            idx = np.flatnonzero(ok)
            pose.append(idx)
            pixels.append(uv[idx])
            cams += [name] * len(idx)
            names += [marker] * len(idx)
            on += [chain] * len(idx)
    return np.concatenate(pose), tuple(cams), tuple(names), np.concatenate(pixels), tuple(on)


def simulate_cameras(robot: Robot, n_poses: int, cameras: Mapping, *, markers: Mapping[str, np.ndarray] | None = None,
                     deviations: str | dict[str, float] = "none", pixel_noise: float = 0.0, seed: int | None = 0,
                     joint_range=None) -> Simulation:
    """A camera campaign: joint sets drawn in the limits, and the pixel where each camera sees each
    marker at each pose (in front of it and on its image), with Gaussian noise ``pixel_noise`` (px
    a coordinate).  cameras: {name: (Camera, CameraMount or None)}: a mounting left out places a fixed
    camera facing the markers' workspace (:func:`facing`); one on a link needs its mounting.
    markers: {name: 4 × 4 on the flange} (default one, ``m1``, at the robot's tool point).  The true
    robot carries the cameras where they were and the markers as its targets."""
    from .model.camera import CameraMount

    opt.number(pixel_noise, "pixel_noise", minimum=0.0)
    if opt.integer(n_poses, "poses") < 1:
        raise InputError(f"need at least 1 pose, got {n_poses}", option="poses")
    rng = np.random.default_rng(seed)
    markers = {"m1": robot.tool} if not markers else dict(markers)
    robot = robot.replace(targets={**robot.targets, **markers})
    planted, truth = plant(robot, deviations, rng)
    q = random_joints(robot, n_poses, rng, joint_range)
    names = list(markers)
    on = marker_chains(robot, {n: m for n, (_, m) in cameras.items() if m is not None})
    points = marker_points(truth, q, names, on).reshape(-1, 3)
    mounts = {}
    for name, (camera, mount) in cameras.items():
        if mount is None:
            mount = CameraMount(0, facing(camera, points))
        elif mount.link > robot.n_joints:
            raise InputError(f"camera {name!r} is on link {mount.link}, but the robot has {robot.n_joints} joints",
                             option="camera")
        mounts[name] = mount
    truth = truth.replace(cameras=mounts)
    intrinsics = {name: camera for name, (camera, _) in cameras.items()}
    pose, rows_cam, rows_marker, rows_uv, rows_chain = camera_rows(truth, q, intrinsics, names, noise=pixel_noise,
                                                                   rng=rng, chains=on)
    for name in cameras:
        if name not in rows_cam:
            raise InputError(f"camera {name!r} sees no marker at any of the {n_poses} poses: place it elsewhere",
                             option="camera")
    order = np.argsort(pose, kind="stable")  # in the order the poses were taken
    meas = Measurements(q=q[pose[order]], position=np.full((len(pose), 3), np.nan),
                        targets=tuple(np.asarray(rows_marker, dtype=object)[order]), source="<simulated>",
                        pose_ids=tuple(str(int(i) + 1) for i in pose[order]),
                        pixels=rows_uv[order], camera=tuple(np.asarray(rows_cam, dtype=object)[order]),
                        intrinsics=intrinsics,
                        chain=None if robot.tree is None else tuple(np.asarray(rows_chain, dtype=object)[order]))
    return Simulation(meas, truth, planted)
