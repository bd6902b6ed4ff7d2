"""Markers found in camera images: a folder of images and a joint log → camera rows (MODEL §10).

The joint log is a CSV with an ``image`` column (a file name in the folder) and the joints
``q1 … qn`` (deg; mm for a sliding joint) the robot stood at when the image was taken.  In each
image OpenCV's ArUco detector (``cv2.aruco``, from the ``camera`` extra) finds the markers of one
dictionary, their corners refined to sub-pixel; each marker gives a row per corner, named
``ID:0`` … ``ID:3`` in OpenCV's order (the marker's top-left, top-right, bottom-right and
bottom-left as it is printed), or one row at its centre (the crossing of its diagonals), named
``ID``.  A markers file that gives a square marker's pose and size (:func:`robocal.calibration.
cameras.load_markers`) names its corners the same way.  Pixels are as the image has them:
distorted, which the camera's lens model accounts for.
"""

from __future__ import annotations

import csv
import io
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..exceptions import InputError
from .atomic import read_text

#: a joint's magnitude beyond which a log's value is garbage (deg), as in measurement files
MAX_JOINT_DEG = 36_000.0


def _cv2():
    try:
        import cv2
    except ImportError:  # the camera extra is not installed
        raise InputError("detecting markers needs OpenCV: pip install 'robocal[camera]'", option="aruco") from None
    return cv2


def dictionary_names() -> list[str]:
    """The ArUco dictionaries OpenCV has, as robocal names them (``4X4_50``, ``APRILTAG_36H11``, …)."""
    cv2 = _cv2()
    return sorted({n[len("DICT_"):].upper() for n in dir(cv2.aruco) if n.startswith("DICT_")})


def dictionary(name: str):
    """OpenCV's predefined dictionary ``name`` (``4X4_50`` or ``DICT_4X4_50``, any case)."""
    cv2 = _cv2()
    key = str(name).strip().upper()
    key = key[len("DICT_"):] if key.startswith("DICT_") else key
    found = next((n for n in dir(cv2.aruco) if n.startswith("DICT_") and n[len("DICT_"):].upper() == key), None)
    if found is None:
        names = dictionary_names()
        raise InputError(f"unknown ArUco dictionary {name!r} (known: {', '.join(names[:8])}, … {len(names)} in all)",
                         option="aruco")
    return cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, found))


@dataclass(frozen=True)
class JointLog:
    """The images of a campaign and the joints (deg as the log has them) at each; ``rows``: the log's line
    of each image."""

    images: tuple[str, ...]
    q: np.ndarray
    rows: tuple[int, ...]
    source: str


def read_joint_log(path: str | Path) -> JointLog:
    """A joint log: ``image`` and ``q1 … qn`` (deg) columns, one image a row."""
    text = read_text(path, "joint log")
    table = list(csv.reader(io.StringIO(text)))
    if not table:
        raise InputError("is empty", source=str(path))
    header = [h.strip() for h in table[0]]
    if "image" not in header:
        raise InputError("needs an image column (the file name of each image) beside q1..qn", source=str(path))
    joints = [f"q{i + 1}" for i in range(sum(1 for h in header if h[:1] == "q" and h[1:].isdigit()))]
    if not joints or any(j not in header for j in joints):
        raise InputError("needs joint columns q1..qn (deg)", source=str(path))
    unknown = [h for h in header if h not in joints and h not in ("image", "pose_id")]
    if unknown:
        raise InputError(f"unknown column '{unknown[0]}' (expected image, q1..qn, pose_id)", source=str(path))
    at = {h: i for i, h in enumerate(header)}
    images, q, rows = [], [], []
    for line, cells in enumerate(table[1:], start=2):
        if not any(c.strip() for c in cells):
            continue
        if len(cells) != len(header):
            raise InputError(f"has {len(cells)} cells, the header {len(header)}", source=str(path), where=f"row {line}")
        name = cells[at["image"]].strip()
        if not name:
            raise InputError("empty image", source=str(path), where=f"row {line}, column 'image'")
        values = []
        for j in joints:
            try:
                v = float(cells[at[j]])
            except ValueError:
                raise InputError(f"{cells[at[j]]!r} is not a number", source=str(path),
                                 where=f"row {line}, column '{j}'") from None
            if not math.isfinite(v) or abs(v) > MAX_JOINT_DEG:
                raise InputError(f"{cells[at[j]]!r} is not a plausible joint value (deg)", source=str(path),
                                 where=f"row {line}, column '{j}'")
            values.append(v)
        images.append(name)
        q.append(values)
        rows.append(line)
    if not images:
        raise InputError("lists no image", source=str(path))
    return JointLog(tuple(images), np.array(q, float), tuple(rows), str(path))


