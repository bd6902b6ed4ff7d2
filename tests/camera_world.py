"""An independent camera cell for planted-truth tests: it shares no code with robocal.

Forward kinematics is :mod:`tests.independent`'s; the projection with its distortion is OpenCV's
own ``cv2.projectPoints``, and the camera files are written by ``cv2.FileStorage``.  A camera is
fixed in the world or rides on a link (its mounting is a 4 × 4 in that link's frame); markers are
points on the flange, seen where they face the camera, lie in front of it and fall on its image.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from tests import independent

cv2 = __import__("pytest").importorskip("cv2")


def look_at(eye, target, up=(0.0, 0.0, 1.0)) -> np.ndarray:
    """A camera frame at ``eye`` whose optical axis (z) points at ``target``, x to the image's right."""
    eye, target = np.asarray(eye, float), np.asarray(target, float)
    z = (target - eye) / np.linalg.norm(target - eye)
    x = np.cross(z, up)
    x /= np.linalg.norm(x)
    T = np.eye(4)
    T[:3, :3] = np.column_stack([x, np.cross(z, x), z])
    T[:3, 3] = eye
    return T


@dataclass
class CellCamera:
    name: str
    K: np.ndarray
    dist: np.ndarray
    size: tuple[int, int]
    pose: np.ndarray  # camera frame in its parent: the world (link 0) or link ``link``'s frame
    link: int = 0

    def write(self, path: Path) -> Path:
        fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
        fs.write("image_width", self.size[0])
        fs.write("image_height", self.size[1])
        fs.write("camera_matrix", self.K)
        fs.write("distortion_coefficients", self.dist.reshape(1, -1))
        fs.release()
        return path

    def project(self, points_camera: np.ndarray) -> np.ndarray:
        uv, _ = cv2.projectPoints(points_camera.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), self.K, self.dist)
        return uv.reshape(-1, 2)


def camera(name: str, pose: np.ndarray, link: int = 0, f: float = 1400.0, dist=(-0.12, 0.08, 0.0005, -0.0004, 0.0),
           size=(1600, 1200)) -> CellCamera:
    K = np.array([[f, 0, size[0] / 2 + 7.5], [0, f * 1.002, size[1] / 2 - 4.0], [0, 0, 1.0]])
    return CellCamera(name, K, np.array(dist, float), size, pose, link)


def dodecahedron(radius: float, centre=(0.0, 0.0, 60.0)) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """20 markers at a regular dodecahedron's vertices around ``centre`` (mm, flange frame): name →
    (position, outward normal)."""
    phi = (1 + 5 ** 0.5) / 2
    v = [(x, y, z) for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)]
    for a in (-1, 1):
        for b in (-1, 1):
            v += [(0, a / phi, b * phi), (a / phi, b * phi, 0), (a * phi, 0, b / phi)]
    v = np.array(v, float)
    n = v / np.linalg.norm(v, axis=1, keepdims=True)
    return {f"m{i + 1}": (np.asarray(centre) + radius * n[i], n[i]) for i in range(20)}


