"""``robocal simulate``: measurements of a robot with planted deviations."""

from __future__ import annotations

from pathlib import Path

import typer

from .common import (
    base_link_option,
    camera_option,
    camera_pose_option,
    markers_option,
    quiet_flag,
    seed_option,
    tip_link_option,
)


def _degrees(values):
    import math

    return None if values is None else {j: math.radians(v) for j, v in values.items()}


def simulate_cmd(
    robot: str = typer.Argument(..., help="robot file or built-in name"),
    poses: int = typer.Option(32, "--poses", help="number of joint sets"),
    errors: str = typer.Option("none", "--errors", help="planted deviations: none | paper | uniform:LEN_MM,ANGLE_RAD"),
    noise: float = typer.Option(0.0, "--noise", help="position noise σ per axis, mm"),
    angle_noise: float = typer.Option(0.0, "--angle-noise", help="orientation noise σ per axis, deg"),
    joint_noise: float = typer.Option(0.0, "--joint-noise", help="Gaussian σ of actual − commanded joints, deg"),
    joint_noise_uniform: float = typer.Option(
        0.0, "--joint-noise-uniform", help="half-width of uniform actual − commanded joints, deg (Wen 2019: 5.7296)"
    ),
    measure: str = typer.Option("pose", "--measure", help="pose | position"),
    seed: int = seed_option("the planted errors, the joint sets and the noise"),
    joint_range: str | None = typer.Option(None, "--range", help="LO,HI deg for every joint (within limits)"),
    base: str | None = typer.Option(None, "--base", help="true measuring frame → base: x,y,z[,rx,ry,rz] mm, deg"),
    tool: str | None = typer.Option(None, "--tool", help="true flange → point: x,y,z[,rx,ry,rz] mm, deg"),
    compliance: str | None = typer.Option(
        None, "--compliance", help="planted joint compliance J=C[,J=C…], rad/(N·m); torques go to the file"),
    harmonic: list[str] | None = typer.Option(
        None, "--harmonic", help="planted transmission harmonic J:H=A,B: A cos(H q_J) + B sin(H q_J), deg "
        "(repeatable)"),
    backlash: str | None = typer.Option(
        None, "--backlash", help="planted backlash J=DEG[,J=DEG…]: joint J stands DEG off along its last move "
        "(rows are written in measuring order)"),
    drift: str | None = typer.Option(
        None, "--drift", help="planted drift J=DEG_PER_H[,…]: joint J's zero moves linearly in time (a time column "
        "is written)"),
    interval: float = typer.Option(10.0, "--interval", help="seconds between poses, for --drift"),
    contact: str | None = typer.Option(None, "--contact", help="points | planes: no tracker, the tool point touches "
                                       "unknown points (two sockets a setup) or planes; --poses per point or plane, "
                                       "--noise the play"),
    setups: int = typer.Option(4, "--setups", help="placements of the artefact, with --contact"),
    spacing: float = typer.Option(50.0, "--spacing", help="distance of the two sockets A and B, mm, with --contact "
                                  "points"),
    cameras: list[str] | None = camera_option("no tracker, this camera (its intrinsics file) sees the markers"),
    camera_pose: list[str] | None = camera_pose_option("where a camera is; default: a fixed camera facing the markers"),
    markers: Path | None = markers_option("with --camera (default: one marker, m1, at the tool point)"),
    pixel_noise: float = typer.Option(0.0, "--pixel-noise", help="pixel noise σ per coordinate, px, with --camera"),
    iso: Path | None = typer.Option(None, "--iso", help="an ISO 9283 command file (iso9283 plan, or its commands "
                                    "compensated): the true robot runs its rows' joints, written as a measured "
                                    "campaign iso9283 evaluate reads (--joint-noise: the robot's repeatability)"),
    base_link: str | None = base_link_option(),
    tip_link: str | None = tip_link_option(),
    out: Path = typer.Option(..., "--out", help="measurement CSV to write"),
    truth: Path | None = typer.Option(None, "--truth", help="true robot TOML to write"),
    quiet: bool = quiet_flag(),
) -> None:
    """Simulate measurements of a robot with planted deviations."""
    import math

    import numpy as np

    from .. import options as opt
    from ..io.atomic import atomic_write, together
    from ..io.measurements import measurements_to_csv
    from ..io.robotfile import load_robot, robot_to_toml
    from ..math.so3 import matrix_to_rpy
    from ..simulation import simulate
    from .common import check_outputs, console

    check_outputs((robot,) + ((iso,) if iso else ()), out=out, truth=truth)

    r = load_robot(robot, base_link=base_link, tip_link=tip_link)
    rng = None if joint_range is None else tuple(math.radians(v) for v in opt.floats(joint_range, "range", (2,)))
    if cameras:
        others = {"--contact": contact, "--noise": noise, "--angle-noise": angle_noise, "--joint-noise": joint_noise,
                  "--joint-noise-uniform": joint_noise_uniform, "--base": base, "--tool": tool,
                  "--compliance": compliance, "--harmonic": harmonic, "--backlash": backlash, "--drift": drift}
        given = [k for k, v in others.items() if v]
        if given:
            from ..exceptions import InputError

            raise InputError(f"{given[0]} is for tracker campaigns: a camera campaign plants geometry, the cameras' "
                             "poses and the pixel noise (--pixel-noise)", option="camera")
        sim = _camera_campaign(r, poses, cameras, camera_pose, markers, errors, pixel_noise, seed, rng)
    elif contact is not None:
        from ..simulation import simulate_contacts

        others = {"--angle-noise": angle_noise, "--joint-noise": joint_noise, "--joint-noise-uniform":
                  joint_noise_uniform, "--base": base, "--compliance": compliance, "--harmonic": harmonic,
                  "--backlash": backlash, "--drift": drift}
        given = [k for k, v in others.items() if v]
        if given:
            from ..exceptions import InputError

            raise InputError(f"{given[0]} is for tracker campaigns: a contact campaign plants geometry, a tool and "
                             "the play (--noise)", option="contact")
        sim = simulate_contacts(r, poses, setups=setups, contact=contact, spacing=spacing, deviations=errors,
                                noise=noise, seed=seed, tool=opt.frame_values(tool, "tool"), joint_range=rng)
    else:
        commands = None
        if iso is not None:
            if contact is not None or cameras:
                from ..exceptions import InputError

                raise InputError("an ISO 9283 campaign is measured by a tracker: no --contact or --camera",
                                 option="iso")
            from ..iso9283.files import load_commands

            commands = load_commands(iso, r.n_joints, r.prismatic if r.prismatic.any() else None)
            poses = len(commands[2])
        sim = simulate(r, poses, q=None if commands is None else commands[2], deviations=errors, noise=noise,
                       angle_noise=math.radians(angle_noise), joint_noise=math.radians(joint_noise),
                       joint_noise_uniform=math.radians(joint_noise_uniform),
                       measure=measure, seed=seed, joint_range=rng, base=opt.frame_values(base, "base"),
                       tool=opt.frame_values(tool, "tool"), compliance=opt.joint_values(compliance, "compliance"),
                       harmonics=opt.harmonic_specs(harmonic),
                       backlash=_degrees(opt.joint_values(backlash, "backlash")),
                       drift=_degrees(opt.joint_values(drift, "drift")), pose_interval=interval)
    if contact is None and not cameras and iso is not None:
        from ..iso9283.files import campaign_csv

        m = sim.measurements
        rpy = None if m.rotation is None else np.degrees(matrix_to_rpy(m.rotation))
        texts = {out: campaign_csv(commands[0], commands[1], m.position, rpy, commands[3])}
    else:
        texts = {out: measurements_to_csv(sim.measurements, prismatic=r.prismatic)}
    if truth is not None:
        planted = ", ".join(f"{k}={v:+.6g}" for k, v in sim.deviations.items() if v) or "none"
        if sim.truth.terms is not None:
            planted += "; joint terms (torque form) as in the joints below"
        texts[truth] = robot_to_toml(sim.truth.replace(name=f"{r.name} (simulated truth)"), comment=(
            f"True robot simulated by robocal from {robot} with errors {errors!r}, seed {seed}.\n"
            f"Planted deviations (mm, rad): {planted}" + _camera_lines(sim.truth)))
    with together():
        for path, text in texts.items():
            atomic_write(path, text)
    if not quiet:
        what = sim.measurements.describe() if sim.measurements.camera is not None or \
            sim.measurements.chain is not None else f"{sim.measurements.n_poses} poses"
        console().print(f"wrote {what} to {out}" + (f" and the true robot to {truth}" if truth else ""), markup=False)


