"""``robocal evaluate``: error metrics of a model on measured data."""

from __future__ import annotations

from pathlib import Path

import typer

from .common import (
    base_link_option,
    camera_option,
    decimal_option,
    delimiter_option,
    euler_option,
    json_flag,
    markers_option,
    quiet_flag,
    tip_link_option,
)


def evaluate_cmd(
    robot: str = typer.Argument(..., help="robot file or built-in name"),
    data: Path = typer.Argument(..., help="measurement CSV"),
    base_link: str | None = base_link_option(),
    tip_link: str | None = tip_link_option(),
    as_json: bool = json_flag("the metrics"),
    frames: str = typer.Option("auto", "--frames", help="auto | none | base | base+tool: fit frames first (auto, as "
                               "in calibrate: registered when the data are not in the model's frame, and said)"),
    column: list[str] | None = typer.Option(None, "--column", help="map file columns: FILE=ROBOCAL[,FILE=ROBOCAL…]"),
    joint_unit: str | None = typer.Option(None, "--joint-unit", help="deg | rad (default: deg; radians read as "
                                          "degrees, and degrees as radians, are told by the robot's joint limits "
                                          "and refused)"),
    length_unit: str | None = typer.Option(None, "--length-unit", help="mm | m (default: mm)"),
    delimiter: str = delimiter_option(),
    decimal: str = decimal_option(),
    euler: str = euler_option(),
    payload: float | None = typer.Option(None, "--payload", help="payload mass, kg, for data without a payload "
                                         "column"),
    poses_out: Path | None = typer.Option(None, "--poses-out", help="per-pose errors CSV to write"),
    uncertainty: bool = typer.Option(False, "--uncertainty", help="also each pose's predicted position uncertainty "
                                     "(mm, from the parameter covariance a calibrated model carries)"),
    point_distance: list[str] | None = typer.Option(None, "--point-distance", help="A,B=MM: two points of each setup "
                                                    "stand MM apart (data whose rows touched points; repeatable)"),
    distance_sigma: float = typer.Option(0.05, "--distance-sigma", help="standard uncertainty of a stated distance, "
                                         "mm"),
    cameras: list[str] | None = camera_option("the intrinsics of a camera the data's camera rows name (its pose is "
                                              "the model's: a calibration's export carries it)"),
    markers: Path | None = markers_option("the markers' offsets the model does not carry"),
    require: list[str] | None = typer.Option(None, "--require", help="a verdict for CI: FIGURE<=VALUE (rms, mean, "
                                             "max, std; point_spread_rms, distance_error_rms, plane_rms for contact "
                                             "data; mm); not met: exit 4, named on stderr; repeatable"),
    quiet: bool = quiet_flag(),
) -> None:
    """Error metrics (MODEL §6) of a robot model on measured data."""
    import json

    from .. import options as opt
    from ..evaluation import evaluate
    from ..requirements import parse_requirements
    from .common import check_outputs, load, print_said, verdict

    checks = parse_requirements(require, "evaluate")
    check_outputs((robot, data, markers), poses_out=poses_out)
    ev = evaluate(load(robot, base_link, tip_link), data, columns=opt.column_map(column), frames=frames,
                  joint_unit=joint_unit, length_unit=length_unit, payload=payload, uncertainty=uncertainty,
                  delimiter=delimiter, decimal=decimal, euler=euler, point_distance=tuple(point_distance or ()),
                  distance_sigma=distance_sigma, cameras=tuple(cameras or ()),
                  markers=None if markers is None else str(markers))
    print_said(ev.notes, quiet)
    if poses_out is not None:
        from ..io.atomic import atomic_write
        from ..io.table import rows_to_csv
        from ..model.metrics import pose_columns

        columns = pose_columns(ev.pose_rows, ev.sigma is not None)
        atomic_write(poses_out, rows_to_csv(ev.pose_rows, columns))
    if as_json:
        print(json.dumps(ev.to_dict(), indent=2))
    elif not quiet:
        _print_tables(ev, robot, data)
    figures = {k: ev.metrics.position[k] for k in ("rms", "mean", "std", "max")}
    verdict(checks, {**figures, **{k: ev.contact.get(k, float("nan")) for k in
                                   ("point_spread_rms", "distance_error_rms", "plane_rms")}})


def _print_tables(ev, robot, data) -> None:
    from .common import console, metrics_table

    what = ev.described or f"{ev.metrics.n} poses"
    title = f"{robot} on {data} ({what}{'' if ev.frames == 'none' else ', frames ' + ev.frames})"
    columns = {"error": ev.metrics, **(ev.per_target if len(ev.per_target) > 1 else {}),
               **(ev.per_camera if len(ev.per_camera) > 1 else {})}
    console().print(metrics_table(title, columns))
    if ev.contact:
        console().print("points and planes touched: " + ", ".join(f"{k.replace('_', ' ')} {v:.4f} mm"
                                                                  for k, v in ev.contact.items()))
    if ev.sigma is not None:
        _print_uncertainty(ev)


#: poses listed one by one; beyond, the largest ones (--json gives them all)
LISTED = 30


def _print_uncertainty(ev) -> None:
    import numpy as np

    from .common import console, table

    s = ev.uncertainty_summary()
    order = np.argsort(-ev.sigma)
    shown = order if len(order) <= LISTED else order[:10]
    title = ("predicted position uncertainty (mm, 1σ)" if len(order) <= LISTED
             else f"the 10 largest of {len(order)} (mm, 1σ)")
    console().print(table(title, ("pose", "σ (mm)"), [(ev.poses[i], f"{ev.sigma[i]:.4f}") for i in sorted(shown)],
                          text_columns=(0,)))
    console().print(f"predicted position uncertainty (1σ, rms radius: the parameters' covariance and the residual "
                    f"process's variance): "
                    f"median {s['median_mm']:.4f} mm, 95 % of poses below {s['p95_mm']:.4f} mm, largest "
                    f"{s['max_mm']:.4f} mm" + ("" if len(order) <= LISTED else "; --json lists every pose"))


def register(app: typer.Typer) -> None:
    app.command("evaluate")(evaluate_cmd)
