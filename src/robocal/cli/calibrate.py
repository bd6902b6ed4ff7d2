"""``robocal calibrate``: identify a robot's parameters from measured poses."""

from __future__ import annotations

from pathlib import Path

import typer

from .common import (
    base_link_option,
    camera_option,
    camera_pose_option,
    decimal_option,
    delimiter_option,
    euler_option,
    json_flag,
    markers_option,
    print_json,
    quiet_flag,
    seed_option,
    tip_link_option,
)


def timing_line(timings: dict) -> str:
    """Where the time went: "time 12.3 s: optimizers 1.35 s, model selection 9.45 s, …"."""
    labels = {"optimize_s": "optimizers", "model_s": "model selection", "statistics_s": "statistics",
              "load_s": "reading", "compile_s": "compiling", "evaluate_s": "evaluation"}
    parts = [f"{label} {timings[k]:.2f} s" for k, label in labels.items() if timings.get(k, 0) >= 0.005]
    return f"time {timings.get('total_s', 0.0):.2f} s: " + ", ".join(parts)

#: compile time above which the first run says where the time went (loading the cached kernels
#: takes well under this; compiling them after install, a few seconds)
COMPILE_SAID_S = 1.5

#: the config's fields an option of the same name sets (angle_noise in degrees here, rad there)
CONFIG_FIELDS = ("method", "frames", "params", "seed", "objective", "noise", "angle_noise", "k", "loss", "f_scale",
                 "particles", "iterations", "box", "halton", "backend", "model", "harmonics", "payload", "joint_unit",
                 "length_unit", "instrument", "delimiter", "decimal", "euler", "exclude", "point_distance",
                 "distance_sigma", "prior", "row_order", "cameras", "camera_poses", "markers", "pixel_noise",
                 "map_over")
#: the command's own options: its inputs and outputs, how to read them, and what it prints
CLI_ONLY = ("robot", "data", "validate", "out", "export", "report", "column", "base_link", "tip_link", "quiet",
            "position_only", "poses_out", "exclude_file", "as_json", "require")


def _print_summary(result, robot_name: str, data: str) -> None:
    from ..report.advice import next_steps
    from ..report.tables import (
        BUDGET_COLUMNS,
        FRAME_COLUMNS,
        LEARNED_COLUMNS,
        PARAMETER_COLUMNS,
        budget_rows,
        chain_table,
        frame_rows,
        ladder_columns,
        ladder_rows,
        learned_rows,
        noise_line,
        parameter_rows,
    )
    from .common import console, metrics_table, table

    out = console()
    out.print(f"[bold]{result.headline_text()}[/bold]")
    for step in next_steps(result):  # what the report's "What to do next" says, in the same words
        out.print(f"next: {step}", markup=False, highlight=False)
    out.print(metrics_table(f"{robot_name}: {result.method} on {data} ({result.measurements.describe()})",
                            result.accuracy_columns()))
    for key, figures in result.contact.items():
        out.print(f"points and planes touched, {key.replace('_', ' ')}: "
                  + ", ".join(f"{k.replace('_', ' ')} {v:.4f} mm" for k, v in figures.items()))
    for key, figures in result.cameras.items():  # the pixels apart where they are not the headline's
        if result.unit == "mm" or len(figures) > 2:
            out.print(f"camera rows, {key.replace('_', ' ')}: "
                      + ", ".join(f"{k.replace('_', ' ')} {v:.4f}" for k, v in figures.items()), markup=False)
    per_target = result.per_target_metrics()
    if per_target:
        keys = [k for k in ("before", "after", "validation_after") if all(k in m for m in per_target.values())]
        rows = [(t, str(m["after"].n), *(f"{m[k].position['rms']:.4f}" for k in keys)) for t, m in per_target.items()]
        title = "per marker: reprojection RMS (px)" if result.unit == "px" else "per reflector: position RMS (mm)"
        out.print(table(title, ("marker" if result.unit == "px" else "reflector", "points", *keys), rows,
                        text_columns=(0,)))
    title, columns, rows = chain_table(result)
    if rows:
        out.print(table(title, columns, rows, text_columns=(0,)))
    out.print(table("identified parameters (angles in degrees)", PARAMETER_COLUMNS, parameter_rows(result),
                    text_columns=(0, len(PARAMETER_COLUMNS) - 1)))
    out.print(table("frames", FRAME_COLUMNS, frame_rows(result), "left"))
    if result.model_selection:
        rows = ladder_rows(result)
        columns = ladder_columns(result)
        out.print(table(f"model selection: {result.selection_title}",
                        columns, rows, text_columns=(0, len(columns) - 1)))
    if result.error_budget:
        out.print(table("error budget on the validation poses: position RMS (mm), and per axis", BUDGET_COLUMNS,
                        budget_rows(result), text_columns=(0,)))
    if learned_rows(result):
        out.print(table("what the trees take on the calibration poses, and the joints they split on most",
                        LEARNED_COLUMNS, learned_rows(result), text_columns=(0, 2)))
    out.print(noise_line(result), markup=False)
    ident, opt = result.identifiability, result.optimization
    out.print(f"model {result.model}: " + f"{len(result.names)} parameters identified, {len(ident.dropped)} dropped"
              + (f" ({', '.join(ident.dropped)})" if ident.dropped else "")
              + f"; condition number {ident.condition:.3g}"
              + ("" if result.at_estimate is None else f" ({result.at_estimate.condition:.3g} at the estimate)")
              + (f"; held by their prior: {', '.join(result.held)}" if result.held else "")
              + f"; {opt.status} ({opt.method}) after {opt.nit} iterations, "
              f"{opt.nfev} evaluations", markup=False)
    out.print(timing_line(result.timings), markup=False)


