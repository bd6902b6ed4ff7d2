"""The ``robocal`` command line: a thin layer over the Python API.

Bad input never produces a traceback: :class:`~robocal.errors.InputError` and
command-line misuse become one line on stderr and exit code 2.
"""

from __future__ import annotations

import contextlib
import json
import math
import sys
import warnings
from pathlib import Path

import numpy as np
import typer
from rich.console import Console
from rich.table import Table

from .errors import InputError, atomic_write
from .measurements import load_measurements, measurements_to_csv
from .metrics import Metrics
from .objectives import DEFAULT_K
from .optimizers import METHODS
from .parameters import is_angle
from .robotfile import builtin_names, builtin_source, load_robot, robot_to_toml
from .simulate import simulate as run_simulation

app = typer.Typer(
    add_completion=False,
    no_args_is_help=True,
    help="Geometric calibration and error compensation of robots.",
    pretty_exceptions_enable=False,
)
# tables stay readable when the output goes to a file or a pipe
console = Console(width=None if sys.stdout.isatty() else 140)


def _floats(text: str | None, what: str, sizes: tuple[int, ...]) -> list[float] | None:
    if text is None:
        return None
    try:
        values = [float(v) for v in text.split(",")]
    except ValueError:
        raise InputError(
            f"expected {' or '.join(map(str, sizes))} comma-separated numbers, got {text!r}", source=what
        ) from None
    if len(values) not in sizes or not all(math.isfinite(v) for v in values):
        raise InputError(
            f"expected {' or '.join(map(str, sizes))} finite comma-separated numbers, got {text!r}", source=what
        )
    return values


def _frame_arg(text: str | None, what: str):
    v = _floats(text, what, (3, 6))
    if v is None:
        return None
    return tuple(v[:3] + [math.radians(a) for a in v[3:]])


def _column_map(items: list[str] | None) -> dict[str, str] | None:
    if not items:
        return None
    out = {}
    for item in items:
        if "=" not in item:
            raise InputError(f"expected FILE_COLUMN=ROBOCAL_COLUMN, got {item!r}", source="--column")
        old, new = item.split("=", 1)
        out[old.strip()] = new.strip()
    return out


def metrics_table(title: str, columns: dict[str, Metrics]) -> Table:
    """A before/after style table: one column per metrics set."""
    table = Table(title=title)
    table.add_column("error")
    for name in columns:
        table.add_column(name, justify="right")
    rows = [m.rows() for m in columns.values()]
    for i, (label, _) in enumerate(rows[0]):
        table.add_row(label, *(f"{r[i][1]:.4f}" for r in rows))
    return table


@app.command("robots")
def robots_cmd() -> None:
    """List the built-in robots."""
    table = Table(title="built-in robots")
    for col in ("name", "robot", "convention", "joints", "source"):
        table.add_column(col)
    for name in builtin_names():
        r = load_robot(name)
        table.add_row(name, r.name, r.convention, str(r.n_joints), builtin_source(name))
    console.print(table)


