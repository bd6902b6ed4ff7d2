"""The camera: OpenCV's lens model against OpenCV itself, and the camera files users have
(OpenCV FileStorage YAML and JSON written by OpenCV, a ROS camera_info YAML), bad ones refused."""

import numpy as np
import pytest

from robocal.exceptions import InputError
from robocal.io.camera import load_camera, parse_camera
from robocal.model.camera import Camera

cv2 = pytest.importorskip("cv2")


def _random_camera(rng) -> Camera:
    return Camera("c", fx=rng.uniform(600, 1400), fy=rng.uniform(600, 1400), cx=rng.uniform(300, 700),
                  cy=rng.uniform(200, 500), distortion=np.array([rng.uniform(-0.3, 0.3), rng.uniform(-0.1, 0.1),
                                                                 rng.uniform(-0.01, 0.01), rng.uniform(-0.01, 0.01),
                                                                 rng.uniform(-0.05, 0.05)]), width=1280, height=960)


def test_the_lens_model_is_opencvs(rng):
    for _ in range(5):
        cam = _random_camera(rng)
        p = np.column_stack([rng.uniform(-400, 400, 200), rng.uniform(-300, 300, 200), rng.uniform(500, 2500, 200)])
        ours = cam.project(p)
        theirs, _ = cv2.projectPoints(p.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), cam.matrix, cam.distortion)
        np.testing.assert_allclose(ours, theirs.reshape(-1, 2), rtol=0, atol=1e-9)
    behind = cam.project(np.array([[0.0, 0.0, -1000.0], [10.0, 5.0, 800.0]]))
    assert np.all(np.isnan(behind[0])) and np.all(np.isfinite(behind[1]))
    assert cam.in_image(np.array([[10.0, 10.0], [-1.0, 10.0], [10.0, 961.0]])).tolist() == [True, False, False]


@pytest.mark.parametrize("suffix", [".yaml", ".json"])
def test_opencv_filestorage_files_written_by_opencv_are_read(tmp_path, rng, suffix):
    cam = _random_camera(rng)
    path = tmp_path / f"cam{suffix}"
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
    fs.write("image_width", 1280)
    fs.write("image_height", 960)
    fs.write("camera_matrix", cam.matrix)
    fs.write("distortion_coefficients", cam.distortion.reshape(1, 5))
    fs.release()
    got = load_camera(path)
    np.testing.assert_allclose(got.matrix, cam.matrix, rtol=1e-15)
    np.testing.assert_allclose(got.distortion, cam.distortion, rtol=1e-15)
    assert (got.width, got.height, got.name) == (1280, 960, "cam")


@pytest.mark.parametrize("suffix", [".yaml", ".json"])
def test_a_quoted_hash_and_a_flow_mapping_as_filestorage_writes_them_are_read(tmp_path, rng, suffix):
    """cv2.FileStorage writes a camera named "cam#2" quoted (no comment in it) and a matrix written as a flow
    mapping on one line or two ({ rows:3, cols:3, dt:d, data:[ … ] })."""
    cam = _random_camera(rng)
    path = tmp_path / f"flow{suffix}"
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
    fs.write("camera_name", "cam#2")
    fs.write("image_width", 1280)
    fs.startWriteStruct("camera_matrix", cv2.FileNode_MAP | cv2.FileNode_FLOW, "opencv-matrix")
    fs.write("rows", 3)
    fs.write("cols", 3)
    fs.write("dt", "d")
    fs.startWriteStruct("data", cv2.FileNode_SEQ | cv2.FileNode_FLOW)
    for v in cam.matrix.ravel():
        fs.write("", float(v))
    fs.endWriteStruct()
    fs.endWriteStruct()
    fs.write("distortion_coefficients", cam.distortion.reshape(1, 5))
    fs.release()
    got = load_camera(path)
    assert got.name == "cam#2" and got.width == 1280
    np.testing.assert_allclose(got.matrix, cam.matrix, rtol=1e-15)
    np.testing.assert_allclose(got.distortion, cam.distortion, rtol=1e-15)