@dataclass
class Cell:
    robot: str
    deviations: dict
    cameras: list[CellCamera]
    markers: dict  # name → (position mm in the flange frame, outward normal or None: seen from anywhere)
    base: np.ndarray = field(default_factory=lambda: np.eye(4))  # the robot's base in the world

    def camera_pose(self, cam: CellCamera, q: np.ndarray) -> np.ndarray:
        """The camera's frame in the world at joints q."""
        if cam.link == 0:
            return cam.pose
        g = independent.geometry(self.robot, self.deviations)
        return self.base @ independent.link_frames(g, q)[cam.link - 1] @ cam.pose

    def observe(self, q_all: np.ndarray, rng: np.random.Generator, noise: float, facing: float = 0.2):
        """Camera rows (q deg, u, v, camera, marker) of every marker each camera sees at each pose,
        with Gaussian pixel noise ``noise`` (px): pose by pose, camera by camera, the markers in
        their order, each one in front of the camera and facing it drawing its noise."""
        g = independent.geometry(self.robot, self.deviations)
        q_all = np.atleast_2d(np.asarray(q_all, float))
        names = list(self.markers)
        P = np.array([p for p, _ in self.markers.values()], float)
        facing_only = np.array([n is not None for _, n in self.markers.values()])
        N = np.array([np.zeros(3) if n is None else n for _, n in self.markers.values()], float)
        flanges = self.base @ independent.poses(g, q_all)
        rows = []
        for q, flange in zip(q_all, flanges):
            pw = P @ flange[:3, :3].T + flange[:3, 3]
            nw = N @ flange[:3, :3].T
            for cam in self.cameras:
                Tc = self.camera_pose(cam, q)
                pc = (pw - Tc[:3, 3]) @ Tc[:3, :3]
                to_camera = Tc[:3, 3] - pw
                faces = np.sum(nw * to_camera, axis=1) / np.linalg.norm(to_camera, axis=1) >= facing
                seen = np.flatnonzero((pc[:, 2] > 100.0) & (faces | ~facing_only))
                if not seen.size:
                    continue
                uv = cam.project(pc[seen]) + rng.normal(0.0, noise, (seen.size, 2))
                inside = (uv[:, 0] >= 20) & (uv[:, 0] <= cam.size[0] - 20) & (uv[:, 1] >= 20) & \
                    (uv[:, 1] <= cam.size[1] - 20)
                rows += [(np.degrees(q), uv[k], cam.name, names[j]) for k, j in enumerate(seen) if inside[k]]
        return rows

    def marker_in(self, frame_of, q_all: np.ndarray, name: str) -> np.ndarray:
        """A marker's true position (m, 3) mm in the frame ``frame_of(q)`` (4 × 4 in the world) gives."""
        g = independent.geometry(self.robot, self.deviations)
        p = self.markers[name][0]
        out = []
        for q in q_all:
            flange = self.base @ independent.pose(g, q)
            pw = flange[:3, :3] @ p + flange[:3, 3]
            T = frame_of(q)
            out.append(T[:3, :3].T @ (pw - T[:3, 3]))
        return np.array(out)


    def seen_from(self, cam: CellCamera, q_all: np.ndarray, name: str) -> np.ndarray:
        """A marker's true position (m, 3) mm in a camera's frame at joints q_all."""
        return self.marker_in(lambda q: self.camera_pose(cam, q), q_all, name)


def with_shared_bias(rows, rng: np.random.Generator, sigma: float):
    """The rows with a detector bias (px, per image axis, σ ``sigma``) shared by every marker one camera
    saw at one pose: what the model does not contain, and robocal must notice."""
    bias: dict = {}
    out = []
    for q, uv, cam, marker in rows:
        key = (tuple(np.round(q, 9)), cam)
        if key not in bias:
            bias[key] = rng.normal(0.0, sigma, 2)
        out.append((q, uv + bias[key], cam, marker))
    return out


def write_rows(rows, path: Path, session: str | None = None) -> Path:
    n = len(rows[0][0])
    lines = [",".join([f"q{i + 1}" for i in range(n)] + ["u", "v", "camera", "marker"]
                      + (["session"] if session is not None else []))]
    for q, uv, cam, marker in rows:
        lines.append(",".join([repr(float(x)) for x in q] + [repr(float(uv[0])), repr(float(uv[1])), cam, marker]
                              + ([session] if session is not None else [])))
    path.write_text("\n".join(lines) + "\n")
    return path


def write_markers(markers: dict, path: Path) -> Path:
    lines = ["marker,x,y,z"] + [f"{k},{float(p[0])!r},{float(p[1])!r},{float(p[2])!r}" for k, (p, _) in markers.items()]
    path.write_text("\n".join(lines) + "\n")
    return path