@app.command("simulate")
def simulate_cmd(
    robot: str = typer.Argument(..., help="robot file or built-in name"),
    poses: int = typer.Option(32, "--poses", help="number of joint sets"),
    errors: str = typer.Option("none", "--errors", help="none | paper | uniform:LEN_MM,ANGLE_RAD"),
    noise: float = typer.Option(0.0, "--noise", help="position noise σ per axis, mm"),
    angle_noise: float = typer.Option(0.0, "--angle-noise", help="orientation noise σ per axis, deg"),
    joint_noise: float = typer.Option(0.0, "--joint-noise", help="Gaussian σ of actual − commanded joints, deg"),
    joint_noise_uniform: float = typer.Option(
        0.0, "--joint-noise-uniform", help="half-width of uniform actual − commanded joints, deg (Wen 2019: 5.7296)"
    ),
    measure: str = typer.Option("pose", "--measure", help="pose | position"),
    seed: int = typer.Option(0, "--seed"),
    joint_range: str | None = typer.Option(None, "--range", help="LO,HI deg for every joint (within limits)"),
    base: str | None = typer.Option(None, "--base", help="true measuring frame → base: x,y,z[,rx,ry,rz] mm, deg"),
    tool: str | None = typer.Option(None, "--tool", help="true flange → point: x,y,z[,rx,ry,rz] mm, deg"),
    out: Path = typer.Option(..., "--out", help="measurement CSV to write"),
    truth: Path | None = typer.Option(None, "--truth", help="true robot TOML to write"),
) -> None:
    """Simulate measurements of a robot with planted errors."""
    for name, value in (
        ("--noise", noise),
        ("--angle-noise", angle_noise),
        ("--joint-noise", joint_noise),
        ("--joint-noise-uniform", joint_noise_uniform),
    ):
        if not math.isfinite(value) or value < 0:
            raise InputError(f"must be a finite value ≥ 0, got {value}", source=name)
    if poses < 1:
        raise InputError(f"need at least 1 pose, got {poses}", source="--poses")
    rng = _floats(joint_range, "--range", (2,))
    r = load_robot(robot)
    sim = run_simulation(
        r,
        poses,
        errors=errors,
        noise=noise,
        angle_noise=math.radians(angle_noise),
        joint_noise=math.radians(joint_noise),
        joint_noise_uniform=math.radians(joint_noise_uniform),
        measure=measure,
        seed=seed,
        joint_range=None if rng is None else (math.radians(rng[0]), math.radians(rng[1])),
        base=_frame_arg(base, "--base"),
        tool=_frame_arg(tool, "--tool"),
    )
    csv_text = measurements_to_csv(sim.measurements)
    truth_text = None
    if truth is not None:
        planted = ", ".join(f"{k}={v:+.6g}" for k, v in sim.errors.items() if v) or "none"
        truth_text = robot_to_toml(
            sim.truth.replace(name=f"{r.name} (simulated truth)"),
            comment=f"True robot simulated by robocal from {robot} with errors {errors!r}, seed {seed}.\n"
            f"Planted errors (mm, rad): {planted}",
        )
    atomic_write(out, csv_text)
    if truth_text is not None:
        atomic_write(truth, truth_text)
    console.print(
        f"wrote {sim.measurements.n_poses} poses to {out}" + (f" and the true robot to {truth}" if truth else "")
    )


@app.command("evaluate")
def evaluate_cmd(
    robot: str = typer.Argument(..., help="robot file or built-in name"),
    data: Path = typer.Argument(..., help="measurement CSV"),
    as_json: bool = typer.Option(False, "--json", help="print the metrics as JSON"),
    column: list[str] | None = typer.Option(None, "--column", help="map a file column: FILE=ROBOCAL (repeatable)"),
) -> None:
    """Error metrics (SPEC §8) of a robot model on measured data."""
    r = load_robot(robot)
    meas = load_measurements(data, n_joints=r.n_joints, columns=_column_map(column), robot_label=r.source)
    try:
        metrics = Metrics.of(r, meas)
    except ValueError as exc:
        raise InputError(str(exc), source=str(data)) from None
    if as_json:
        print(json.dumps(metrics.to_dict(), indent=2))
    else:
        console.print(metrics_table(f"{r.name} on {data} ({meas.n_poses} poses)", {"error": metrics}))


def _progress_bar(quiet: bool, label: str):
    """A rich progress bar for swarm generations, or nothing when quiet."""
    if quiet or not sys.stderr.isatty():
        return contextlib.nullcontext(None)
    from rich.progress import BarColumn, Progress, TextColumn, TimeRemainingColumn

    return Progress(
        TextColumn(f"[bold]{label}"),
        BarColumn(),
        TextColumn("{task.completed}/{task.total}"),
        TextColumn("best {task.fields[best]:.6g}"),
        TimeRemainingColumn(),
        console=Console(stderr=True),
        transient=True,
    )


def _warn(messages: list[str]) -> None:
    for m in messages:
        print(f"robocal: warning: {_one_line(m)}", file=sys.stderr)


