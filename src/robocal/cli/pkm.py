"""``robocal pkm …``: the 2TPR&2TPS parallel mechanism (Chen et al.)."""

from __future__ import annotations

from pathlib import Path

import typer

from .common import quiet_flag, seed_option

app = typer.Typer(help="The 2TPR&2TPS parallel mechanism (Chen et al.).", no_args_is_help=True)


@app.command("ik")
def ik_cmd(
    pose: str | None = typer.Option(None, "--pose", help="y,z,alpha,beta (mm, deg)"),
    poses: Path | None = typer.Option(None, "--poses", help="CSV with columns y, z, alpha, beta (mm, deg)"),
    geometry: str | None = typer.Option(None, "--geometry", help="mechanism TOML (default: built-in 2tpr2tps)"),
    quiet: bool = quiet_flag(),
) -> None:
    """Rod lengths for platform poses (γ = 0, x = z tan β)."""
    import math

    import numpy as np

    from ..pkm.files import load_pkm, read_rows
    from ..pkm.geometry import reduced_to_pose
    from ..pkm.kinematics import check_workspace, ik
    from .common import console, table

    g = load_pkm(geometry)
    q = read_rows(pose, poses, ("y", "z", "alpha", "beta"), "pose")
    q[:, 2:] = np.radians(q[:, 2:])
    check_workspace(g, reduced_to_pose(q), source=str(poses or "--pose"))
    rows = [tuple(f"{v:.4f}" for v in (qi[0], qi[1], math.degrees(qi[2]), math.degrees(qi[3]), *Li))
            for qi, Li in zip(q, ik(g, q))]
    if quiet:
        return
    console().print(table("inverse kinematics (commanded rod lengths, mm)",
                          ("y", "z", "α°", "β°", "L1", "L2", "L3", "L4"), rows))


@app.command("fk")
def fk_cmd(
    lengths: str | None = typer.Option(None, "--lengths", help="L1,L2,L3,L4 (mm)"),
    file: Path | None = typer.Option(None, "--file", help="CSV with columns L1, L2, L3, L4 (mm)"),
    geometry: str | None = typer.Option(None, "--geometry", help="mechanism TOML (default: built-in 2tpr2tps)"),
    quiet: bool = quiet_flag(),
) -> None:
    """Platform pose for rod lengths (Newton iteration, tolerance 1e-10 mm)."""
    import numpy as np

    from ..pkm.files import load_pkm, read_rows
    from ..pkm.kinematics import fk
    from .common import console, table

    p = fk(load_pkm(geometry), read_rows(lengths, file, ("L1", "L2", "L3", "L4"), "lengths"))
    rows = [tuple(f"{v:.6f}" for v in (*row[:3], *np.degrees(row[3:]))) for row in p]
    if quiet:
        return
    console().print(table("forward kinematics", ("x mm", "y mm", "z mm", "α°", "β°", "γ°"), rows))


@app.command("sensitivity")
def sensitivity_cmd(
    out: Path = typer.Option(..., "--out", help="JSON file of mean |E| per case"),
    poses: int = typer.Option(30, "--poses", help="random poses per case"),
    seed: int = seed_option("the swarm and the simulated measurements"),
    geometry: str | None = typer.Option(None, "--geometry", help="mechanism TOML (default: built-in 2tpr2tps)"),
    quiet: bool = quiet_flag(),
) -> None:
    """Chen et al. Fig. 4–9: pose errors for 1 mm of error per parameter over workspace poses."""
    import json
    import math

    from .. import options as opt
    from ..io.atomic import atomic_write
    from ..pkm.files import load_pkm
    from ..pkm.kinematics import workspace_targets
    from ..pkm.sensitivity import sensitivity
    from .common import check_outputs, console, table

    check_outputs(out=out)
    opt.integer(poses, "poses", minimum=1)
    g = load_pkm(geometry)
    means = sensitivity(g, workspace_targets(g, poses, seed, angle=0.2)).mean_table()
    atomic_write(out, json.dumps(means, indent=1) + "\n")
    rows = [(group, name, *(f"{x:.4f}" for x in v[:3]), *(f"{math.degrees(x):.4f}" for x in v[3:5]))
            for group, entries in means.items() for name, v in entries.items()]
    if quiet:
        return
    console().print(table(f"mean |E| over {poses} poses, 1 mm error",
                          ("case", "parameter", "dx mm", "dy mm", "dz mm", "dα°", "dβ°"), rows, "left"))


@app.command("compensate")
def compensate_cmd(
    errors: float = typer.Option(0.5, "--errors", help="planted errors: uniform ± this many mm on all 28"),
    targets: int = typer.Option(30, "--targets", help="random goal poses to compensate"),
    noise: float = typer.Option(0.0, "--noise", help="tracker noise σ, mm"),
    seed: int = seed_option("the swarm and the simulated measurements"),
    out: Path | None = typer.Option(None, "--out", help="JSON summary"),
    quiet: bool = quiet_flag(),
) -> None:
    """Compensate a simulated machine: the paper's eq. 18 (PSO), its iteration, and the identified model."""
    import json

    from ..io.atomic import atomic_write
    from ..pkm.compensation import simulate_compensation
    from .common import check_outputs, console, table

    check_outputs(out=out)
    study = simulate_compensation(errors=errors, targets=targets, noise=noise, seed=seed)
    rows = study.table()
    if out is not None:
        atomic_write(out, json.dumps({r["method"]: {"mean_mm": r["mean_mm"], "improvement_pct": r["improvement_pct"]}
                                      for r in rows}, indent=1) + "\n")
    if quiet:
        return
    console().print(table(f"{targets} targets, planted ±{errors} mm, tracker noise {noise} mm",
                          ("method", "mean error mm", "max mm", "improvement %"),
                          [(r["method"], f"{r['mean_mm']:.6f}", f"{r['max_mm']:.6f}", f"{r['improvement_pct']:.3f}")
                           for r in rows], "left"))


@app.command("calibrate")
def calibrate_cmd(
    data: Path = typer.Argument(..., help="CSV with columns L1..L4 (commanded, mm) and x, y, z (measured, mm)"),
    geometry: str | None = typer.Option(None, "--geometry", help="mechanism TOML (default: built-in 2tpr2tps)"),
    out: Path | None = typer.Option(None, "--out", help="result JSON"),
    export: Path | None = typer.Option(None, "--export", help="identified mechanism TOML"),
    quiet: bool = quiet_flag(),
) -> None:
    """Identify the identifiable subset of the 28 parameters from measured platform positions."""
    import json

    from ..io.atomic import atomic_write, together
    from ..pkm.files import load_pkm, save_pkm
    from ..pkm.identify import identify_file
    from .common import check_outputs, console

    check_outputs(out=out, export=export)
    res = identify_file(data, load_pkm(geometry))
    with together():
        if out is not None:
            atomic_write(out, json.dumps(res.to_dict(), indent=1) + "\n")
        if export is not None:
            save_pkm(res.geometry, export, comment=f"Identified by robocal from {data}")
    dropped = ", ".join(res.identifiability.dropped) or "none"
    if quiet:
        return
    console().print(f"{len(res.names)} parameters identified, dropped: {dropped}"
                    f"; position RMS {res.rms_before:.4f} → {res.rms_after:.6f} mm ({res.status})")