#: what the AprilTag refinement's corners are shifted by to OpenCV's camera model, where a pixel's
#: centre is at whole numbers (a marker drawn at whole pixels has its outer edge at −0.5; the
#: refinement reports it at 0)
APRILTAG_SHIFT = -0.5


def detector(name: str):
    """OpenCV's ArUco detector for dictionary ``name``.  Corners are refined as AprilTag refines them: on
    markers a few dozen pixels wide, rendered and warped, OpenCV's sub-pixel corner search lands a
    quarter of a pixel inside the square (which shrinks it, and so pushes every marker away from the
    camera), the AprilTag refinement within a fiftieth, at a little more scatter.  It reports corners
    with the pixels' edges at whole numbers (:data:`APRILTAG_SHIFT`)."""
    cv2 = _cv2()
    parameters = cv2.aruco.DetectorParameters()
    parameters.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_APRILTAG
    return cv2.aruco.ArucoDetector(dictionary(name), parameters)


@dataclass(frozen=True)
class Board:
    """A ChArUco board: ``columns`` × ``rows`` squares of ``square`` mm, its markers ``marker`` mm a side,
    of an ArUco dictionary."""

    columns: int
    rows: int
    square: float
    marker: float
    dictionary: str

    @classmethod
    def parse(cls, text: str, dictionary_name: str) -> Board:
        """``COLSxROWS,SQUARE_MM,MARKER_MM`` (``5x7,30,22``)."""
        try:
            size, square, marker = (x.strip() for x in str(text).split(","))
            columns, rows = (int(x) for x in size.lower().split("x"))
            board = cls(columns, rows, float(square), float(marker), dictionary_name)
        except ValueError:
            raise InputError(f"expected COLSxROWS,SQUARE_MM,MARKER_MM (5x7,30,22), got {text!r}", option="charuco") \
                from None
        if min(columns, rows) < 2 or not 0 < board.marker < board.square or not math.isfinite(board.square):
            raise InputError(f"a board has at least 2 × 2 squares and markers smaller than its squares, got {text!r}",
                             option="charuco")
        return board

    def opencv(self):
        cv2 = _cv2()
        return cv2.aruco.CharucoBoard((self.columns, self.rows), self.square, self.marker, dictionary(self.dictionary))

    def corners(self) -> np.ndarray:
        """Its chessboard corners (N, 3) mm in the board's frame, in OpenCV's numbering."""
        return np.asarray(self.opencv().getChessboardCorners(), float)

    def markers_csv(self) -> str:
        """A markers file of its corners ``C:k`` as one body whose place is unknown
        (:func:`robocal.calibration.fit.cameras.load_markers`)."""
        lines = ["marker,x,y,z,body"]
        lines += [f"C:{k},{x!r},{y!r},{z!r},board" for k, (x, y, z) in enumerate(self.corners().tolist())]
        return "\n".join(lines) + "\n"


def _grey(path: str | Path) -> np.ndarray:
    """An image in grey, as OpenCV reads it (one line naming the file where it cannot)."""
    cv2 = _cv2()
    image = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
    if image is None:
        raise InputError("is not an image OpenCV can read", source=str(path))
    return image


def find_board(path: str | Path, found_by) -> dict[int, np.ndarray]:
    """A ChArUco board's chessboard corners in one image: corner id → (2,) px (OpenCV's convention)."""
    corners, ids, _, _ = found_by.detectBoard(_grey(path))
    if ids is None:
        return {}
    return {int(i): np.asarray(c, float).reshape(2) for i, c in zip(ids.ravel(), corners)}


def find_markers(path: str | Path, found_by) -> dict[int, np.ndarray]:
    """The markers in one image: id → its four corners (4, 2) px, in OpenCV's order."""
    corners, ids, _ = found_by.detectMarkers(_grey(path))
    if ids is None:
        return {}
    return {int(i): np.asarray(c, float).reshape(4, 2) + APRILTAG_SHIFT for i, c in zip(ids.ravel(), corners)}