@app.command("calibrate")
def calibrate_cmd(
    robot: str = typer.Argument(..., help="nominal robot: file or built-in name"),
    data: Path = typer.Argument(..., help="measurement CSV"),
    method: str = typer.Option("lm", "--method", help="lm | pso | ipso | ldpso-bt | hybrid"),
    validate: Path | None = typer.Option(None, "--validate", help="validation CSV (poses not used to identify)"),
    frames: str = typer.Option("none", "--frames", help="none | base | base+tool"),
    seed: int = typer.Option(0, "--seed"),
    params: str | None = typer.Option(
        None, "--params", help="candidate joint parameters: comma list, or wen2019 | kou2022 (default: all)"
    ),
    objective: str | None = typer.Option(None, "--objective", help="sum_squares | sum_norms (default: method's)"),
    k: float = typer.Option(DEFAULT_K, "--k", help="orientation weight of the pose objective, mm²/rad²"),
    position_only: bool = typer.Option(False, "--position-only", help="ignore rx, ry, rz columns"),
    loss: str = typer.Option("linear", "--loss", help="LM loss: linear | huber | soft_l1 | cauchy"),
    f_scale: float = typer.Option(1.0, "--f-scale", help="robust loss scale, mm"),
    particles: int | None = typer.Option(None, "--particles", help="swarm size (default: the paper's)"),
    iterations: int | None = typer.Option(None, "--iterations", help="swarm generations (default: the paper's)"),
    box: str | None = typer.Option(None, "--box", help="swarm search half-widths LEN_MM,ANGLE_RAD"),
    halton: str = typer.Option("scrambled", "--halton", help="IPSO start: scrambled | plain"),
    out: Path | None = typer.Option(None, "--out", help="result JSON to write"),
    export: Path | None = typer.Option(None, "--export", help="calibrated robot TOML to write"),
    report: Path | None = typer.Option(None, "--report", help="self-contained HTML report to write"),
    column: list[str] | None = typer.Option(None, "--column", help="map a file column: FILE=ROBOCAL (repeatable)"),
    quiet: bool = typer.Option(False, "--quiet", "-q", help="no table, no progress bar"),
) -> None:
    """Identify a robot's geometric parameters from measured poses."""
    from .calibration import calibrate

    if method not in METHODS:
        raise InputError(f"unknown method {method!r} (expected {' | '.join(METHODS)})", source="--method")
    if halton not in ("scrambled", "plain"):
        raise InputError(f"expected scrambled or plain, got {halton!r}", source="--halton")
    for name, value in (("--particles", particles), ("--iterations", iterations)):
        if value is not None and value < 1:
            raise InputError(f"must be ≥ 1, got {value}", source=name)
    if not (math.isfinite(f_scale) and f_scale > 0):
        raise InputError(f"must be a finite value > 0, got {f_scale}", source="--f-scale")
    box_v = _floats(box, "--box", (2,))
    if box_v is not None and min(box_v) <= 0:
        raise InputError(f"half-widths must be > 0, got {box}", source="--box")
    nominal = load_robot(robot)
    cols = _column_map(column)
    meas = load_measurements(data, n_joints=nominal.n_joints, columns=cols, robot_label=nominal.source)
    val = (
        None
        if validate is None
        else load_measurements(validate, n_joints=nominal.n_joints, columns=cols, robot_label=nominal.source)
    )
    # LM on a few thousand poses takes well under a second; beyond that show it working
    with _progress_bar(quiet or (method == "lm" and meas.n_poses < 5000), method) as bar:
        callback = None
        if bar is not None:
            task = bar.add_task(method, total=iterations, best=float("nan"))

            def callback(t, total, best):
                bar.update(task, completed=t, total=total or None, best=best)

        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            result = calibrate(
                nominal, meas, method, frames=frames, params=params, validate=val, seed=seed, objective=objective,
                k=k, use_orientation=not position_only, loss=loss, f_scale=f_scale, particles=particles,
                iterations=iterations, box=None if box_v is None else (box_v[0], box_v[1]),
                swarm_options={"halton_scramble": halton == "scrambled"}, progress=callback,
            )  # fmt: skip
    if out is not None:
        result.save(out)
    if export is not None:
        result.export(export)
    if report is not None:
        from .report import write_report

        write_report(result, report)
    _warn(result.warnings)
    if not quiet:
        cols_m = {"before": result.metrics["before"], "after": result.metrics["after"]}
        if "validation_before" in result.metrics:
            cols_m["validation before"] = result.metrics["validation_before"]
            cols_m["validation after"] = result.metrics["validation_after"]
        console.print(metrics_table(f"{nominal.name}: {method} on {data} ({result.n_poses} poses)", cols_m))
        ident = result.identifiability
        console.print(
            f"{len(result.names)} parameters identified, {len(ident.dropped)} dropped"
            + (f" ({', '.join(ident.dropped)})" if ident.dropped else "")
            + f"; condition number {ident.condition:.3g}; {result.optimisation.status} after "
            f"{result.optimisation.nit} iterations, {result.optimisation.nfev} evaluations, {result.time_s:.2f} s"
        )


