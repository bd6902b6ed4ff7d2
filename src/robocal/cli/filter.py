"""``robocal filter``: a robot program's targets rewritten for the calibrated robot."""

from __future__ import annotations

from pathlib import Path

import typer

from .common import base_link_option, json_flag, quiet_flag, summary_option, tip_link_option

#: exit status of a run that wrote the program but left targets uncorrected (2 is bad input)
PARTIAL = 3


def filter_cmd(
    calibrated: str = typer.Argument(..., help="the accurate model: a robot file from calibrate --export"),
    program: Path = typer.Argument(..., help="the program: KRL .src (its .dat beside it), RAPID .mod/.prg, "
                                   "URScript .script, FANUC .ls"),
    nominal: str = typer.Option(..., "--nominal", help="the nominal model the controller runs (built-in name or "
                                "file)"),
    out: Path = typer.Option(..., "--out", help="the filtered program to write (KRL: its .dat beside it)"),
    tool: list[str] | None = typer.Option(None, "--tool", help="a TCP in the nominal model's tool frame (the "
                                          "controller's flange): x,y,z,rx,ry,rz (mm, deg, "
                                          "R = Rz(rz)·Ry(ry)·Rx(rx): FANUC's w,p,r, KUKA's C,B,A) for every target, "
                                          "or NAME=x,y,z,rx,ry,rz for the program's tool NAME (KRL TOOL_DATA[n] "
                                          "and FANUC UT n: n; RAPID: the tooldata's name); NAME=calibrated (or "
                                          "…,calibrated, or calibrated for every target): the calibration measured "
                                          "that tool, and its calibrated tool stands in for it; repeatable"),
    user_frame: list[str] | None = typer.Option(None, "--user-frame", help="a user frame in the robot's world, "
                                                "[NAME=]x,y,z,rx,ry,rz as --tool (KRL BASE_DATA[n] and FANUC UF "
                                                "n: n; RAPID: the wobjdata's name); repeatable"),
    controller_frames: Path | None = typer.Option(None, "--controller-frames", help="KRL: the controller's "
                                                  "$config.dat with TOOL_DATA and BASE_DATA (default: found "
                                                  "beside the program or in a folder above it)"),
    fmt: str = typer.Option("auto", "--format", help="auto | krl | rapid | urscript | fanuc"),
    as_json: bool = json_flag("the summary (every target's status, reason, correction, check and configuration)"),
    summary: Path | None = summary_option("the summary"),
    seed: int = typer.Option(0, "--seed", help="random starts of a nominal inverse with no closed form"),
    verbose: bool = typer.Option(False, "--verbose", help="a table row and a stderr line for every target (default: "
                                 "the flagged targets and the largest corrections, about 20 rows)"),
    no_stamp: bool = typer.Option(False, "--no-stamp", help="leave out the comment lines a changed program gets "
                                  "at its top (robocal's version, the calibrated model's file and SHA-256, the "
                                  "date; RAPID, KRL and URScript)"),
    base_link: str | None = base_link_option(),
    tip_link: str | None = tip_link_option(),
    quiet: bool = quiet_flag(),
) -> None:
    """Rewrite a program's targets so the uncalibrated controller drives the real robot where the
    programmer meant; everything else in the files stays byte for byte.  Exit status 3: the program
    was written but some targets were left uncorrected (listed, with the reason of each)."""
    import sys

    from .. import options as opt
    from ..exceptions import Note
    from ..filtering import Frames, filter_program, language_of, load_program
    from ..io.atomic import atomic_write, together
    from ..io.robotfile import load_robot
    from ..math.se3 import frame_from_values
    from .common import check_outputs, console, many_small_objects, print_json, print_notes, print_said, table

    language = language_of(program, fmt)
    tcp, tools, measured = opt.tool_frames(tool, "tool")
    user, users = opt.named_frames(user_frame, "user_frame")
    with many_small_objects():
        prog = load_program(program, language.name, controller_frames)  # reading it names its companion files
    outputs = [out if f.out_suffix is None else out.with_suffix(f.out_suffix) for f in prog.files]
    inputs = (calibrated, nominal, controller_frames, *(f.path for f in prog.files))
    companions = {f.out_suffix.strip("."): path for f, path in zip(prog.files[1:], outputs[1:])}
    check_outputs(inputs, out=out, summary=summary, **companions)
    frames = Frames(tcp=None if tcp is None else frame_from_values(tcp),
                    tools={k: frame_from_values(v) for k, v in tools.items()}, users={k: frame_from_values(v) for k, v
                                                                                     in users.items()},
                    user=None if user is None else frame_from_values(user), calibrated=measured)
    nom = load_robot(nominal, base_link=base_link, tip_link=tip_link)
    with many_small_objects():
        result = filter_program(calibrated, prog, nom, frames=frames, frames_file=controller_frames, seed=seed)
    written = result.outputs(out, None if no_stamp else stamp_lines(calibrated, nominal))
    if nom.source.startswith("built-in ur"):  # the drawing's DH, where every UR runs its own calibration
        result.notes.append(Note(f"--nominal {nominal} is the drawing's geometry; a UR controller runs its own "
                                 "factory calibration (calibration.conf): give that as the nominal (robocal robots "
                                 "--from-ur FILE --out ur-nominal.toml) so that the corrections are the "
                                 "calibration's alone"))
    with together():
        for path, data in written:
            atomic_write(path, data)
        if summary is not None:
            atomic_write(summary, result.json())
    flagged = result.flagged
    if as_json:
        print_json(result.json())
    elif not quiet:
        rows = shown_rows(result.corrections, verbose)
        n = len(result.corrections)
        title = f"{program} → {out}: {n - len(flagged)} of {n} targets corrected"
        if len(rows) < n:
            title += f" ({len(rows)} shown: the flagged, then the largest corrections; --verbose shows every one)"
        console().print(table(title, ("target", "line", "kind", "status", "moved mm", "turned °", "joints °",
                                      "configuration", "check mm"),
                              [_row(c) for c in rows], text_columns=(0, 2, 3, 7)))
    print_said(result.notes, quiet)
    for line in flagged_lines(flagged, verbose):
        print(line, file=sys.stderr)
    counts = ", ".join(f"{v} {k}" for k, v in result.counts().items())
    print_notes([f"{len(result.corrections)} targets: {counts}", files_note(prog, written)], quiet)
    if flagged:
        raise typer.Exit(PARTIAL)