def poses(robot: str, n: int, rng: np.random.Generator, centre_deg=None, spread_deg=None) -> np.ndarray:
    """n joint sets (rad) around ``centre_deg`` within ±``spread_deg`` (default: the limits)."""
    lim = np.array(independent.LIMITS_DEG[robot], float)
    if centre_deg is None:
        return np.radians(rng.uniform(lim[:, 0], lim[:, 1], (n, len(lim))))
    c, s = np.asarray(centre_deg, float), np.asarray(spread_deg, float)
    return np.radians(np.clip(rng.uniform(c - s, c + s, (n, len(lim))), lim[:, 0], lim[:, 1]))


#: an ArUco marker's corners in its own frame (x right, y up as printed, z out of its face), in
#: OpenCV's order as multiples of its side: written here from OpenCV's ArUco documentation
ARUCO_CORNERS = np.array([[-0.5, 0.5, 0.0], [0.5, 0.5, 0.0], [0.5, -0.5, 0.0], [-0.5, -0.5, 0.0]])


def cube_markers(side: float = 60.0, offset: float = 100.0, half: float = 45.0) -> dict[int, tuple[np.ndarray, float]]:
    """Five ArUco markers (ids 1–5) of ``side`` mm on the faces of a cube of half-width ``half`` whose
    centre stands ``offset`` mm out along the flange's z: id → (marker frame on the flange, side)."""
    from scipy.spatial.transform import Rotation

    centre = np.array([0.0, 0.0, offset])
    faces = {1: (0, 0, 0), 2: (0, 90, 0), 3: (0, -90, 0), 4: (90, 0, 0), 5: (-90, 0, 0)}  # xyz Euler, deg
    out = {}
    for marker_id, angles in faces.items():
        T = np.eye(4)
        T[:3, :3] = Rotation.from_euler("xyz", angles, degrees=True).as_matrix()
        T[:3, 3] = centre + T[:3, :3] @ np.array([0.0, 0.0, half])
        out[marker_id] = (T, side)
    return out