@app.command("compensate")
def compensate_cmd(
    nominal: str = typer.Argument(..., help="nominal robot (what the controller runs): file or built-in name"),
    calibrated: str = typer.Argument(..., help="calibrated robot file"),
    targets: Path = typer.Argument(..., help="targets CSV: q1..qn and/or x, y, z[, rx, ry, rz] (deg, mm)"),
    out: Path = typer.Option(..., "--out", help="commands CSV to write"),
    truth: str | None = typer.Option(None, "--truth", help="simulated true robot: report its errors"),
    position_only: bool = typer.Option(
        False, "--position-only", help="match positions only (use for models calibrated from position data)"
    ),
    as_json: Path | None = typer.Option(None, "--json", help="write the summary as JSON too"),
    column: list[str] | None = typer.Option(None, "--column", help="map a file column: FILE=ROBOCAL (repeatable)"),
    quiet: bool = typer.Option(False, "--quiet", "-q"),
) -> None:
    """Corrected joint commands and Cartesian goals that make the calibrated robot reach its targets."""
    from .compensation import compensate, load_targets

    nom = load_robot(nominal)
    cal = load_robot(calibrated)
    tru = None if truth is None else load_robot(truth)
    if cal.n_joints != nom.n_joints or (tru is not None and tru.n_joints != nom.n_joints):
        raise InputError("nominal, calibrated and true robots must have the same number of joints", source=calibrated)
    tg = load_targets(targets, n_joints=nom.n_joints, columns=_column_map(column))
    result = compensate(nom, cal, tg, truth=tru, position_only=position_only or None)
    result.save(out)
    counts = result.counts()
    summary = {"targets": tg.n, "status": counts, "full_pose": result.full_pose}
    val = result.validation()
    if val is not None:
        summary["validation"] = {k: v.to_dict() for k, v in val.items()}
    if as_json is not None:
        atomic_write(as_json, json.dumps(summary, indent=2) + "\n")
    if not quiet:
        console.print(f"{tg.n} targets: " + ", ".join(f"{v} {k}" for k, v in counts.items()) + f"; wrote {out}")
        if val is not None and "nominal_commands" in val:
            console.print(
                metrics_table(
                    "true robot at the targets (rows with status ok)",
                    {"nominal commands": val["nominal_commands"], "compensated commands": val["compensated_commands"]},
                )
            )


def _joint_limits_arg(text: str | None, n: int) -> np.ndarray | None:
    """'lo:hi,lo:hi,…' (deg, one per joint) → (n, 2) rad."""
    if text is None:
        return None
    parts = [p.strip() for p in text.split(",")]
    if len(parts) != n:
        raise InputError(f"expected {n} ranges lo:hi (deg), got {len(parts)}", source="--limits")
    out = []
    for j, p in enumerate(parts):
        try:
            lo, hi = (float(v) for v in p.split(":"))
        except ValueError:
            raise InputError(f"joint {j + 1}: expected lo:hi in degrees, got {p!r}", source="--limits") from None
        if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
            raise InputError(f"joint {j + 1}: need finite lo < hi, got {p!r}", source="--limits")
        out.append((math.radians(lo), math.radians(hi)))
    return np.array(out)