ROS = """image_width: 640
image_height: 480
camera_name: wrist_cam
camera_matrix:
  rows: 3
  cols: 3
  data: [612.5, 0, 320.25,
         0, 611.75, 241.5, 0, 0, 1]
distortion_model: plumb_bob
distortion_coefficients:
  rows: 1
  cols: 5
  data: [0.1, -0.25, 0.001, -0.002, 0.05]
rectification_matrix:
  rows: 3
  cols: 3
  data: [1, 0, 0, 0, 1, 0, 0, 0, 1]
projection_matrix:
  rows: 3
  cols: 4
  data: [612.5, 0, 320.25, 0, 0, 611.75, 241.5, 0, 0, 0, 1, 0]
"""


def test_a_ros_camera_info_is_read():
    cam = parse_camera(ROS, source="wrist.yaml")
    assert (cam.name, cam.fx, cam.fy, cam.cx, cam.cy, cam.width, cam.height) == \
        ("wrist_cam", 612.5, 611.75, 320.25, 241.5, 640, 480)
    np.testing.assert_array_equal(cam.distortion, [0.1, -0.25, 0.001, -0.002, 0.05])


@pytest.mark.parametrize("change, message", [
    (lambda t: t.replace("camera_matrix", "camera_matrx"), "missing the intrinsics"),
    (lambda t: t.replace("plumb_bob", "equidistant"), "distortion model 'equidistant'"),
    (lambda t: t.replace("rows: 3\n  cols: 3\n  data: [612.5", "rows: 3\n  cols: 2\n  data: [612.5"),
     "says 3 × 2 but holds 9"),
    (lambda t: t.replace("612.5, 0, 320.25,", "-612.5, 0, 320.25,"), "fx, fy > 0"),
    (lambda t: t.replace("image_width: 640", "image_width: 640.5"), "not a whole number of pixels"),
    (lambda t: t.replace("cols: 5\n  data: [0.1, -0.25, 0.001, -0.002, 0.05]", "cols: 3\n  data: [0.1, -0.25, 0.001]"),
     "holds 3 coefficients"),
    (lambda t: t.replace("data: [612.5, 0, 320.25,", "data: [612.5, 0, nan,"), "not a finite number"),
])
def test_a_camera_file_that_cannot_be_used_is_refused_naming_what(change, message):
    with pytest.raises(InputError, match=message) as caught:
        parse_camera(change(ROS), source="wrist.yaml")
    assert "wrist.yaml" in str(caught.value)


def test_the_lens_models_derivative_is_its_finite_difference(rng):
    cam = _random_camera(rng)
    p = np.column_stack([rng.uniform(-400, 400, 50), rng.uniform(-300, 300, 50), rng.uniform(500, 2500, 50)])
    uv, J = cam.project_jacobian(p)
    np.testing.assert_allclose(uv, cam.project(p), atol=1e-12)
    h = 1e-4
    for k in range(3):
        e = np.zeros(3)
        e[k] = h
        fd = (cam.project(p + e) - cam.project(p - e)) / (2 * h)
        np.testing.assert_allclose(J[:, :, k], fd, rtol=1e-6, atol=1e-8)


def test_undistorting_inverts_the_lens_model_as_opencv_does(rng):
    cam = _random_camera(rng)
    p = np.column_stack([rng.uniform(-400, 400, 50), rng.uniform(-300, 300, 50), rng.uniform(800, 2500, 50)])
    uv = cam.project(p)
    theirs = cv2.undistortPoints(uv.reshape(-1, 1, 2), cam.matrix, cam.distortion).reshape(-1, 2)
    np.testing.assert_allclose(cam.normalized(uv), p[:, :2] / p[:, 2:], atol=1e-7)
    np.testing.assert_allclose(cam.normalized(uv), theirs, atol=1e-6)