def calibrate_cmd(
    robot: str = typer.Argument(..., help="nominal robot: file or built-in name"),
    data: list[Path] = typer.Argument(..., help="measurement CSV; several: each a session (or the sessions their "
                                      "session column names), calibrated together, held out in turn"),
    method: str = typer.Option("lm", "--method", help="lm | pso | ipso | ldpso-bt | hybrid"),
    validate: Path | None = typer.Option(None, "--validate", help="validation CSV (poses not used to identify)"),
    frames: str = typer.Option("auto", "--frames", help="auto | none | base | base+tool | tcp (auto: registered if "
                               "needed; tcp: the tool point alone, for rows that touched points or planes)"),
    seed: int = seed_option("every random choice: swarm starts, cross-validation folds, learned corrections"),
    params: str | None = typer.Option(
        None, "--params", help="candidate joint parameters: auto (every one; for camera rows chosen among frames, "
        "zeros and all by held-out data), all, zeros (each joint's zero), frames (none), wen2019 | kou2022, or a "
        "comma list (default: auto)"
    ),
    objective: str | None = typer.Option(None, "--objective", help="sum_squares | sum_norms (default: method's)"),
    noise: float | None = typer.Option(None, "--noise", help="measuring noise σ per axis, mm (default: estimated)"),
    angle_noise: float | None = typer.Option(
        None, "--angle-noise", help="orientation noise σ per axis, deg (default: estimated)"
    ),
    k: float | None = typer.Option(None, "--k", help="fixed orientation weight (σp/σr)², mm²/rad² (instead of "
                                   "--angle-noise)"),
    instrument: str | None = typer.Option(
        None, "--instrument", help="the instrument's MPE statement A+B/m: mm plus mm per metre of distance from it, "
        "taken as 2σ per axis (k=K for another coverage); sets each point's σ (files may give sx..srz instead)"),
    position_only: bool = typer.Option(False, "--position-only", help="ignore rx, ry, rz columns"),
    loss: str = typer.Option("linear", "--loss", help="LM loss: linear | huber | soft_l1 | cauchy | arctan"),
    f_scale: float = typer.Option(1.0, "--f-scale", help="robust loss scale, mm"),
    particles: int | None = typer.Option(None, "--particles", help="swarm size (default: the paper's)"),
    iterations: int | None = typer.Option(None, "--iterations", help="swarm generations (default: the paper's)"),
    box: str | None = typer.Option(None, "--box", help="swarm search half-widths LEN_MM,ANGLE_RAD"),
    halton: str = typer.Option("scrambled", "--halton", help="IPSO start: scrambled | plain"),
    backend: str = typer.Option("auto", "--backend", help="swarm objectives: auto | numba | numpy"),
    model: str = typer.Option("geometric", "--model", help="geometric | auto | TERM[+TERM…] with TERM compliance, "
                              "harmonics, backlash, drift, residual, trees (auto: chosen by 5-fold "
                              "cross-validation)"),
    harmonics: int = typer.Option(2, "--harmonics", help="harmonics per joint of the harmonics term"),
    payload: float | None = typer.Option(None, "--payload", help="payload mass, kg, for data without a payload "
                                         "column (centre of mass: the robot file's [gravity] payload_com)"),
    out: Path | None = typer.Option(None, "--out", help="result JSON to write"),
    export: list[Path] | None = typer.Option(None, "--export", help="the calibrated robot to write: a robot TOML "
                                             "(.toml, robocal's whole model), a URDF (.urdf) or a UR kinematics YAML "
                                             "(.yaml), each saying what its receiver gets; repeatable, one file per "
                                             "format"),
    report: Path | None = typer.Option(None, "--report", help="self-contained HTML report to write"),
    poses_out: Path | None = typer.Option(None, "--poses-out", help="per-pose errors CSV to write (calibration and "
                                          "validation poses, outliers and poses outside the region flagged)"),
    map_over: str = typer.Option("workspace", "--map-over", help="the report's uncertainty map: workspace (joint "
                                 "sets whose TCP lies in the box the measured poses span) | joints (anywhere in the "
                                 "calibrated joint ranges, in any combination)"),
    exclude: str | None = typer.Option(None, "--exclude", help="pose ids to leave out, ID[,ID…] (row N for files "
                                       "without pose_id)"),
    exclude_file: Path | None = typer.Option(None, "--exclude-file", help="a file of pose ids to leave out, one a "
                                             "line"),
    point_distance: list[str] | None = typer.Option(None, "--point-distance", help="A,B=MM: two points of each setup "
                                                    "stand MM apart (data whose rows touched points; repeatable)"),
    distance_sigma: float = typer.Option(0.05, "--distance-sigma", help="standard uncertainty of a stated distance, "
                                         "mm"),
    prior: list[str] | None = typer.Option(None, "--prior", help="what is known before measuring: KIND=WIDTH "
                                           "(length mm, angle, zero, compliance, harmonic, backlash, drift deg; all) "
                                           "or PARAMETER=WIDTH, or =free; over the robot file's [prior] and the "
                                           "defaults (length 1 mm, angle 0.1°, zero 1°); repeatable"),
    row_order: bool = typer.Option(False, "--row-order", help="the rows are in the order they were measured: drift "
                                   "may take time, and backlash the direction of approach, from it (without time or "
                                   "dir1..dirN columns)"),
    cameras: list[str] | None = camera_option("the intrinsics (OpenCV YAML/JSON or ROS camera_info) of a camera the "
                                              "data's camera rows name, fixed in the cell or on link K"),
    camera_poses: list[str] | None = camera_pose_option("a camera whose pose is known, not estimated"),
    markers: Path | None = markers_option("the markers' known offsets or sizes (else they are identified)"),
    pixel_noise: float | None = typer.Option(None, "--pixel-noise", help="σ of the camera rows' pixels, px (default: "
                                             "estimated)"),
    column: list[str] | None = typer.Option(None, "--column", help="map file columns: FILE=ROBOCAL[,FILE=ROBOCAL…]"),
    joint_unit: str | None = typer.Option(None, "--joint-unit", help="deg | rad (default: deg; radians read as "
                                          "degrees, and degrees as radians, are told by the robot's joint limits "
                                          "and refused)"),
    length_unit: str | None = typer.Option(None, "--length-unit", help="mm | m (default: mm, checked)"),
    delimiter: str = delimiter_option(),
    decimal: str = decimal_option(),
    euler: str = euler_option(),
    base_link: str | None = base_link_option(),
    tip_link: str | None = tip_link_option(),
    as_json: bool = json_flag("the result (what --out writes)"),
    require: list[str] | None = typer.Option(None, "--require", help="a verdict for CI: FIGURE<=VALUE (rms, max, "
                                             "cv_rms, validation_rms, validation_max; mm) or physical; not met: "
                                             "exit 4, named on stderr; repeatable"),
    quiet: bool = quiet_flag(),
) -> None:
    """Identify a robot's geometric parameters from measured poses."""
    # the options named like the config's fields are its fields (tests/unit/test_config.py
    # checks that every option is one or is listed as the command line's own)
    given = {k: v for k, v in locals().items() if k in CONFIG_FIELDS}
    import math
    import sys
    import warnings

    from .. import options as opt
    from ..calibration import CalibrationConfig, calibrate
    from ..calibration.fit.methods import settings
    from ..exceptions import InputError
    from ..io.atomic import together
    from ..io.robotfile import load_robot
    from ..requirements import parse_requirements
    from .common import check_outputs, print_notes, print_warnings, progress_bar, stage_status, verdict

    checks = parse_requirements(require, "calibrate")
    if validate is None and any(c.figure.startswith("validation") for c in checks):
        raise InputError("validation figures need validation poses: give --validate, or require cv_rms",
                         option="require")
    check_outputs((robot, *data, validate), out=out, export=export, report=report, poses_out=poses_out)
    if exclude_file is not None:
        from ..io.atomic import read_text

        listed = [line.split("#", 1)[0].strip() for line in read_text(exclude_file, "exclude file").splitlines()]
        listed = [x for x in listed if x]
        if not listed:
            raise InputError("lists no pose id (one a line; # starts a comment)", source=exclude_file,
                             option="exclude_file")
        given["exclude"] = ",".join([*(exclude.split(",") if exclude else []), *listed])
    given["point_distance"] = tuple(point_distance or ())
    given["prior"] = tuple(prior) if prior else None
    given["cameras"] = tuple(cameras or ())
    given["camera_poses"] = tuple(camera_poses or ())
    given["markers"] = None if markers is None else str(markers)
    cfg = CalibrationConfig(**{**given, "use_orientation": not position_only,
                               "angle_noise": None if angle_noise is None else math.radians(angle_noise)})
    nominal = load_robot(robot, base_link=base_link, tip_link=tip_link)
    total = None if method == "lm" else settings(cfg)["iterations"]
    with progress_bar(not quiet and method != "lm", method, total) as callback, \
            stage_status(not quiet and cfg.model == "auto") as stages, warnings.catch_warnings():
        warnings.simplefilter("ignore")
        result = calibrate(nominal, data[0] if len(data) == 1 else list(data), config=cfg, validate=validate,
                           columns=opt.column_map(column), progress=callback, stages=stages)
    with together():  # all or nothing: a failure leaves every earlier output as it was
        if out is not None:
            result.save(out)
        written = [result.export(path) for path in export or []]
        if report is not None:
            import shlex
            import sys

            from ..report.html import write_report

            write_report(result, report, "robocal " + shlex.join(sys.argv[1:]))
        if poses_out is not None:
            from ..io.atomic import atomic_write
            from ..io.table import rows_to_csv
            from ..model.metrics import pose_columns

            rows = result.per_pose()
            atomic_write(poses_out, rows_to_csv(rows, pose_columns(rows, any("sigma_mm" in r for r in rows))))
    print_warnings(result.warnings)
    print_notes(result.notes, quiet)
    compiled = result.timings.get("compile_s", 0.0)
    if compiled >= COMPILE_SAID_S:
        print_notes([f"compiled the numba kernels once ({compiled:.1f} s, not in time_s); later runs load them from "
                     "numba's cache"], quiet)
    if as_json:
        print_json(result.to_dict())
    elif not quiet:
        _print_summary(result, nominal.name, " + ".join(map(str, data)))
    chain_files = {f"{c}.toml" for c in (result.robot.tree.names if result.robot.tree else ())}
    for files in written if result.exports is not None else []:
        arms = [w for w in files[1:] if w.name.removeprefix(f"{files[0].stem}.") in chain_files]
        files = [w for w in files if w not in arms]
        sidecar = next((w for w in files[1:] if w.suffix == ".toml"), None)
        parts = "" if files[0].suffix.lower() in (".urdf", ".yaml", ".yml") or len(files) < 2 else \
            f" (with {' and '.join(map(str, files[1:]))} beside it: parts of the same model, keep them together)"
        print_notes([f"wrote {result.exports.sentence(files[0], sidecar)}{parts}"], quiet)
        if arms:
            print_notes([f"wrote each chain as its own robot file, for filter and compensate: "
                         f"{', '.join(map(str, arms))}"], quiet)
    verdict(checks, result.figures())


def register(app: typer.Typer) -> None:
    app.command("calibrate")(calibrate_cmd)
