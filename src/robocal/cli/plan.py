"""``robocal plan``: choose the poses worth measuring."""

from __future__ import annotations

from pathlib import Path

import typer

from .common import (
    base_link_option,
    camera_option,
    camera_pose_option,
    json_flag,
    markers_option,
    quiet_flag,
    seed_option,
    summary_option,
    tip_link_option,
)


def _print_plan(p, r, poses: int, candidates: int, criterion: str, measure: str, noise: float, angle_noise: float):
    import math

    import numpy as np

    from ..model.parameters import is_angle
    from .common import console, table

    c = console()
    c.print(table(f"{r.name}: {poses} of {candidates} candidates, criterion {criterion}, {measure}",
                  ("", "criterion", "predicted validation RMS (mm)"),
                  [("plan", f"{p.value:.6g}", f"{p.predicted_rms:.5f}"),
                   (f"median of {len(p.random_rms)} random sets", f"{np.median(p.random_values):.6g}",
                    f"{np.median(p.random_rms):.5f}")]))
    worst = np.argsort(-p.predicted_std / np.where([is_angle(n) for n in p.names], 1 / r.reach(), 1.0))[:3]
    advice = ""
    if measure == "pose":
        advice = f"; calibrate with --noise {noise:g} --angle-noise {angle_noise:g} to weigh the data as planned"
    if p.model_error > 0:
        c.print(f"expected validation RMS {p.expected_rms:.4f} mm: {p.predicted_rms:.4f} mm from what these poses "
                f"leave of the parameters, and {math.sqrt(3) * p.model_error:.4f} mm (3 axes × {p.model_error:g} mm) "
                "the model cannot take, whatever the poses")
    else:
        c.print(f"predicted validation RMS {p.predicted_rms:.4f} mm counts the measuring noise only: what the model "
                "cannot take (about half a millimetre of a real arm's geometric fit) comes on top; state it with "
                "--model-error")
    from ..report.tables import shown_sigma

    c.print("least determined: " + ", ".join(f"{p.names[i]} {shown_sigma(p.names[i], p.predicted_std[i])}"
                                             for i in worst) + advice)


def plan_cmd(
    robot: str = typer.Argument(..., help="robot file or built-in name"),
    poses: int = typer.Option(30, "--poses", help="number of poses to measure (with --socket: for each socket)"),
    candidates: int = typer.Option(2000, "--candidates", help="random joint sets to choose from"),
    criterion: str = typer.Option("O1", "--criterion", help="O1 | O2 | O3 | O4 | D"),
    measure: str = typer.Option("pose", "--measure", help="pose | position"),
    frames: str = typer.Option("base+tool", "--frames", help="none | base | base+tool (the frames the calibration "
                               "will fit; base+tool when the tracker's place and the tool are not known; no auto: "
                               "before measuring, no data tell it)"),
    joint_range: str | None = typer.Option(None, "--range", help="LO,HI deg for every joint"),
    limits: str | None = typer.Option(None, "--limits", help="per joint lo:hi deg, comma-separated (work cell)"),
    noise: float = typer.Option(0.02, "--noise", help="position noise σ, mm"),
    angle_noise: float = typer.Option(0.001, "--angle-noise", help="orientation noise σ, deg"),
    seed: int = seed_option("the candidate joint sets drawn"),
    workspace: str | None = typer.Option(None, "--workspace", help="xmin:xmax,ymin:ymax,zmin:zmax (mm, base frame): "
                                         "where the tool may go"),
    tracker: str | None = typer.Option(None, "--tracker", help="x,y,z of the tracker (mm, base frame): poses keep "
                                       "the reflector facing it"),
    fov: float = typer.Option(90.0, "--fov", help="the reflector's acceptance cone, full angle (deg), with --tracker"),
    model_error: float = typer.Option(0.0, "--model-error", help="σ per axis (mm) of what the model cannot take "
                                      "(e.g. an earlier calibration's scatter beyond the instrument), stated apart"),
    socket: list[str] | None = typer.Option(None, "--socket", help="x,y,z (mm, the robot's base frame) of a socket "
                                            "the tool point (a ball) will touch: --poses configurations for each, "
                                            "for calibration without a tracker (repeatable)"),
    cameras: list[str] | None = camera_option("plan images for this camera (its intrinsics) instead of a tracker"),
    camera_pose: list[str] | None = camera_pose_option("where a camera is, the measuring frame being the robot's "
                                                       "base here; default: a fixed camera facing the markers"),
    markers: Path | None = markers_option("known markers (default: one unknown marker at the tool point)"),
    pixel_noise: float = typer.Option(0.5, "--pixel-noise", help="pixel noise σ, px, with --camera"),
    base_link: str | None = base_link_option(),
    tip_link: str | None = tip_link_option(),
    out: Path = typer.Option(..., "--out", help="measurement-file skeleton to write (pose_id, q1..qn; with --socket "
                                                "q1..qn, point, setup; with --camera the joint log robocal detect "
                                                "reads: pose_id, image, q1..qn)"),
    as_json: bool = json_flag("the plan report"),
    report: Path | None = summary_option("the plan report"),
    quiet: bool = quiet_flag(),
) -> None:
    """Choose the joint sets worth measuring (greedy + exchange on an observability criterion)."""
    import json
    import math

    import numpy as np

    from .. import options as opt
    from ..io.atomic import atomic_write, together
    from ..io.measurements import joints_to_file
    from ..io.robotfile import load_robot
    from ..plan import plan_poses
    from .common import check_outputs, console, print_json

    check_outputs((robot,), out=out, summary=report)

    r = load_robot(robot, base_link=base_link, tip_link=tip_link)
    jr = opt.joint_limits(limits, r.n_joints)
    if jr is None and joint_range is not None:
        jr = tuple(math.radians(v) for v in opt.floats(joint_range, "range", (2,)))
    box = None
    if workspace is not None:
        box = opt.joint_limits(workspace, 3, "workspace")
        box = None if box is None else np.degrees(box)  # joint_limits reads degrees; these are mm
    at = None if tracker is None else np.array(opt.floats(tracker, "tracker", (3,)))
    opt.number(fov, "fov", minimum=0.0, strict=True)
    opt.number(model_error, "model_error", minimum=0.0)
    if socket:
        _plan_sockets(r, socket, poses, candidates, seed, jr, out, report, as_json, quiet)
        return
    if cameras:
        _plan_cameras(r, cameras, camera_pose, markers, pixel_noise, poses, candidates, seed, jr, out, report,
                      as_json, quiet)
        return
    p = plan_poses(r, poses, candidates=candidates, criterion=criterion, measure=measure, frames=frames,
                   joint_range=jr, noise=noise, angle_noise=math.radians(angle_noise), seed=seed, workspace=box,
                   tracker=at, fov=fov, model_error=model_error)
    lines = ["pose_id," + ",".join(f"q{i + 1}" for i in range(r.n_joints))]
    lines += [f"P{j + 1:03d}," + ",".join(f"{v:.6f}" for v in joints_to_file(q, r.prismatic))
              for j, q in enumerate(p.q)]
    with together():
        atomic_write(out, "\n".join(lines) + "\n")
        if report is not None:
            atomic_write(report, json.dumps(p.to_dict(), indent=1) + "\n")
    if as_json:
        print_json(p.to_dict())
    elif not quiet:
        _print_plan(p, r, poses, candidates, criterion, measure, noise, angle_noise)
        console().print(f"wrote {out}")