@app.command("plan")
def plan_cmd(
    robot: str = typer.Argument(..., help="robot file or built-in name"),
    poses: int = typer.Option(30, "--poses", help="number of poses to measure"),
    candidates: int = typer.Option(2000, "--candidates", help="random joint sets to choose from"),
    criterion: str = typer.Option("O1", "--criterion", help="O1 | O2 | O3 | O4 | D"),
    measure: str = typer.Option("pose", "--measure", help="pose | position"),
    frames: str = typer.Option("none", "--frames", help="none | base | base+tool"),
    joint_range: str | None = typer.Option(None, "--range", help="LO,HI deg for every joint"),
    limits: str | None = typer.Option(None, "--limits", help="per joint lo:hi deg, comma-separated (work cell)"),
    noise: float = typer.Option(0.02, "--noise", help="position noise σ, mm"),
    angle_noise: float = typer.Option(0.001, "--angle-noise", help="orientation noise σ, deg"),
    seed: int = typer.Option(0, "--seed"),
    out: Path = typer.Option(..., "--out", help="measurement-file skeleton to write (pose_id, q1..qn)"),
    report: Path | None = typer.Option(None, "--json", help="write the plan report as JSON"),
    quiet: bool = typer.Option(False, "--quiet", "-q"),
) -> None:
    """Choose the joint sets worth measuring (greedy + exchange on an observability criterion)."""
    from .planning import plan_poses

    r = load_robot(robot)
    if poses < 1 or candidates < poses:
        raise InputError(f"need 1 ≤ poses ≤ candidates, got {poses} and {candidates}", source="--poses")
    for name, v in (("--noise", noise), ("--angle-noise", angle_noise)):
        if not (math.isfinite(v) and v > 0):
            raise InputError(f"must be a finite value > 0, got {v}", source=name)
    if frames not in ("none", "base", "base+tool"):
        raise InputError(f"unknown frames mode {frames!r} (expected none | base | base+tool)", source="--frames")
    rng_arg = _floats(joint_range, "--range", (2,))
    jr = _joint_limits_arg(limits, r.n_joints)
    if jr is None and rng_arg is not None:
        jr = (math.radians(rng_arg[0]), math.radians(rng_arg[1]))
    p = plan_poses(
        r,
        poses,
        candidates=candidates,
        criterion=criterion,
        measure=measure,
        frames=frames,
        joint_range=jr,
        noise=noise,
        angle_noise=math.radians(angle_noise),
        seed=seed,
    )
    lines = ["pose_id," + ",".join(f"q{i + 1}" for i in range(r.n_joints))]
    lines += [f"P{j + 1:03d}," + ",".join(f"{v:.6f}" for v in np.degrees(q)) for j, q in enumerate(p.q)]
    atomic_write(out, "\n".join(lines) + "\n")
    if report is not None:
        atomic_write(report, json.dumps(p.to_dict(), indent=1) + "\n")
    if not quiet:
        t = Table(title=f"{r.name}: {poses} of {candidates} candidates, criterion {criterion}, {measure}")
        for col in ("", "criterion", "predicted validation RMS (mm)"):
            t.add_column(col, justify="right")
        t.add_row("plan", f"{p.value:.6g}", f"{p.predicted_rms:.5f}")
        t.add_row(
            f"median of {len(p.random_rms)} random sets",
            f"{np.median(p.random_values):.6g}",
            f"{np.median(p.random_rms):.5f}",
        )
        console.print(t)
        worst = np.argsort(-p.predicted_std / np.where([is_angle(n) for n in p.names], 1 / r.reach(), 1.0))[:3]
        console.print(
            "least determined: "
            + ", ".join(
                f"{p.names[i]} ± {p.predicted_std[i]:.3g} {'rad' if is_angle(p.names[i]) else 'mm'}" for i in worst
            )
            + (
                f"; calibrate with --k {(noise / math.radians(angle_noise)) ** 2:.3g} to weigh orientation as "
                f"planned ({noise} mm, {angle_noise}°)"
                if measure == "pose"
                else ""
            )
        )
        console.print(f"wrote {out}")