def _camera_campaign(robot, poses, cameras, poses_given, markers, errors, pixel_noise, seed, joint_range):
    """The cameras' files and poses and the markers read, then :func:`robocal.simulation.simulate_cameras`."""
    from ..calibration.config import camera_poses, camera_specs
    from ..calibration.fit.cameras import load_markers
    from ..io.camera import load_camera
    from ..simulation import simulate_cameras

    specs = camera_specs(cameras)
    poses_given_of = camera_poses(tuple(poses_given or ()), specs).get
    setup = {spec.name: (load_camera(spec.path, spec.name), placed(robot, spec, poses_given_of(spec.name)))
             for spec in specs}
    return simulate_cameras(robot, poses, setup, markers=None if markers is None else load_markers(str(markers)).points,
                            deviations=errors, pixel_noise=pixel_noise, seed=seed, joint_range=joint_range)


def placed(robot, spec, values):
    """A camera's mounting where the command line places it (``values``: x, y, z mm, rx, ry, rz rad in its
    link's frame), or None: a fixed camera left to face the markers.  One on a link needs its place."""
    from ..calibration.fit.cameras import mount_of
    from ..exceptions import InputError
    from ..math.se3 import frame_from_values

    if values is None:
        mount = mount_of(robot, spec.name, spec.link)
        if mount.link > 0 and robot.urdf is not None and spec.link not in (robot.joint_names or ()) and \
                not str(spec.link).isdigit():
            return mount  # a URDF's link places it: the file's fixed joints are its pose
        if mount.link > 0:
            raise InputError(f"camera {spec.name!r} rides on link {spec.link}: give its pose there (--camera-pose "
                             f"{spec.name}=x,y,z,rx,ry,rz)", option="camera_pose")
        return None
    return mount_of(robot, spec.name, spec.link, frame_from_values(values))


def _camera_lines(truth) -> str:
    """The true cameras' poses, for the truth file's comment (a robot file does not hold cameras)."""
    import math

    from ..math.se3 import transform_to_xyz_rpy

    lines = []
    for name, mount in truth.cameras.items():
        xyz, rpy = transform_to_xyz_rpy(mount.pose)
        where = "the measuring frame" if mount.link == 0 else f"link {mount.link}"
        lines.append(f"\nCamera {name} in {where}: x,y,z,rx,ry,rz = "
                     + ",".join(f"{v:.6g}" for v in (*xyz, *(math.degrees(a) for a in rpy))) + " (mm, deg)")
    return "".join(lines)


def register(app: typer.Typer) -> None:
    app.command("simulate")(simulate_cmd)
