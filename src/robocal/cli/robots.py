"""``robocal robots``: the built-in robots."""

from __future__ import annotations

from pathlib import Path

import typer

from .common import json_flag, quiet_flag


def robots_cmd(
    urdf: str | None = typer.Option(None, "--urdf", metavar="ROBOT",
                                    help="print this robot (built-in name or file) as URDF instead"),
    from_ur: Path | None = typer.Option(None, "--from-ur", help="read a UR controller's calibration: its kinematics "
                                        "YAML (as the UR ROS drivers extract it) or its DH deltas (calibration.conf, "
                                        "with --nominal)"),
    nominal: str | None = typer.Option(None, "--nominal", help="the nominal standard-DH model DH deltas apply to "
                                       "(e.g. ur10)"),
    out: Path | None = typer.Option(None, "--out", help="robot file to write (default: print it)"),
    as_json: bool = json_flag("the list of built-in robots"),
    quiet: bool = quiet_flag(),
) -> None:
    """List the built-in robots and the published source of each table, print one as URDF, or
    read a UR controller's calibration as a robot file."""
    if from_ur is not None:
        _from_ur(from_ur, nominal, out, quiet)
        return
    if urdf is not None:
        from ..io.robotfile import load_robot
        from ..io.urdf import urdf_text

        robot = load_robot(urdf)
        print(urdf_text(robot, comment=f"{robot.name}, written by robocal from {robot.source or urdf}; lengths in m, "
                                       "angles in rad; measuring_frame and target carry the robot file's base and "
                                       "tool"), end="")
        return
    from ..io.builtins import builtin_summaries
    from .common import console, print_json, table

    if as_json:
        print_json(builtin_summaries())
        return
    if quiet:
        return
    rows = [(r["name"], r["robot"], r["convention"], str(r["joints"]), r["source"]) for r in builtin_summaries()]
    console().print(table("built-in robots", ("name", "robot", "convention", "joints", "source"), rows, "left"))


def _from_ur(path: Path, nominal: str | None, out: Path | None, quiet: bool = False) -> None:
    from ..exceptions import InputError
    from ..io.atomic import atomic_write, read_text
    from ..io.robotfile import load_robot, robot_to_toml
    from ..io.ur import parse_ur_deltas, parse_ur_kinematics
    from .common import check_outputs, console

    check_outputs((path,) + ((nominal,) if nominal else ()), out=out)
    text = read_text(path, "UR calibration file")
    if path.suffix.lower() in (".yaml", ".yml"):
        robot = parse_ur_kinematics(text, source=str(path))
    elif nominal is None:
        raise InputError("DH deltas are added to a nominal model: name it with --nominal (e.g. ur10)", source=path)
    else:
        robot = parse_ur_deltas(text, load_robot(nominal), source=str(path))
    toml = robot_to_toml(robot, comment=f"{robot.name}, read by robocal from {path}")
    if out is None:
        print(toml, end="")
    else:
        atomic_write(out, toml)
        if not quiet:
            console().print(f"wrote {out}")


def register(app: typer.Typer) -> None:
    app.command("robots")(robots_cmd)
