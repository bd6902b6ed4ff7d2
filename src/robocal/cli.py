"""The ``robocal`` command line: a thin layer over the Python API.

Bad input never produces a traceback: :class:`~robocal.errors.InputError` and
command-line misuse become one line on stderr and exit code 2.
"""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path

import numpy as np
import typer
from rich.console import Console
from rich.table import Table

from .errors import InputError, atomic_write
from .measurements import load_measurements, measurements_to_csv
from .metrics import Metrics
from .robotfile import builtin_names, builtin_source, load_robot, robot_to_toml
from .simulate import simulate as run_simulation

app = typer.Typer(
    add_completion=False,
    no_args_is_help=True,
    help="Geometric calibration and error compensation of robots.",
    pretty_exceptions_enable=False,
)
console = Console()


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
    first = next(iter(columns.values()))
    rows = [(f"position {k} (mm)", lambda m, k=k: m.position[k]) for k in ("rms", "mean", "std", "max")]
    rows += [(f"max |{ax}| (mm)", lambda m, ax=ax: m.axis_max[ax]) for ax in "xyz"]
    if first.orientation is not None:
        rows += [
            (f"orient. {ax} {k} (deg)", lambda m, ax=ax, k=k: m.orientation[ax][k])
            for ax in "xyz"
            for k in ("mean", "std", "max")
        ]
    for label, get in rows:
        table.add_row(label, *(f"{get(m):.4f}" for m in columns.values()))
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
    meas = load_measurements(data, n_joints=r.n_joints, columns=_column_map(column))
    try:
        metrics = Metrics.of(r, meas)
    except ValueError as exc:
        raise InputError(str(exc), source=str(data)) from None
    if as_json:
        print(json.dumps(metrics.to_dict(), indent=2))
    else:
        console.print(metrics_table(f"{r.name} on {data} ({meas.n_poses} poses)", {"error": metrics}))


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