@app.command("reproduce")
def reproduce_cmd(
    scenario: str = typer.Argument(..., help="wen2019 | kou2022 | all"),
    out: Path = typer.Option(..., "--out", help="folder for summary.md, results.json and figures"),
    quick: bool = typer.Option(False, "--quick", help="shortened settings (a smoke test, not the paper's)"),
    runs: int = typer.Option(10, "--runs", help="runs per swarm method (kou2022)"),
    seed: int = typer.Option(0, "--seed"),
    quiet: bool = typer.Option(False, "--quiet", "-q"),
) -> None:
    """Re-run a paper's experiment and write what it published beside what robocal measures."""
    from .reproduce import reproduce

    if runs < 1:
        raise InputError(f"must be ≥ 1, got {runs}", source="--runs")
    err = Console(stderr=True)

    def say(message: str) -> None:
        if not quiet:
            err.print(f"[dim]{message}[/dim]")

    reproduce(scenario, out, quick=quick, runs=runs, seed=seed, say=say)
    if not quiet:
        console.print(f"wrote {out}")


@app.command("bench")
def bench_cmd(
    quick: bool = typer.Option(False, "--quick", help="fewer repeats, no 100 000-pose LM"),
) -> None:
    """Time the workloads of robocal's speed targets (medians), with peers side by side."""
    from .bench import format_value, run_all

    err = Console(stderr=True)
    rows = run_all(quick=quick, say=lambda m: err.print(f"[dim]{m}[/dim]"))
    table = Table(title="robocal bench" + (" (quick)" if quick else ""))
    for col in ("workload", "median", "target", "met", "peer", "note"):
        table.add_column(col)
    for r in rows:
        met = "" if r.met is None else ("yes" if r.met else "falls short")
        table.add_row(r.workload, format_value(r), r.target, met, r.peer, r.note)
    Console(width=max(console.width, 160)).print(table)


pkm_app = typer.Typer(help="The 2TPR&2TPS parallel mechanism (Chen et al.).", no_args_is_help=True)
app.add_typer(pkm_app, name="pkm")


def _pkm_rows(text: str | None, path: Path | None, names: tuple[str, ...], what: str) -> np.ndarray:
    """Rows of numbers from a comma list (one row) or a CSV file with the named columns."""
    if (text is None) == (path is None):
        raise InputError(f"give either a comma list or a file of {', '.join(names)}", source=what)
    if text is not None:
        return np.array([_floats(text, what, (len(names),))])
    import csv as _csv
    import io as _io

    from .measurements import read_text

    body = read_text(path, "file")
    reader = list(_csv.reader(_io.StringIO(body)))
    if not reader:
        raise InputError("file is empty", source=path)
    header = [h.strip() for h in reader[0]]
    missing = [n for n in names if n not in header]
    if missing:
        raise InputError(f"missing column '{missing[0]}'", source=path)
    rows = []
    for ln, r in enumerate(reader[1:], start=2):
        if not any(c.strip() for c in r):
            continue
        vals = []
        for n in names:
            try:
                v = float(r[header.index(n)])
            except (ValueError, IndexError):
                raise InputError("not a number", source=path, where=f"row {ln}, column '{n}'") from None
            if not math.isfinite(v):
                raise InputError("value is not finite", source=path, where=f"row {ln}, column '{n}'")
            vals.append(v)
        rows.append(vals)
    if not rows:
        raise InputError("file has a header but no data rows", source=path)
    return np.array(rows)


