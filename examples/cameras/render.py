"""Render a planted camera cell's images: what `robocal detect` and `robocal calibrate` are tried on.

A KUKA KR5 arc whose geometry is off its drawing (up to 0.5 mm and 0.05° a parameter, drawn with the
seed) holds a cube of five ArUco markers (4X4_50, ids 1–5, 60 mm a side) on its flange, as
`markers.csv` beside this script describes them; the wall camera of `wall.yaml` (its lens
distortion included) films it at each pose.  Each marker is drawn by OpenCV, warped onto where its
corners project through a pinhole, and the image then distorted through the camera's lens model.

Writes, in the folder given:
  images/pose_NNN.png  the images (grey, 1600 × 1200);
  joints.csv           the joint log `robocal detect` reads (image, q1..q6 in deg);
  exact.csv            the camera rows of the exact pixels the images were drawn from (to compare);
  truth.toml           the planted robot, and the camera's pose in a comment.

    python examples/cameras/render.py --out cell [--poses 60] [--seed 1]
"""

from __future__ import annotations

import argparse
import csv
from pathlib import Path

import cv2
import numpy as np

import robocal
from robocal.io.camera import load_camera
from robocal.io.robotfile import save_robot
from robocal.math.se3 import frame_from_values

HERE = Path(__file__).parent
#: where the camera is (mm, in the robot's base frame) and the point it looks at
EYE, AT = np.array([1350.0, 650.0, 1000.0]), np.array([420.0, 0.0, 480.0])
#: the joint sets drawn: around this pose (deg), within ± this spread
CENTRE, SPREAD = np.array([0, -60, 90, 0, 30, 0.0]), np.array([50, 25, 25, 120, 40, 150.0])
PIXELS = 240  # a printed marker's bits, drawn before warping


def look_at(eye: np.ndarray, target: np.ndarray) -> np.ndarray:
    """A camera frame (4 × 4) at eye whose optical axis points at target, x to the image's right."""
    z = (target - eye) / np.linalg.norm(target - eye)
    x = np.cross(z, [0.0, 0.0, 1.0])
    x /= np.linalg.norm(x)
    T = np.eye(4)
    T[:3, :3] = np.column_stack([x, np.cross(z, x), z])
    T[:3, 3] = eye
    return T


def planted(rng: np.random.Generator) -> robocal.Robot:
    """The KR5 arc with its lengths off by up to 0.5 mm and its angles by up to 0.05°."""
    robot = robocal.load_robot("kr5-arc")
    geometry = robot.geometry.copy()
    geometry[:, [0, 3]] += rng.uniform(-0.5, 0.5, (6, 2))  # a, d
    geometry[:, [1, 2]] += np.radians(rng.uniform(-0.05, 0.05, (6, 2)))  # alpha, theta
    return robot.replace(geometry=geometry, name="KUKA KR5 arc (planted)")


def distortion_maps(camera) -> tuple[np.ndarray, np.ndarray]:
    """For each pixel of the distorted image, where it lies in the pinhole one (OpenCV's inverse of
    its own lens model)."""
    u, v = np.meshgrid(np.arange(camera.width, dtype=np.float32), np.arange(camera.height, dtype=np.float32))
    points = np.stack([u.ravel(), v.ravel()], axis=1).reshape(-1, 1, 2)
    pinhole = cv2.undistortPoints(points, camera.matrix, camera.distortion, P=camera.matrix).reshape(-1, 2)
    return (pinhole[:, 0].reshape(u.shape).astype(np.float32), pinhole[:, 1].reshape(u.shape).astype(np.float32))