def stamp_lines(calibrated, nominal) -> list[str]:
    """What a filtered program says of itself, in ASCII comment lines: who filtered it, when, for which
    calibrated model (its file's SHA-256) on which controller model, and what a corrected motion is."""
    import datetime

    from .. import __version__
    from ..report.header import digest

    today = datetime.datetime.now(datetime.UTC).date().isoformat()
    return [f"Filtered by robocal {__version__} on {today}: targets corrected for the calibrated model",
            f"  {calibrated} (sha256 {digest(calibrated)}) on a controller running {nominal};",
            "  linear and circular motions are corrected at their taught points."]


#: rows a default run shows: the flagged targets first, then the largest corrections
SHOWN_ROWS = 20
#: stderr lines a default run gives per status before it counts the rest
SHOWN_FLAGGED = 10


def shown_rows(corrections, verbose: bool) -> list:
    """Every target (``verbose``), else the flagged ones and the largest corrections, SHOWN_ROWS at
    most, in program order."""
    if verbose or len(corrections) <= SHOWN_ROWS:
        return list(corrections)
    flagged = [c for c in corrections if not c.corrected][:SHOWN_ROWS // 2]
    room = SHOWN_ROWS - len(flagged)
    largest = sorted((c for c in corrections if c.corrected), key=lambda c: -(c.moved_mm or c.joints_deg or 0.0))
    keep = {id(c) for c in flagged + largest[:room]}
    return [c for c in corrections if id(c) in keep]


#: configuration data that name one joint's quadrant, turn or sign (RAPID cf1/cf4/cf6, FANUC's turn
#: numbers and flip): the joint (0-based) whose value after the correction says why the datum changed
_JOINT_OF = {"cf1": 0, "cf4": 3, "cf6": 5, "t1": 0, "t4": 3, "t6": 5, "flip": 4}


def config_change(c) -> str:
    """A corrected target's configuration data that changed, before → after, each with why: the joint
    it names at its corrected value (``cf4 0→-1: j4 at -0.016°``), or the arm's posture it encodes."""
    import math

    after = c.config_after or {}
    q = None if c.q is None else [math.degrees(v) for v in c.q]
    parts = []
    for k, v in after.items():
        before = c.config_before.get(k)
        if k not in c.config_before or before == v:
            continue
        joints = [_JOINT_OF[k]] if k in _JOINT_OF else \
            [i for i in range(6) if (int(before) ^ int(v)) >> i & 1] if k == "T" else \
            [4] if (k == "S" and (int(before) ^ int(v)) & 4) or (k == "cfx" and (int(before) ^ int(v)) & 1) else []
        why = ", ".join(f"j{j + 1} at {q[j]:+.3f}°" for j in joints if q is not None and j < len(q)) or \
            "the arm's posture (front/back, elbow)"
        parts.append(f"{k} {before}→{v}: {why}")
    return "; ".join(parts)


def _row(c) -> tuple[str, ...]:
    done = c.corrected
    return (c.target.name, str(c.target.line), c.target.kind, c.status,
            "" if c.moved_mm is None or not done else f"{c.moved_mm:.3f}",
            "" if c.turned_deg is None or not done else f"{c.turned_deg:.4f}",
            "" if c.joints_deg is None or not done else f"{c.joints_deg:.4f}",
            config_change(c) if done else "", "" if c.check_mm is None else f"{c.check_mm:.2g}")


def flagged_lines(flagged, verbose: bool) -> list[str]:
    """One stderr line per flagged target, SHOWN_FLAGGED at most per status unless ``verbose``, the
    rest counted."""
    from collections import defaultdict

    from .common import one_line

    by_status: dict[str, list] = defaultdict(list)
    for c in flagged:
        by_status[c.status].append(c)
    out = []
    for status, cs in by_status.items():
        shown = cs if verbose else cs[:SHOWN_FLAGGED]
        out += [f"robocal: not corrected: {c.target.name} (line {c.target.line}): {status}: {one_line(c.reason)}"
                for c in shown]
        if len(cs) > len(shown):
            out.append(f"robocal: not corrected: {len(cs) - len(shown)} more {status} (--verbose lists every one, "
                       "--summary FILE writes them with their reasons)")
    return out


def files_note(program, written) -> str:
    """Which files the run wrote, and which of them are the program's own bytes unchanged."""
    parts = []
    for f, (path, data) in zip(program.files, written):
        same = data == _bytes_of(f)
        parts.append(f"{path} ({'identical to ' + Path(f.path).name if same else 'its targets rewritten'})")
    return "wrote " + " and ".join(parts)


def _bytes_of(f) -> bytes:
    from ..filtering.program import encode

    return encode(f.text, f.encoding)


def register(app: typer.Typer) -> None:
    app.command("filter")(filter_cmd)