@pkm_app.command("ik")
def pkm_ik_cmd(
    pose: str | None = typer.Option(None, "--pose", help="y,z,alpha,beta (mm, deg)"),
    poses: Path | None = typer.Option(None, "--poses", help="CSV with columns y, z, alpha, beta (mm, deg)"),
    geometry: str | None = typer.Option(None, "--geometry", help="mechanism TOML (default: built-in 2tpr2tps)"),
) -> None:
    """Rod lengths for platform poses (γ = 0, x = z tan β)."""
    from .pkm import check_workspace, ik, load_pkm, reduced_to_pose

    g = load_pkm(geometry)
    q = _pkm_rows(pose, poses, ("y", "z", "alpha", "beta"), "--pose")
    q[:, 2:] = np.radians(q[:, 2:])
    check_workspace(g, reduced_to_pose(q), source=str(poses or "--pose"))
    table = Table(title="inverse kinematics (commanded rod lengths, mm)")
    for col in ("y", "z", "α°", "β°", "L1", "L2", "L3", "L4"):
        table.add_column(col, justify="right")
    for qi, Li in zip(q, ik(g, q)):
        table.add_row(*(f"{v:.4f}" for v in (qi[0], qi[1], math.degrees(qi[2]), math.degrees(qi[3]), *Li)))
    console.print(table)


@pkm_app.command("fk")
def pkm_fk_cmd(
    lengths: str | None = typer.Option(None, "--lengths", help="L1,L2,L3,L4 (mm)"),
    file: Path | None = typer.Option(None, "--file", help="CSV with columns L1, L2, L3, L4 (mm)"),
    geometry: str | None = typer.Option(None, "--geometry", help="mechanism TOML (default: built-in 2tpr2tps)"),
) -> None:
    """Platform pose for rod lengths (Newton iteration, tolerance 1e-10 mm)."""
    from .pkm import fk, load_pkm

    g = load_pkm(geometry)
    L = _pkm_rows(lengths, file, ("L1", "L2", "L3", "L4"), "--lengths")
    p = fk(g, L)
    table = Table(title="forward kinematics")
    for col in ("x mm", "y mm", "z mm", "α°", "β°", "γ°"):
        table.add_column(col, justify="right")
    for row in p:
        table.add_row(*(f"{v:.6f}" for v in (*row[:3], *np.degrees(row[3:]))))
    console.print(table)


@pkm_app.command("sensitivity")
def pkm_sensitivity_cmd(
    out: Path = typer.Option(..., "--out", help="JSON file of mean |E| per case"),
    poses: int = typer.Option(30, "--poses"),
    seed: int = typer.Option(0, "--seed"),
    geometry: str | None = typer.Option(None, "--geometry"),
) -> None:
    """Chen et al. Fig. 4–9: pose errors for 1 mm of error per parameter over workspace poses."""
    from .pkm import load_pkm
    from .pkm_study import sensitivity, workspace_targets

    if poses < 1:
        raise InputError(f"need at least 1 pose, got {poses}", source="--poses")
    g = load_pkm(geometry)
    table = sensitivity(g, workspace_targets(g, poses, seed, angle=0.2)).mean_table()
    atomic_write(out, json.dumps(table, indent=1) + "\n")
    t = Table(title=f"mean |E| over {poses} poses, 1 mm error")
    for col in ("case", "parameter", "dx mm", "dy mm", "dz mm", "dα°", "dβ°"):
        t.add_column(col)
    for group, rows in table.items():
        for name, v in rows.items():
            t.add_row(group, name, *(f"{x:.4f}" for x in v[:3]), *(f"{math.degrees(x):.4f}" for x in v[3:5]))
    console.print(t)