def centre(corners: np.ndarray) -> np.ndarray | None:
    """The crossing of a square's projected diagonals: where its centre is seen (exact for a pinhole);
    None where they do not cross (a degenerate detection: its corners on one line)."""
    p0, p1, p2, p3 = corners
    d1, d2 = p2 - p0, p3 - p1
    A = np.column_stack([d1, -d2])
    if not np.all(np.isfinite(A)) or \
            not abs(np.linalg.det(A)) > 1e-9 * max(float(np.sum(d1 * d1) + np.sum(d2 * d2)), 1e-300):
        return None
    try:
        t = np.linalg.solve(A, p1 - p0)[0]
    except np.linalg.LinAlgError:  # singular after all: no crossing
        return None
    out = p0 + t * d1
    return out if np.all(np.isfinite(out)) else None


@dataclass(frozen=True)
class Detection:
    """Camera rows found in a campaign's images, and what was noticed (images where no marker was found)."""

    text: str
    n_rows: int
    n_images: int
    empty: tuple[str, ...]
    #: the rows' names (``ID:k`` corners, ``ID`` centres, ``C:k`` a board's corners)
    markers: tuple[str, ...]
    #: the markers (ids) or board found, and the detections left out as degenerate
    found: tuple[int, ...] = ()
    degenerate: int = 0


def detect_campaign(folder: str | Path, log: JointLog, camera: str, dictionary_name: str, *,
                    centres: bool = False, ids: Sequence[int] | None = None, board: Board | None = None) -> Detection:
    """Camera rows (CSV text: pose_id, q1..qn, u, v, camera, marker) of the markers of
    ``dictionary_name`` that ``camera`` saw in each image of the log; ``centres``: one row a marker at
    its centre instead of one a corner; ``ids``: only these markers (others in view are left out);
    ``board``: a ChArUco board's chessboard corners instead, one row each (``C:k``)."""
    folder = Path(folder)
    if not folder.is_dir():
        raise InputError("is not a folder of images", source=str(folder))
    found_by = detector(dictionary_name) if board is None else _cv2().aruco.CharucoDetector(board.opencv())
    keep = None if ids is None else set(int(i) for i in ids)
    n = log.q.shape[1]
    out = io.StringIO()
    w = csv.writer(out, lineterminator="\n")
    w.writerow(["pose_id", *(f"q{i + 1}" for i in range(n)), "u", "v", "camera", "marker"])
    rows, empty, names, ids_found, degenerate = 0, [], set(), set(), 0
    inside = folder.resolve()
    for image, q, line in zip(log.images, log.q, log.rows):
        path = folder / image
        if Path(image).is_absolute() or ".." in Path(image).parts or inside not in path.resolve().parents:
            raise InputError(f"image {image!r} is outside the images' folder {folder}: the log names images in it "
                             "(a name, or a path below it)", source=log.source, where=f"row {line}, column 'image'")
        if not path.is_file():
            raise InputError(f"image {image!r} is not in {folder}", source=log.source, where=f"row {line}")
        found = find_markers(path, found_by) if board is None else find_board(path, found_by)
        markers = {k: v for k, v in found.items() if keep is None or k in keep}
        if not markers:
            empty.append(image)
            continue
        pose = Path(image).stem
        for marker_id in sorted(markers):
            corners = markers[marker_id]
            if board is not None:
                points = [(f"C:{marker_id}", corners)]
            else:
                middle = centre(corners)
                if middle is None:  # its corners on a line: no square was seen
                    degenerate += 1
                    continue
                points = [(str(marker_id), middle)] if centres else \
                    [(f"{marker_id}:{k}", corners[k]) for k in range(4)]
                ids_found.add(marker_id)
            for name, (u, v) in points:
                w.writerow([pose, *(repr(float(x)) for x in q), repr(float(u)), repr(float(v)), camera, name])
                names.add(name)
                rows += 1
    if not rows:
        raise InputError(f"no marker of dictionary {dictionary_name} found in any of its {len(log.images)} images",
                         source=log.source)
    return Detection(out.getvalue(), rows, len(log.images), tuple(empty), tuple(sorted(names)),
                     tuple(sorted(ids_found)), degenerate)