@pytest.mark.parametrize("planar", [False, True])
def test_a_cameras_pose_from_points_and_pixels_is_opencvs_solvepnp(rng, planar):
    """Points in space (the direct linear transform), and points on one plane (markers on one face, a
    planar campaign: the homography), both to OpenCV's own iterative PnP."""
    from scipy.spatial.transform import Rotation

    cam = _random_camera(rng)
    R = Rotation.from_rotvec(rng.normal(0, 1, 3)).as_matrix()
    eye = rng.uniform(-500, 500, 3)
    pc = np.column_stack([rng.uniform(-400, 400, 40), rng.uniform(-300, 300, 40), rng.uniform(1200, 2000, 40)])
    if planar:  # onto a plane tilted to the optical axis
        normal = np.array([0.3, -0.2, 1.0]) / np.linalg.norm([0.3, -0.2, 1.0])
        pc -= np.outer((pc - [0.0, 0.0, 1500.0]) @ normal, normal)
    world = pc @ R.T + eye  # the camera frame (R, eye) in the world
    uv = cam.project(pc) + rng.normal(0, 0.3, (40, 2))
    ours = cam.pose_of(world, uv)
    ok, rvec, tvec = cv2.solvePnP(world, uv, cam.matrix, cam.distortion, flags=cv2.SOLVEPNP_ITERATIVE)
    Rc = cv2.Rodrigues(rvec)[0]  # world → camera
    np.testing.assert_allclose(ours[:3, :3], Rc.T, atol=1e-5)
    np.testing.assert_allclose(ours[:3, 3], (-Rc.T @ tvec).ravel(), atol=1e-2)
    assert np.linalg.norm(ours[:3, 3] - eye) < 5.0


def test_points_that_cannot_give_a_cameras_pose_are_refused(rng):
    cam = _random_camera(rng)
    line = np.outer(np.linspace(-1, 1, 10), [100.0, 50.0, 20.0]) + [0.0, 0.0, 1500.0]
    with pytest.raises(ValueError, match="on one line"):
        cam.pose_of(line, cam.project(line))
    with pytest.raises(ValueError, match="cannot give"):
        cam.pose_of(line[:3], cam.project(line[:3]))


def test_the_image_spans_half_a_pixel_beyond_its_outer_pixel_centres():
    """OpenCV's pixel (i, j) has its centre at (i, j): a W-pixel row spans [−0.5, W − 0.5]."""
    cam = Camera("c", 500.0, 500.0, 320.0, 240.0, width=640, height=480)
    inside = cam.in_image(np.array([[-0.5, -0.5], [639.5, 479.5], [0.0, 0.0]]))
    outside = cam.in_image(np.array([[-0.6, 10.0], [639.6, 10.0], [10.0, 479.6], [10.0, -0.51]]))
    assert inside.all() and not outside.any()


def test_detected_corners_are_in_opencvs_pixel_convention(tmp_path):
    """A marker drawn at whole pixels has its outer edge half a pixel before its first pixel's centre:
    robocal's detector reports it there, as OpenCV's camera model (projectPoints) places pixels."""
    from robocal.io.detect import detector, find_markers

    aruco = cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_4X4_50)
    for side, (row, col) in ((120, (100, 200)), (48, (310, 57))):
        image = np.full((480, 640), 255, np.uint8)
        image[row:row + side, col:col + side] = cv2.aruco.generateImageMarker(aruco, 7, side)
        cv2.imwrite(str(tmp_path / "m.png"), image)
        found = find_markers(tmp_path / "m.png", detector("DICT_4x4_50"))
        edges = np.array([[col, row], [col + side, row], [col + side, row + side], [col, row + side]]) - 0.5
        np.testing.assert_allclose(found[7], edges, atol=0.02)


@pytest.mark.parametrize("corners", [
    [[0, 0], [1, 1], [2, 2], [3, 3]],  # on one line
    [[5, 5], [5, 5], [5, 5], [5, 5]],  # one point
    [[0, 0], [1, 0], [float("nan"), 1], [0, 1]],  # a corner OpenCV could not place
    [[0, 0], [1e-300, 0], [2e-300, 1e-300], [0, 1e-300]],  # vanishingly small
])
def test_a_degenerate_detection_has_no_centre_and_raises_nothing(corners):
    from robocal.io.detect import centre

    assert centre(np.array(corners, float)) is None


@pytest.mark.parametrize("name", ["../outside.png", "/etc/hostname", "sub/../../outside.png"])
def test_detect_refuses_an_image_named_outside_its_folder(tmp_path, run_cli, name):
    folder = tmp_path / "images"
    folder.mkdir()
    (tmp_path / "outside.png").write_bytes(b"")
    log = tmp_path / "log.csv"
    log.write_text(f"image,q1,q2,q3,q4,q5,q6\n{name},0,10,20,30,40,50\n")
    code, _, err = run_cli("detect", folder, "--joints", log, "--camera", "wall", "--aruco", "4X4_50", "--out",
                           tmp_path / "rows.csv")
    assert code == 2 and "outside the images' folder" in err and "row 2" in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "rows.csv").exists()