@pkm_app.command("compensate")
def pkm_compensate_cmd(
    errors: float = typer.Option(0.5, "--errors", help="planted errors: uniform ± this many mm on all 28"),
    targets: int = typer.Option(30, "--targets"),
    noise: float = typer.Option(0.0, "--noise", help="tracker noise σ, mm"),
    seed: int = typer.Option(0, "--seed"),
    out: Path | None = typer.Option(None, "--out", help="JSON summary"),
) -> None:
    """Compensate a simulated machine: the paper's eq. 18 (PSO), its iteration, and the identified model."""
    from .pkm import chen2023
    from .pkm_study import compare_methods, identify_simulated, improvement, planted, workspace_targets

    for name, v in (("--errors", errors), ("--noise", noise)):
        if not math.isfinite(v) or v < 0:
            raise InputError(f"must be a finite value ≥ 0, got {v}", source=name)
    if targets < 1:
        raise InputError(f"need at least 1 target, got {targets}", source="--targets")
    g = chen2023()
    real = g.with_errors(planted(seed, errors, errors))
    model = identify_simulated(g, real, workspace_targets(g, 40, seed + 2, angle=0.2), noise=noise, seed=seed)
    runs = compare_methods(
        g, real, workspace_targets(g, targets, seed + 1), model.geometry, noise=noise, seed=seed, rounds=5
    )
    base = runs[0]
    t = Table(title=f"{targets} targets, planted ±{errors} mm, tracker noise {noise} mm")
    for col in ("method", "mean error mm", "max mm", "improvement %"):
        t.add_column(col)
    summary = {}
    for r in runs:
        imp = improvement(base, r)
        summary[r.method] = {"mean_mm": r.mean_error, "improvement_pct": imp}
        t.add_row(r.method, f"{r.mean_error:.6f}", f"{np.linalg.norm(r.error, axis=1).max():.6f}", f"{imp:.3f}")
    if out is not None:
        atomic_write(out, json.dumps(summary, indent=1) + "\n")
    console.print(t)


@pkm_app.command("calibrate")
def pkm_calibrate_cmd(
    data: Path = typer.Argument(..., help="CSV with columns L1..L4 (commanded, mm) and x, y, z (measured, mm)"),
    geometry: str | None = typer.Option(None, "--geometry"),
    out: Path | None = typer.Option(None, "--out", help="result JSON"),
    export: Path | None = typer.Option(None, "--export", help="identified mechanism TOML"),
) -> None:
    """Identify the identifiable subset of the 28 parameters from measured platform positions."""
    from .pkm import load_pkm, save_pkm
    from .pkm_study import identify

    g = load_pkm(geometry)
    rows = _pkm_rows(None, data, ("L1", "L2", "L3", "L4", "x", "y", "z"), "data")
    if len(rows) < 10:
        raise InputError(f"{len(rows)} poses are too few to identify the mechanism (need ≥ 10)", source=data)
    try:
        res = identify(g, rows[:, :4], rows[:, 4:])
    except ValueError as exc:
        raise InputError(str(exc), source=data) from None
    if out is not None:
        atomic_write(out, json.dumps(res.to_dict(), indent=1) + "\n")
    if export is not None:
        save_pkm(res.geometry, export, comment=f"Identified by robocal from {data}")
    console.print(
        f"{len(res.names)} parameters identified, dropped: {', '.join(res.identifiability.dropped) or 'none'};"
        f" position RMS {res.rms_before:.4f} → {res.rms_after:.6f} mm ({res.status})"
    )


def _one_line(text: str) -> str:
    return " ".join(str(text).split())


def main(argv: list[str] | None = None) -> int:
    """Entry point: runs the app and turns input errors into one line and exit code 2."""
    np.seterr(all="ignore")
    try:
        result = app(args=argv, prog_name="robocal", standalone_mode=False)
    except InputError as exc:
        print(f"robocal: error: {_one_line(exc)}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("robocal: interrupted", file=sys.stderr)
        return 130
    except Exception as exc:
        # Command-line misuse, raised by typer's click (vendored or not): duck-typed so
        # that either generation of typer gives the same one-line message.
        kind = type(exc).__name__
        if kind == "Abort":
            print("robocal: aborted", file=sys.stderr)
            return 130
        if not hasattr(exc, "format_message"):
            raise
        if kind == "NoArgsIsHelpError":
            print(exc.format_message())
            return 0
        ctx = getattr(exc, "ctx", None)
        where = f" ({ctx.command_path})" if ctx is not None and ctx.command_path != "robocal" else ""
        print(f"robocal: usage error{where}: {_one_line(exc.format_message())}", file=sys.stderr)
        return 2
    return result if isinstance(result, int) else 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
