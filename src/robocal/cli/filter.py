"""``robocal filter``: a robot program's targets rewritten for the calibrated robot."""

from __future__ import annotations

from pathlib import Path

import typer


def filter_cmd(
    calibrated: str = typer.Argument(..., help="the accurate model: a robot file from calibrate --export"),
    program: Path = typer.Argument(..., help="the program: KRL .src (its .dat beside it), RAPID .mod/.prg, or "
                                   "URScript .script"),
    nominal: str = typer.Option(..., "--nominal", help="the nominal model the controller runs (built-in name or "
                                "file)"),
    out: Path = typer.Option(..., "--out", help="the filtered program to write (KRL: its .dat beside it)"),
    tool: str | None = typer.Option(None, "--tool", help="TCP x,y,z,rx,ry,rz (mm, deg, flange frame; default: the "
                                    "program's tool data, else the nominal model's tool)"),
    fmt: str = typer.Option("auto", "--format", help="auto | krl | rapid | urscript"),
    summary: Path | None = typer.Option(None, "--json", help="JSON summary to write: every target's correction "
                                        "and status"),
) -> None:
    """Rewrite a program's targets so the uncalibrated controller drives the real robot where the
    programmer meant; everything else in the file stays byte for byte."""
    from .. import options as opt
    from ..filtering import filter_program, language_of
    from ..io.atomic import atomic_write, together
    from ..math.se3 import frame_from_values
    from .common import check_outputs, console, print_warnings, table

    language = language_of(program, fmt)
    src = program.with_suffix(".src") if language == "krl" and program.suffix.lower() == ".dat" else program
    inputs = (calibrated, nominal, src) + ((src.with_suffix(".dat"),) if language == "krl" else ())
    dat_out = out.with_suffix(".dat") if language == "krl" and src.with_suffix(".dat").is_file() else None
    check_outputs(inputs, out=out, summary=summary, **({"dat": dat_out} if dat_out else {}))
    values = opt.frame_values(tool, "tool")
    T = None if values is None else frame_from_values(values)
    result = filter_program(calibrated, src, nominal, tool=T, fmt=language)
    with together():
        atomic_write(out, result.text.encode(result.encodings["main"]))
        if dat_out is not None and result.dat is not None:
            atomic_write(dat_out, result.dat.encode(result.encodings["dat"]))
        if summary is not None:
            atomic_write(summary, result.json())
    flagged = result.flagged
    rows = [(c.target.name, str(c.target.line), c.target.kind, c.status,
             f"{c.moved_mm:.3f}" if c.corrected and c.target.kind == "pose" else "",
             f"{c.turned_deg:.4f}" if c.corrected and c.target.kind == "pose" else "",
             f"{c.joints_deg:.4f}" if c.corrected else "") for c in result.corrections]
    console().print(table(f"{src} → {out}: {len(rows) - len(flagged)} of {len(rows)} targets corrected",
                          ("target", "line", "kind", "status", "moved mm", "turned °", "joints °"), rows,
                          text_columns=(0, 2, 3)))
    notes = list(result.notes)
    if flagged:
        names = ", ".join(f"{c.target.name} ({c.status})" for c in flagged[:5]) + (" …" if len(flagged) > 5 else "")
        notes.append(f"{len(flagged)} target(s) left unchanged and flagged: {names}")
    print_warnings(notes)


def register(app: typer.Typer) -> None:
    app.command("filter")(filter_cmd)