def square_points(squares: dict) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Each square marker's corners as points ``ID:k`` (flange frame) with the marker's normal."""
    out = {}
    for marker_id, (T, side) in squares.items():
        for k, c in enumerate(ARUCO_CORNERS * side):
            out[f"{marker_id}:{k}"] = (T[:3, :3] @ c + T[:3, 3], T[:3, 2])
    return out


def write_square_markers(squares: dict, path: Path) -> Path:
    """A markers file of square markers: marker, x, y, z, rx, ry, rz (deg, xyz as robocal reads them), size."""
    from scipy.spatial.transform import Rotation

    lines = ["marker,x,y,z,rx,ry,rz,size"]
    for marker_id, (T, side) in squares.items():
        with __import__("warnings").catch_warnings():  # a face turned 90° about y: any split of x and z will do
            __import__("warnings").simplefilter("ignore")
            rx, ry, rz = Rotation.from_matrix(T[:3, :3]).as_euler("xyz", degrees=True)
        lines.append(",".join([str(marker_id)] + [repr(float(v)) for v in (*T[:3, 3], rx, ry, rz, side)]))
    path.write_text("\n".join(lines) + "\n")
    return path


def render(cell: Cell, cam: CellCamera, q: np.ndarray, squares: dict, dictionary: int, pixels: int = 240,
           facing: float = 0.3) -> tuple[np.ndarray, list]:
    """An image (grey background) of the square markers at joints q, each drawn by OpenCV
    (``cv2.aruco.generateImageMarker``) and warped onto where its corners project (a pinhole: the
    camera has no distortion), with its white quiet zone; and the rows of the corners drawn
    (marker ``ID:k``, exact pixel)."""
    assert not np.any(cam.dist), "rendering warps planes: a camera without distortion"
    g = independent.geometry(cell.robot, cell.deviations)
    flange = cell.base @ independent.pose(g, q)
    Tc = cell.camera_pose(cam, q)
    image = np.full((cam.size[1], cam.size[0]), 128, np.uint8)
    rows = []
    aruco = cv2.aruco.getPredefinedDictionary(dictionary)
    pad = pixels // 8
    for marker_id, (T, side) in squares.items():
        Tw = flange @ T
        normal, centre = Tw[:3, 2], Tw[:3, 3]
        if normal @ (Tc[:3, 3] - centre) / np.linalg.norm(Tc[:3, 3] - centre) < facing:
            continue
        corners = ARUCO_CORNERS * side
        quiet = corners * (1 + 2 * pad / pixels)  # the white border around the printed marker
        world = (Tw[:3, :3] @ np.vstack([corners, quiet]).T).T + Tw[:3, 3]
        pc = (world - Tc[:3, 3]) @ Tc[:3, :3]
        if np.any(pc[:, 2] <= 100):
            continue
        uv = cam.project(pc)
        if np.any(uv < 5) or np.any(uv[:, 0] > cam.size[0] - 5) or np.any(uv[:, 1] > cam.size[1] - 5):
            continue
        printed = np.full((pixels + 2 * pad, pixels + 2 * pad), 255, np.uint8)
        printed[pad:pad + pixels, pad:pad + pixels] = cv2.aruco.generateImageMarker(aruco, marker_id, pixels)
        edge = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], float)
        source = pad - 0.5 + edge * pixels  # the marker's outer edges, pixel-centre coordinates
        source_quiet = -0.5 + edge * (pixels + 2 * pad)
        H = cv2.getPerspectiveTransform(np.vstack([source, source_quiet])[:4].astype(np.float32),
                                        uv[:4].astype(np.float32))
        warped = cv2.warpPerspective(printed, H, cam.size, flags=cv2.INTER_LINEAR, borderValue=0)
        mask = cv2.warpPerspective(np.full(printed.shape, 255, np.uint8), H, cam.size, flags=cv2.INTER_LINEAR)
        alpha = mask.astype(float) / 255.0
        image = (alpha * warped + (1 - alpha) * image).round().astype(np.uint8)
        del source_quiet
        rows += [(np.degrees(q), uv[k], cam.name, f"{marker_id}:{k}") for k in range(4)]
    return image, rows


def render_board(cell: Cell, cam: CellCamera, q: np.ndarray, pose: np.ndarray, board, pixels_per_square: int = 80,
                 facing: float = 0.3) -> tuple[np.ndarray, list]:
    """An image of a ChArUco board (``cv2.aruco.CharucoBoard``, its lengths in mm) held at ``pose`` on the
    flange (the board's frame as OpenCV lays out its corners: x along its columns, y along its rows, z
    behind its printed face), drawn by OpenCV and warped onto where its outline projects; and the rows
    of its chessboard corners in view (marker ``C:k``, exact pixel)."""
    g = independent.geometry(cell.robot, cell.deviations)
    Tw = cell.base @ independent.pose(g, q) @ pose
    Tc = cell.camera_pose(cam, q)
    columns, rows = board.getChessboardSize()
    square = board.getSquareLength()
    image = np.full((cam.size[1], cam.size[0]), 128, np.uint8)
    front = -Tw[:3, 2]  # the printed face looks along −z
    if front @ (Tc[:3, 3] - Tw[:3, 3]) / np.linalg.norm(Tc[:3, 3] - Tw[:3, 3]) < facing:
        return image, []
    outline = np.array([[0, 0, 0], [columns, 0, 0], [columns, rows, 0], [0, rows, 0]], float) * square
    corners = np.asarray(board.getChessboardCorners(), float)
    pc = ((Tw[:3, :3] @ np.vstack([outline, corners]).T).T + Tw[:3, 3] - Tc[:3, 3]) @ Tc[:3, :3]
    if np.any(pc[:, 2] <= 100):
        return image, []
    uv = cam.project(pc)
    printed = board.generateImage((columns * pixels_per_square, rows * pixels_per_square), marginSize=0)
    source = np.array([[0, 0], [columns, 0], [columns, rows], [0, rows]], float) * pixels_per_square - 0.5
    H = cv2.getPerspectiveTransform(source.astype(np.float32), uv[:4].astype(np.float32))
    warped = cv2.warpPerspective(printed, H, cam.size, flags=cv2.INTER_LINEAR)
    mask = cv2.warpPerspective(np.full(printed.shape, 255, np.uint8), H, cam.size, flags=cv2.INTER_LINEAR)
    alpha = mask.astype(float) / 255.0
    image = (alpha * warped + (1 - alpha) * image).round().astype(np.uint8)
    inside = np.all((uv[4:] > 5) & (uv[4:] < np.array(cam.size) - 5), axis=1)
    return image, [(np.degrees(q), uv[4 + k], cam.name, f"C:{k}") for k in np.flatnonzero(inside)]


def prior_draw(robot: str, rng: np.random.Generator, limit: float = 2.0) -> dict:
    """Deviations drawn from robocal's default prior (lengths 1 mm, twists 0.1°, zeros 1°, β 0.1° on parallel
    axes), each within ±``limit`` of its σ (a truth the prior deems plausible)."""
    def draw(sigma):
        return float(np.clip(rng.normal(0.0, sigma), -limit * sigma, limit * sigma))

    t = independent.TABLES[robot]
    out = {f"beta{i + 1}": draw(np.radians(0.1)) for i in range(len(t) - 1) if abs(np.sin(np.radians(t[i][1]))) < 1e-9}
    for i in range(1, len(t) + 1):
        out[f"a{i}"], out[f"d{i}"] = draw(1.0), draw(1.0)
        out[f"alpha{i}"], out[f"theta{i}"] = draw(np.radians(0.1)), draw(np.radians(1.0))
    return out


@dataclass
class Sessions:
    """A camera campaign over sessions (:func:`sessions`): the truth, the cameras as the files describe
    them, the markers file's markers, each session's rows, and each session's true cell."""

    deviations: dict
    cameras: list[CellCamera]
    markers: dict
    rows: list[list]
    cells: list[Cell]


