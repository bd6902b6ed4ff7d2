"""``robocal detect``: camera images and a joint log → the camera rows a calibration reads."""

from __future__ import annotations

from pathlib import Path

import typer

from .common import quiet_flag


def detect_cmd(
    images: Path = typer.Argument(..., help="folder of one camera's images"),
    joints: Path = typer.Option(..., "--joints", help="joint log CSV: image (file name) and q1..qn (deg) of each"),
    camera: str = typer.Option(..., "--camera", help="the camera's name, as the calibration's --camera NAME=FILE "
                               "names it"),
    aruco: str = typer.Option(..., "--aruco", help="ArUco dictionary of the markers (4X4_50, 6X6_250, "
                              "APRILTAG_36H11, …)"),
    centres: bool = typer.Option(False, "--centres", help="one row a marker, at its centre (default: one a corner, "
                                 "ID:0..ID:3)"),
    ids: str | None = typer.Option(None, "--ids", help="only these marker ids, ID[,ID…] (others in view are left "
                                   "out)"),
    charuco: str | None = typer.Option(None, "--charuco", help="COLSxROWS,SQUARE_MM,MARKER_MM: a ChArUco board of "
                                       "the --aruco dictionary; one row per chessboard corner found (C:k)"),
    markers_out: Path | None = typer.Option(None, "--markers-out", help="with --charuco: the board's corners as a "
                                            "markers file (one body, its place on the robot found by calibrate)"),
    out: Path = typer.Option(..., "--out", help="camera rows CSV to write (pose_id, q1..qn, u, v, camera, marker)"),
    quiet: bool = quiet_flag(),
) -> None:
    """Find ArUco markers (or a ChArUco board's corners) in a folder of images (OpenCV) and write the camera rows of
    the joint log's poses."""
    from .. import options as opt
    from ..exceptions import InputError
    from ..io.atomic import atomic_write, together
    from ..io.detect import Board, detect_campaign, read_joint_log
    from .common import check_outputs, console, print_warnings

    check_outputs((joints,), out=out, markers_out=markers_out)
    if markers_out is not None and charuco is None:
        raise InputError("the markers file a detection writes is a ChArUco board's layout: give --charuco",
                         option="markers_out")
    if not camera.strip() or "=" in camera:
        raise InputError(f"expected the camera's name, got {camera!r}", option="camera")
    wanted = None
    if ids is not None:
        wanted = [opt.integer(x.strip(), "ids", minimum=0) for x in ids.split(",")]
    board = None if charuco is None else Board.parse(charuco, aruco)
    found = detect_campaign(images, read_joint_log(joints), camera.strip(), aruco, centres=centres, ids=wanted,
                            board=board)
    with together():
        atomic_write(out, found.text)
        if markers_out is not None:
            atomic_write(markers_out, board.markers_csv())
    if found.empty:
        print_warnings([f"no marker of {aruco} found in {len(found.empty)} of the {found.n_images} images: "
                        + ", ".join(found.empty[:10]) + (" …" if len(found.empty) > 10 else "")])
    if found.degenerate:
        print_warnings([f"{found.degenerate} detection(s) left out: their corners lie on one line (no square seen)"])
    if not quiet:
        seen = found.n_images - len(found.empty)
        if board is not None:
            what = f"{len(found.markers)} of the board's corners"
        else:
            many = len(found.found) != 1
            what = (f"{'the centres' if centres else 'the corners'} of {len(found.found)} marker{'s' * many} "
                    f"({', '.join(map(str, found.found[:12]))}{' …' if len(found.found) > 12 else ''})")
        console().print(f"wrote {found.n_rows} rows ({what}, in {seen} image{'s' * (seen != 1)}) to {out}",
                        markup=False)


def register(app: typer.Typer) -> None:
    app.command("detect")(detect_cmd)