def render(flange: np.ndarray, camera_pose: np.ndarray, camera, squares: dict, aruco, maps) -> tuple[np.ndarray, list]:
    """An image of the markers at a flange pose (4 × 4), and the rows (marker ``ID:k``, exact pixel)
    of the corners drawn."""
    canvas = np.full((camera.height, camera.width), 128, np.uint8)
    rows = []
    pad = PIXELS // 8
    for marker_id, (T, side) in squares.items():
        Tw = flange @ T
        to_eye = camera_pose[:3, 3] - Tw[:3, 3]
        if Tw[:3, 2] @ to_eye / np.linalg.norm(to_eye) < 0.3:  # seen edge-on or from behind
            continue
        corners = np.array([[-0.5, 0.5, 0], [0.5, 0.5, 0], [0.5, -0.5, 0], [-0.5, -0.5, 0]]) * side
        world = corners @ Tw[:3, :3].T + Tw[:3, 3]
        seen = (world - camera_pose[:3, 3]) @ camera_pose[:3, :3]  # in the camera's frame
        flat, _ = cv2.projectPoints(seen, np.zeros(3), np.zeros(3), camera.matrix, None)
        uv, _ = cv2.projectPoints(seen, np.zeros(3), np.zeros(3), camera.matrix, camera.distortion)
        flat, uv = flat.reshape(4, 2), uv.reshape(4, 2)
        size = np.array([camera.width, camera.height])
        if np.any(seen[:, 2] < 100) or np.any(uv < 10) or np.any(uv > size - 10):
            continue
        printed = np.full((PIXELS + 2 * pad, PIXELS + 2 * pad), 255, np.uint8)  # its white quiet zone
        printed[pad:pad + PIXELS, pad:pad + PIXELS] = cv2.aruco.generateImageMarker(aruco, marker_id, PIXELS)
        edge = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], float) * PIXELS + pad - 0.5  # pixel-centre coordinates
        H = cv2.getPerspectiveTransform(edge.astype(np.float32), flat.astype(np.float32))
        warped = cv2.warpPerspective(printed, H, (camera.width, camera.height), flags=cv2.INTER_LINEAR,
                                     borderValue=0)
        mask = cv2.warpPerspective(np.full(printed.shape, 255, np.uint8), H, (camera.width, camera.height))
        alpha = mask.astype(float) / 255.0
        canvas = (alpha * warped + (1 - alpha) * canvas).round().astype(np.uint8)
        rows += [(f"{marker_id}:{k}", uv[k]) for k in range(4)]
    image = cv2.remap(canvas, *maps, interpolation=cv2.INTER_LINEAR, borderValue=128)
    return image, rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, required=True, help="folder to write the cell into")
    parser.add_argument("--poses", type=int, default=60, help="joint sets to film")
    parser.add_argument("--seed", type=int, default=1)
    args = parser.parse_args()
    rng = np.random.default_rng(args.seed)
    robot = planted(rng)
    camera = load_camera(HERE / "wall.yaml", "wall")
    with open(HERE / "markers.csv", newline="") as f:  # each marker's frame on the flange (mm, deg) and size
        squares = {int(r["marker"]): (frame_from_values([float(r[k]) for k in "xyz"] + [np.radians(float(r[k]))
                                                                                      for k in ("rx", "ry", "rz")]),
                                      float(r["size"])) for r in csv.DictReader(f)}
    camera_pose = look_at(EYE, AT)
    aruco = cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_4X4_50)
    maps = distortion_maps(camera)
    (args.out / "images").mkdir(parents=True, exist_ok=True)
    log = [["image", *(f"q{i + 1}" for i in range(6))]]
    exact = [["pose_id", *(f"q{i + 1}" for i in range(6)), "u", "v", "camera", "marker"]]
    filmed = 0
    while filmed < args.poses:
        q = np.radians(rng.uniform(CENTRE - SPREAD, CENTRE + SPREAD))
        flange = robot.replace(tool=np.eye(4), targets={}).fk(q[None])[0]
        image, rows = render(flange, camera_pose, camera, squares, aruco, maps)
        if not rows:
            continue
        name = f"pose_{filmed:03d}.png"
        cv2.imwrite(str(args.out / "images" / name), image)
        degrees = [repr(float(v)) for v in np.degrees(q)]
        log.append([name, *degrees])
        exact += [[Path(name).stem, *degrees, repr(float(u)), repr(float(v)), "wall", marker]
                  for marker, (u, v) in rows]
        filmed += 1
    for path, rows in ((args.out / "joints.csv", log), (args.out / "exact.csv", exact)):
        with open(path, "w", newline="") as f:
            csv.writer(f, lineterminator="\n").writerows(rows)
    x, y, z = camera_pose[:3, 3]
    save_robot(robot, args.out / "truth.toml", comment="The planted robot the images were rendered from; the wall "
               f"camera's optical centre stands at ({x:.1f}, {y:.1f}, {z:.1f}) mm in its base frame.")
    print(f"rendered {filmed} images of {len(exact) - 1} marker corners into {args.out}")


if __name__ == "__main__":
    main()