def sessions(robot: str, cameras: list[CellCamera], markers: dict, n_sessions: int, per_session: int,
             rng: np.random.Generator, centre_deg, spread_deg, *, noise: float = 0.5, bias: float = 0.0,
             remount_mm: float = 0.0, lens_px: float = 0.0) -> Sessions:
    """Sessions of a camera campaign with what a model does not contain: the marker body remounted
    between sessions (a rigid move of ``remount_mm`` mm RMS and 0.1° on the flange), a detector bias
    (px) shared by the markers one camera saw at one pose, and each lens off its file's intrinsics
    by ``lens_px`` px at the image's corners (its k1).  The truth is drawn from the prior."""
    deviations = prior_draw(robot, rng)
    true_cameras = []
    for c in cameras:
        corner = np.hypot(c.size[0] / 2, c.size[1] / 2) / c.K[0, 0]
        dk1 = lens_px / (c.K[0, 0] * corner ** 3)
        true_cameras.append(CellCamera(c.name, c.K, c.dist + np.array([dk1, 0, 0, 0, 0]), c.size, c.pose, c.link))
    rows, cells = [], []
    for _ in range(n_sessions):
        from scipy.spatial.transform import Rotation

        R = Rotation.from_rotvec(rng.normal(0.0, np.radians(0.1) / np.sqrt(3), 3)).as_matrix()
        t = rng.normal(0.0, remount_mm / np.sqrt(3), 3)
        moved = {k: (R @ p + t, None if n is None else R @ n) for k, (p, n) in markers.items()}
        cell = Cell(robot, deviations, true_cameras, moved)
        seen = cell.observe(poses(robot, per_session, rng, centre_deg, spread_deg), rng, noise)
        rows.append(with_shared_bias(seen, rng, bias) if bias else seen)
        cells.append(cell)
    return Sessions(deviations, cameras, markers, rows, cells)


def write_sessions(campaign: Sessions, which, path: Path) -> Path:
    """The rows of sessions ``which`` in one file with a session column."""
    lines = []
    for s in which:
        text = write_rows(campaign.rows[s], path, session=f"s{s}").read_text().splitlines()
        lines += text[1:] if lines else text
    path.write_text("\n".join(lines) + "\n")
    return path