def _plan_sockets(r, sockets, poses, candidates, seed, jr, out, report, as_json, quiet) -> None:
    """Configurations to record at each socket (see :mod:`robocal.plan.contacts`)."""

    from .. import options as opt
    from ..io.measurements import joints_to_file
    from ..plan.contacts import plan_contacts

    places = [opt.floats(s, "socket", (3,)) for s in sockets]
    p = plan_contacts(r, places, poses, candidates=min(candidates, 500), seed=seed, joint_range=jr)
    lines = [",".join(f"q{i + 1}" for i in range(r.n_joints)) + ",point,setup"]
    lines += [",".join(f"{v:.6f}" for v in joints_to_file(q, r.prismatic)) + f",socket{k + 1},S1"
              for q, k in zip(p.q, p.socket)]
    document = p.summary()
    _write(lines, document, out, report, as_json, quiet, lambda: (
        f"{len(p.q)} configurations, {len(p.q) // max(len(places), 1)} at each of {len(places)} socket(s) "
        f"({', '.join(map(str, p.reachable))} distinct reaching configurations drawn): log det of the information "
        f"per parameter {p.value:.3f} against {document['random_median']:.3f} for the median of "
        f"{len(p.random_values)} random choices; wrote {out}"))


def _write(lines, document, out, report, as_json, quiet, said) -> None:
    """A plan's file and its report, all or nothing; then its JSON or what ``said()`` says."""
    import json

    from ..io.atomic import atomic_write, together
    from .common import console, print_json

    with together():
        atomic_write(out, "\n".join(lines) + "\n")
        if report is not None:
            atomic_write(report, json.dumps(document, indent=1) + "\n")
    if as_json:
        print_json(document)
    elif not quiet:
        console().print(said(), markup=False)


def _plan_cameras(r, cameras, camera_pose, markers, pixel_noise, poses, candidates, seed, jr, out, report, as_json,
                  quiet) -> None:
    """Images to take (see :mod:`robocal.plan.cameras`): the joint log of the chosen poses."""

    from .. import options as opt
    from ..calibration.config import camera_poses, camera_specs
    from ..calibration.fit.cameras import load_markers
    from ..io.camera import load_camera
    from ..io.measurements import joints_to_file
    from ..plan.cameras import plan_camera_poses
    from .simulate import placed as _placed

    specs = camera_specs(cameras)
    placed = camera_poses(tuple(camera_pose or ()), specs)
    setup = {}
    for spec in specs:
        setup[spec.name] = (load_camera(spec.path, spec.name), _placed(r, spec, placed.get(spec.name)))
    known = None if markers is None else load_markers(str(markers)).points
    opt.number(pixel_noise, "pixel_noise", minimum=0.0, strict=True)
    p = plan_camera_poses(r, poses, setup, markers=known, markers_known=known is not None, candidates=candidates,
                          pixel_noise=pixel_noise, seed=seed, joint_range=jr)
    lines = ["pose_id,image," + ",".join(f"q{i + 1}" for i in range(r.n_joints))]
    lines += [f"P{j + 1:03d},P{j + 1:03d}.png," + ",".join(f"{v:.6f}" for v in joints_to_file(q, r.prismatic))
              for j, q in enumerate(p.q)]
    document = p.summary()
    _write(lines, document, out, report, as_json, quiet, lambda: (
        f"{len(p.q)} poses, {int(p.rows.sum())} camera rows expected ({p.in_view[0]} of {p.in_view[1]} candidates "
        f"see a marker): log det of the information per parameter {p.value:.3f} against "
        f"{document['random_median']:.3f} for the median of {len(p.random_values)} random sets; wrote {out} (the "
        "joint log robocal detect reads: name each image as its row says)"))


def register(app: typer.Typer) -> None:
    app.command("plan")(plan_cmd)
