"""``robocal iso9283 …``: the ISO 9283 test: its poses for a robot, and its characteristics from measured cycles."""

from __future__ import annotations

from pathlib import Path

import typer

from .common import json_flag, quiet_flag, summary_option

app = typer.Typer(help="ISO 9283 pose and distance accuracy and repeatability.", no_args_is_help=True)


@app.command("plan")
def plan_cmd(
    robot: str = typer.Argument(..., help="robot file or built-in name (its nominal model: the controller's)"),
    cube_size: float | None = typer.Option(None, "--cube-size", help="edge of the test cube, mm (default: 0.15 × "
                                           "the arm's length scale)"),
    center: str | None = typer.Option(None, "--center", help="x,y,z of the cube's centre, mm, base frame (default: "
                                      "where the tool is at the start configuration)"),
    start: str | None = typer.Option(None, "--start", help="q1,…,qN deg: the configuration to plan from and whose "
                                     "tool orientation the poses keep (default: a well-conditioned one)"),
    cycles: int = typer.Option(30, "--cycles", help="cycles of P1..P5 (ISO 9283: 30)"),
    out: Path = typer.Option(..., "--out", help="command sequence CSV to write"),
    quiet: bool = quiet_flag(),
) -> None:
    """The five ISO 9283 poses in the test cube, checked for reach and limits, as a command sequence."""
    import math

    import numpy as np

    from .. import options as opt
    from ..io.atomic import atomic_write
    from ..io.robotfile import load_robot
    from ..iso9283.cube import plan_cube
    from ..iso9283.files import plan_csv
    from .common import check_outputs, console, table

    check_outputs((robot,), out=out)
    r = load_robot(robot)
    n = opt.integer(cycles, "cycles", minimum=2)
    centre = None if center is None else np.array(opt.floats(center, "center", (3,)))
    q0 = None if start is None else np.radians(opt.floats(start, "start", (r.n_joints,)))
    plan = plan_cube(r, cube_size, centre, q0)
    atomic_write(out, plan_csv(plan, n, r.prismatic if r.prismatic.any() else None))
    rpy = plan.rpy_deg()
    if quiet:
        return
    rows = [(label, *(f"{v:.2f}" for v in plan.position[k]), *(f"{math.degrees(v):.2f}" for v in plan.q[k]))
            for k, label in enumerate(plan.labels)]
    console().print(table(f"ISO 9283 test poses: cube of {plan.edge:.1f} mm, orientation rpy "
                          f"{', '.join(f'{v:.2f}' for v in rpy)} deg (base frame)",
                          ("pose", "x", "y", "z", *(f"q{i + 1}" for i in range(r.n_joints))), rows, text_columns=(0,)))
    console().print(f"wrote {n} cycles of P1..P5 ({n * len(plan.labels)} commands) to {out}")


@app.command("evaluate")
def evaluate_cmd(
    measured: list[Path] = typer.Argument(..., help="measured campaign CSV(s): pose, cycle, x, y, z [rx, ry, rz] and "
                                          "the commanded cx, cy, cz [crx, cry, crz] or q1..qN; several are shown "
                                          "side by side (before, after)"),
    robot: str | None = typer.Option(None, "--robot", help="robot whose nominal model gives the commanded poses of "
                                      "joint commands"),
    conditions: list[str] | None = typer.Option(None, "--conditions", help="the test conditions, KEY=VALUE[,…]: "
                                                "payload, speed, warmup, temperature, instrument, tcp (ISO 9283 §6) "
                                                "or others; in the report and the JSON; repeatable"),
    report: Path | None = typer.Option(None, "--report", help="HTML report to write"),
    as_json: bool = json_flag("the characteristics of every campaign"),
    summary: Path | None = summary_option("the characteristics"),
    require: list[str] | None = typer.Option(None, "--require", help="a specification the last campaign must "
                                             "meet, e.g. AP<=0.3,RP<=0.05 (mm; AP, RP: the largest over the "
                                             "poses; AD, RD: over the pairs); exit status 4 when not met"),
    quiet: bool = quiet_flag(),
) -> None:
    """Pose accuracy AP and repeatability RP, distance accuracy AD and repeatability RD (ISO 9283)."""
    import json

    from ..io.atomic import atomic_write, together
    from ..io.robotfile import load_robot
    from ..iso9283.characteristics import characteristics
    from ..iso9283.files import load_campaign
    from ..report.iso9283 import distance_rows, parse_conditions, pose_rows, write_iso9283_report
    from ..requirements import parse_requirements
    from .common import check_outputs, console, print_json, print_said, table, verdict

    checks = parse_requirements(require, "iso9283")
    stated = parse_conditions(conditions)
    check_outputs(tuple(measured) + ((robot,) if robot else ()), report=report, summary=summary)
    r = None if robot is None else load_robot(robot)
    results = [characteristics(load_campaign(path, r)) for path in measured]
    labels = [p for p in results[0].poses]
    for path, res in zip(measured[1:], results[1:]):
        if [p.pose for p in res.poses] != [p.pose for p in labels]:
            from ..exceptions import InputError

            raise InputError(f"poses {', '.join(p.pose for p in res.poses)} differ from the first campaign's "
                             f"({', '.join(p.pose for p in labels)})", source=str(path))
    document = [{**res.to_dict(), **({"conditions": stated} if stated else {})} for res in results]
    with together():
        if report is not None:
            import shlex
            import sys

            write_iso9283_report(results, [str(p) for p in measured], report, "robocal " + shlex.join(sys.argv[1:]),
                                 checks, robot, stated)
        if summary is not None:
            atomic_write(summary, json.dumps(document, indent=2) + "\n")
    print_said([n for res in results for n in res.notes], quiet)
    if as_json:
        print_json(document)
    elif not quiet:
        console().print(table("ISO 9283 pose characteristics", *pose_rows(results), text_columns=(0, 1)))
        console().print(table("ISO 9283 distance characteristics", *distance_rows(results), text_columns=(0, 1)))
    verdict(checks, results[-1].figures())


def register(app_: typer.Typer) -> None:
    app_.add_typer(app, name="iso9283")
