"""Calibration from camera pixels against an independent cell (tests.camera_world: its own
kinematics, OpenCV's projection and OpenCV's camera files): what the pixels give in millimetres,
what they cannot give (the scale) said by name, and bad camera inputs refused on one line."""

import json
import warnings

import numpy as np
import pytest

import robocal
from robocal.math.se3 import homogeneous
from robocal.model.camera import CameraMount
from tests import camera_world as cw
from tests import independent

pytest.importorskip("cv2")

CENTRE, SPREAD = [0, -60, 90, 0, 30, 0], [60, 30, 30, 90, 40, 90]
MARKER = np.array([20.0, 10, 80])


def _wall_cell(seed, tmp_path, n=300, noise=0.5):
    rng = np.random.default_rng(seed)
    dev = independent.uniform_deviations("kr5-arc", 1.0, np.radians(0.1), rng)
    cam = cw.camera("wall", cw.look_at([2036.0, 1209, 1335], [236.0, 9, 435]))
    cell = cw.Cell("kr5-arc", dev, [cam], {"m1": (MARKER, None)})
    rows = cell.observe(cw.poses("kr5-arc", n, rng, CENTRE, SPREAD), rng, noise)
    data = cw.write_rows(rows, tmp_path / f"rows{seed}.csv")
    cam.write(tmp_path / "wall.yaml")
    return cell, cam, data, rng


def _calibrate(robot, data, *specs, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return robocal.calibrate(robot, data, cameras=list(specs), **kw)


def test_a_wall_camera_seeing_one_marker_predicts_new_poses_in_millimetres(tmp_path):
    cell, cam, data, rng = _wall_cell(0, tmp_path)
    result = _calibrate("kr5-arc", data, f"wall={tmp_path / 'wall.yaml'}")
    # the pixels: fitted to their noise (0.5 px a coordinate: |δ| RMS 0.5·√2), σ found
    assert result.unit == "px" and result.metrics["after"].unit == "px"
    assert abs(result.metrics["after"].position["rms"] - 0.5 * 2 ** 0.5) < 0.07
    assert abs(result.noise.position - 0.5) < 0.05
    assert result.metrics["predicted"].unit == "px" and result.metrics["predicted"].position["rms"] < 0.8
    assert result.headline_text().startswith("reprojection RMS")
    # what the pixels cannot see, said: the wall camera is the measuring frame, the scale is the prior's
    said = " ".join(result.notes + result.warnings)
    assert "camera 'wall' is the measuring frame" in said
    assert any(w.startswith("the pixels do not fix the scale") for w in result.warnings)
    # in millimetres, on new poses, in the camera's frame: within 1.5× of the same data calibrated
    # with the true camera pose and the true marker given
    fresh = cw.poses("kr5-arc", 200, rng, CENTRE, SPREAD)
    truth = cell.marker_in(lambda q: cam.pose, fresh, "m1")
    ours = np.sqrt(np.mean(np.sum((result.robot.positions(fresh, ["m1"] * 200) - truth) ** 2, axis=1)))
    known = robocal.load_robot("kr5-arc").replace(targets={"m1": homogeneous(np.eye(3), MARKER)},
                                                   cameras={"wall": CameraMount(0, np.eye(4), known=True)})
    # the camera known at the measuring frame's origin: the same frame the truth is taken in
    floor_fit = _calibrate(known, data, f"wall={tmp_path / 'wall.yaml'}")
    floor = np.sqrt(np.mean(np.sum((floor_fit.robot.positions(fresh, ["m1"] * 200) - truth) ** 2, axis=1)))
    assert ours <= 1.5 * floor + 0.5, (ours, floor)
    assert "tool[m1]_x" in result.names and "tool[m1]_x" not in floor_fit.names


def test_the_camera_files_and_rows_are_checked_on_one_line(tmp_path, run_cli):
    cell, cam, data, _ = _wall_cell(1, tmp_path, n=60, noise=0.3)
    good = f"wall={tmp_path / 'wall.yaml'}"
    out = tmp_path / "out.json"

    def refused(*args, says):
        code, stdout, err = run_cli("calibrate", "kr5-arc", *args, "--out", out)
        assert code == 2 and not out.exists(), err
        assert len(err.strip().splitlines()) == 1 and "Traceback" not in err, err
        assert says in err, err
        return err

    # a camera the rows name and no file gives
    refused(data, says="camera 'wall' has no camera file")
    # a camera file without intrinsics
    (tmp_path / "empty.yaml").write_text("%YAML:1.0\n---\nimage_width: 1600\nimage_height: 1200\n")
    refused(data, "--camera", f"wall={tmp_path / 'empty.yaml'}", says="empty.yaml")
    # a camera file no row sees
    refused(data, "--camera", good, "--camera", f"door={tmp_path / 'wall.yaml'}", says="camera 'door'")
    # a pixel off the image, named by its row
    text = data.read_text().splitlines()
    cells = text[3].split(",")
    cells[-3] = "1650.5"
    (tmp_path / "off.csv").write_text("\n".join(text[:3] + [",".join(cells)] + text[4:]) + "\n")
    refused(tmp_path / "off.csv", "--camera", good, says="row 4")
    # a marker no markers file names
    (tmp_path / "markers.csv").write_text("marker,x,y,z\nm7,0,0,50\n")
    refused(data, "--camera", good, "--markers", tmp_path / "markers.csv", says="marker 'm1'")
    # a misspelled camera option
    refused(data, "--camera", f"wall={tmp_path / 'wall.yaml'},lnk=2", says="link=K")
    # a length noise for pixels
    refused(data, "--camera", good, "--noise", "0.5", says="--pixel-noise")
    # a known pose for a camera not given, or not six numbers
    refused(data, "--camera", good, "--camera-pose", "door=0,0,0,0,0,0", says="camera 'door' has a pose")
    refused(data, "--camera", good, "--camera-pose", "wall=0,0,0", says="NAME=x,y,z,rx,ry,rz")
    # camera rows evaluated without their camera's file, or with a model that has no pose for the camera
    code, _, err = run_cli("evaluate", "kr5-arc", data)
    assert code == 2 and "camera 'wall' has no camera file" in err and len(err.strip().splitlines()) == 1
    code, _, err = run_cli("evaluate", "kr5-arc", data, "--camera", good)
    assert code == 2 and "has no pose for it" in err and len(err.strip().splitlines()) == 1
    # validation rows of a camera the calibration has not, or of a marker it has not
    other = tmp_path / "other.csv"
    other.write_text("\n".join(text[:3] + [text[3].replace(",wall,", ",door,")]) + "\n")
    refused(data, "--camera", good, "--validate", other, says="camera 'door' has no camera file")
    other.write_text("\n".join(text[:3] + [text[3].replace(",m1", ",m9")]) + "\n")
    refused(data, "--camera", good, "--validate", other, says="marker 'm9' is named in no calibration row")
    # and the good one runs, its JSON in pixels, validation rows too
    rng = np.random.default_rng(9)
    fresh = cw.write_rows(cell.observe(cw.poses("kr5-arc", 40, rng, CENTRE, SPREAD), rng, 0.3), tmp_path / "fresh.csv")
    code, stdout, err = run_cli("calibrate", "kr5-arc", data, "--camera", good, "--validate", fresh, "--out", out)
    assert code == 0, err
    saved = json.loads(out.read_text())
    assert saved["metrics"]["after"]["unit"] == "px" and saved["metrics"]["validation_after"]["unit"] == "px"
    assert saved["metrics"]["validation_after"]["position"]["rms"] < 1.0


def _prior_draw(rng) -> dict:
    """A robot drawn from robocal's default prior (lengths 1 mm, twists 0.1°, zeros 1°, β 0.1°)."""
    out = {"beta2": rng.normal(0, np.radians(0.1))}
    for i in range(1, 7):
        out[f"a{i}"], out[f"d{i}"] = rng.normal(0, 1.0), rng.normal(0, 1.0)
        out[f"alpha{i}"], out[f"theta{i}"] = rng.normal(0, np.radians(0.1)), rng.normal(0, np.radians(1.0))
    return out


def _torso_cell(seed, tmp_path, n, deviations=None, bias=0.0):
    """Two cameras on link 1 (a torso's), 300 mm apart, seeing 20 markers at a dodecahedron's
    vertices (60 mm from its centre, 90 mm out from the flange) where they face the camera; with
    ``bias``, a detector bias (px) shared by the markers one camera saw at one pose."""
    rng = np.random.default_rng(seed)
    dev = _prior_draw(rng) if deviations is None else deviations
    g = independent.geometry("kr5-arc", dev)
    link1 = independent.link_frames(g, np.zeros(6))[0]
    cams = [cw.camera(name, np.linalg.inv(link1) @ cw.look_at([-300.0, off, 1300.0], [340.0, 0, 430]), link=1,
                      f=1100) for name, off in (("left", -150.0), ("right", 150.0))]
    markers = cw.dodecahedron(60.0, centre=(0, 0, 90.0))
    cell = cw.Cell("kr5-arc", dev, cams, markers)
    rows = cell.observe(cw.poses("kr5-arc", n, rng, CENTRE, SPREAD_TORSO), rng, 0.5)
    if bias:
        rows = cw.with_shared_bias(rows, rng, bias)
    folder = tmp_path / f"torso{seed}"
    folder.mkdir()
    data = cw.write_rows(rows, folder / "rows.csv")
    specs = [f"{c.name}={c.write(folder / f'{c.name}.yaml')},link=1" for c in cams]
    return cell, data, specs, cw.write_markers(markers, folder / "markers.csv"), rng


SPREAD_TORSO = [60, 30, 30, 120, 50, 150]


def _in_camera(robot, camera: str, q, marker="m1"):
    T = robot.camera_frames([camera] * len(q), q)
    p = robot.positions(q, [marker] * len(q))
    return np.einsum("mji,mj->mi", T[:, :3, :3], p - T[:, :3, 3])


def test_two_cameras_on_a_link_seeing_a_dodecahedron_predict_new_poses_in_millimetres(tmp_path):
    cell, data, specs, markers, rng = _torso_cell(7, tmp_path, 150)
    result = _calibrate("kr5-arc", data, *specs, markers=str(markers))
    assert abs(result.metrics["after"].position["rms"] - 0.5 * 2 ** 0.5) < 0.05
    said = " ".join(result.notes + result.warnings)
    assert "the base frame is not seen" in said and "scale: from the markers' known offsets" in said
    assert not any(n.startswith(("a1", "alpha1", "theta1", "d1", "base_")) for n in result.names)
    # in millimetres, on new poses, in the left camera's frame (what cameras on link 1 can see: neither
    # the base nor joint 1, nor joint 2's zero and offset apart from their own mounting), against the same
    # pixels calibrated with the cameras' true mounting given
    fresh = cw.poses("kr5-arc", 200, rng, CENTRE, SPREAD_TORSO)
    seen = cell.seen_from(cell.cameras[0], fresh, "m1")
    known = robocal.load_robot("kr5-arc").replace(cameras={c.name: CameraMount(1, c.pose, known=True)
                                                           for c in cell.cameras})
    floor = _calibrate(known, data, *specs, markers=str(markers))
    ours, best = _in_camera(result.robot, "left", fresh) - seen, _in_camera(floor.robot, "left", fresh) - seen
    across = np.sqrt(np.mean(np.sum(ours[:, :2] ** 2, axis=1)))
    assert across <= 1.5 * np.sqrt(np.mean(np.sum(best[:, :2] ** 2, axis=1)))
    # along the optical axis the mounting is found from the markers' apparent size alone: several times the
    # floor's error, and as large as the model says it is
    from robocal.model.parameters import ParameterSpace

    space = ParameterSpace.of(result.robot, result.measurements.target_names)
    depth = np.empty(len(result.names))
    for j, i in enumerate(space.index(result.names)):
        step = np.zeros(space.size)
        step[i] = 1e-6
        depth[j] = np.mean(_in_camera(space.apply(step), "left", fresh)[:, 2]
                           - _in_camera(space.apply(-step), "left", fresh)[:, 2]) / 2e-6
    assert abs(ours[:, 2].mean()) <= 3.0 * np.sqrt(depth @ result.covariance @ depth)
    assert np.sqrt(np.mean(np.sum(ours ** 2, axis=1))) < 0.5


def _z_scores(cell, result, fresh) -> np.ndarray:
    """The calibrated model's marker m1 in the left camera's frame at joints ``fresh``, less the truth,
    over its σ from the posterior covariance (by finite differences here, through the calibrated model's
    own parameter space)."""
    from robocal.model.parameters import ParameterSpace

    space = ParameterSpace.of(result.robot, result.measurements.target_names)
    index = space.index(result.names)
    J = np.empty((3 * len(fresh), len(index)))
    for j, i in enumerate(index):
        step = np.zeros(space.size)
        step[i] = 1e-6
        J[:, j] = ((_in_camera(space.apply(step), "left", fresh) - _in_camera(space.apply(-step), "left", fresh))
                   / 2e-6).ravel()
    sigma = np.sqrt(np.einsum("ij,jk,ik->i", J, result.covariance, J))
    truth = cell.seen_from(cell.cameras[0], fresh, "m1").ravel()
    return (_in_camera(result.robot, "left", fresh).ravel() - truth) / sigma


def test_the_sigma_of_a_camera_calibration_is_the_spread_over_50_draws(tmp_path):
    """Robots drawn from the prior, pixels with 0.5 px noise: the predicted marker in the left camera's
    frame at new poses, less the truth, over its σ from the posterior covariance (by finite
    differences here, through the calibrated model's own parameter space)."""
    zs = []
    for draw in range(50):
        cell, data, specs, markers, rng = _torso_cell(1000 + draw, tmp_path, 40)
        # every joint parameter: what the defaults choose for a robot drawn from the prior (checked on the
        # first draw), without refitting the simpler sets each draw
        result = _calibrate("kr5-arc", data, *specs, markers=str(markers), params="all")
        if draw == 0:
            default = _calibrate("kr5-arc", data, *specs, markers=str(markers))
            assert any(n.startswith("parameters auto: all,") for n in default.notes) and default.names == result.names
        zs.append(_z_scores(cell, result, cw.poses("kr5-arc", 10, rng, CENTRE, SPREAD_TORSO)))
    z = np.concatenate(zs)
    assert 0.8 <= np.std(z) <= 1.25, np.std(z)


def test_simulate_plants_a_camera_campaign_that_calibrate_reads_back(tmp_path, run_cli):
    cw.camera("wall", np.eye(4)).write(tmp_path / "wall.yaml")
    data, truth, out = tmp_path / "sim.csv", tmp_path / "truth.toml", tmp_path / "fit.json"
    code, _, err = run_cli("simulate", "kr5-arc", "--camera", f"wall={tmp_path / 'wall.yaml'}", "--poses", 150,
                           "--pixel-noise", 0.3, "--errors", "uniform:0.5,0.001", "--seed", 3, "--out", data,
                           "--truth", truth)
    assert code == 0, err
    line = next(x for x in truth.read_text().splitlines() if x.startswith("# Camera wall in the measuring frame"))
    values = [float(v) for v in line.split("=")[1].split("(")[0].split(",")]
    from robocal.math.se3 import frame_from_values

    camera = frame_from_values(values[:3] + [np.radians(v) for v in values[3:]])
    code, _, err = run_cli("calibrate", "kr5-arc", data, "--camera", f"wall={tmp_path / 'wall.yaml'}", "--out", out)
    assert code == 0, err
    saved = json.loads(out.read_text())
    assert saved["headline"]["unit"] == "px"
    assert abs(saved["metrics"]["after"]["position"]["rms"] - 0.3 * 2 ** 0.5) < 0.05
    # the wall camera is the measuring frame: the base found in it is where the robot stood, seen from the camera
    base = np.linalg.inv(camera)
    found = saved["frames_identified"]["base"]["xyz_mm"]
    assert np.linalg.norm(np.array(found) - base[:3, 3]) < 5.0
    assert saved["frames_identified"]["camera[wall]"]["xyz_mm"] == [0.0, 0.0, 0.0]
    # a tracker's option in a camera campaign is refused
    code, _, err = run_cli("simulate", "kr5-arc", "--camera", f"wall={tmp_path / 'wall.yaml'}", "--noise", 0.1,
                           "--out", tmp_path / "x.csv")
    assert code == 2 and "--noise is for tracker campaigns" in err


def test_images_rendered_from_a_planted_robot_detect_and_calibrate_to_the_same_model(tmp_path, run_cli):
    """A wall camera (no distortion: the renderer warps planes) films a cube of five ArUco markers on the
    flange, each drawn by OpenCV; robocal detect finds their corners, and the calibration from them is
    the one from the exact pixels the images were rendered from, within the detection's noise."""
    import cv2

    rng = np.random.default_rng(4)
    cam = cw.camera("wall", cw.look_at([1300.0, 700, 1000], [400.0, 0, 500]), f=1300, dist=(0, 0, 0, 0, 0),
                    size=(1280, 960))
    squares = cw.cube_markers()
    cell = cw.Cell("kr5-arc", independent.uniform_deviations("kr5-arc", 1.0, np.radians(0.1), rng), [cam],
                   cw.square_points(squares))
    folder = tmp_path / "images"
    folder.mkdir()
    log, exact = ["image," + ",".join(f"q{i + 1}" for i in range(6))], []
    for i, q in enumerate(cw.poses("kr5-arc", 60, rng, [0, -60, 90, 0, 30, 0], [50, 25, 25, 120, 40, 150])):
        image, rows = cw.render(cell, cam, q, squares, cv2.aruco.DICT_4X4_50)
        cv2.imwrite(str(folder / f"pose{i:03d}.png"), image)
        log.append(f"pose{i:03d}.png," + ",".join(repr(float(v)) for v in np.degrees(q)))
        exact += rows
    (tmp_path / "joints.csv").write_text("\n".join(log) + "\n")
    detected = tmp_path / "detected.csv"
    code, out, err = run_cli("detect", folder, "--joints", tmp_path / "joints.csv", "--camera", "wall", "--aruco",
                             "4x4_50", "--out", detected)
    assert code == 0, err
    # every corner drawn is found, where it was drawn, to a fraction of a pixel
    from robocal.io.measurements import load_measurements

    found = load_measurements(detected, n_joints=6)
    truth = {(tuple(np.round(q, 9)), m): (q, uv, c, m) for q, uv, c, m in exact}
    drawn = [truth[(tuple(np.round(np.degrees(found.q[i]), 9)), found.targets[i])] for i in range(found.n_poses)]
    assert found.n_poses >= 0.95 * len(exact)  # a marker seen edge-on may be missed, as in a real cell
    miss = found.pixels - np.array([uv for _, uv, _, _ in drawn])
    noise = float(np.sqrt(np.mean(np.sum(miss ** 2, axis=1))))
    assert noise < 0.8 and np.abs(miss.mean(0)).max() < 0.1
    # the same model as the exact pixels give, within what the detection's noise leaves uncertain
    markers = cw.write_square_markers(squares, tmp_path / "markers.csv")
    spec = f"wall={cam.write(tmp_path / 'wall.yaml')}"
    from_images = _calibrate("kr5-arc", str(detected), spec, markers=str(markers))
    from_pixels = _calibrate("kr5-arc", str(cw.write_rows(drawn, tmp_path / "exact.csv")), spec, markers=str(markers))
    assert abs(from_images.noise.position - noise / 2 ** 0.5) < 0.1
    fresh = cw.poses("kr5-arc", 100, rng, [0, -60, 90, 0, 30, 0], [50, 25, 25, 120, 40, 150])
    a, b = (r.robot.positions(fresh, ["1"] * 100) for r in (from_images, from_pixels))
    from robocal.model.uncertainty import predicted_sigma

    sigma = predicted_sigma(from_images.robot, fresh, ["1"] * 100)
    assert np.sqrt(np.mean(np.sum((a - b) ** 2, axis=1))) <= 3.0 * np.sqrt(np.mean(sigma ** 2))
    assert np.sqrt(np.mean(sigma ** 2)) < 1.0
    # an image the log names and the folder has not, and a dictionary OpenCV has not: one line each
    (folder / "pose000.png").unlink()
    code, _, err = run_cli("detect", folder, "--joints", tmp_path / "joints.csv", "--camera", "wall", "--aruco",
                           "4x4_50", "--out", tmp_path / "again.csv")
    assert code == 2 and "row 2" in err and "pose000.png" in err and not (tmp_path / "again.csv").exists()
    code, _, err = run_cli("detect", folder, "--joints", tmp_path / "joints.csv", "--camera", "wall", "--aruco",
                           "4x4_55", "--out", tmp_path / "again.csv")
    assert code == 2 and "unknown ArUco dictionary '4x4_55'" in err


def test_plan_chooses_poses_that_keep_the_marker_in_a_cameras_view(tmp_path, run_cli):
    from scipy.spatial.transform import Rotation

    cam = cw.camera("wall", cw.look_at([1500.0, 900, 1200], [500.0, 200, 400]))
    cam.write(tmp_path / "wall.yaml")
    xyz = cam.pose[:3, 3]
    rpy = Rotation.from_matrix(cam.pose[:3, :3]).as_euler("xyz", degrees=True)
    out, summary = tmp_path / "plan.csv", tmp_path / "plan.json"
    code, _, err = run_cli("plan", "kr5-arc", "--camera", f"wall={tmp_path / 'wall.yaml'}", "--camera-pose",
                           "wall=" + ",".join(f"{v:.9g}" for v in (*xyz, *rpy)), "--poses", 25, "--candidates", 1500,
                           "--out", out, "--summary", summary)
    assert code == 0, err
    planned = json.loads(summary.read_text())
    assert planned["candidates_in_view"]["seeing_a_marker"] < 0.8 * planned["candidates_in_view"]["drawn"]
    assert planned["value"] > planned["random_median"]
    # each planned pose puts the tool point on the camera's image (the independent cell says so)
    lines = out.read_text().splitlines()
    assert lines[0] == "pose_id,image,q1,q2,q3,q4,q5,q6" and len(lines) == 26
    q = np.radians([[float(v) for v in line.split(",")[2:]] for line in lines[1:]])
    cell = cw.Cell("kr5-arc", {}, [cam], {"m1": (np.zeros(3), None)})
    seen = cell.observe(q, np.random.default_rng(0), 0.0)
    assert len(seen) == 25


TORSO_URDF = """<?xml version="1.0"?>
<robot name="torso_arm">
  <link name="world"/><link name="torso_link"/><link name="head"/><link name="eye"/>
  <link name="l1"/><link name="l2"/><link name="l3"/><link name="l4"/><link name="l5"/><link name="tool"/>
  <joint name="torso" type="revolute"><parent link="world"/><child link="torso_link"/>
    <origin xyz="0 0 0.8"/><axis xyz="0 0 1"/><limit lower="-2" upper="2" effort="1" velocity="1"/></joint>
  <joint name="neck" type="fixed"><parent link="torso_link"/><child link="head"/>
    <origin xyz="0.05 0 0.55" rpy="0 0.3 0"/></joint>
  <joint name="optical" type="fixed"><parent link="head"/><child link="eye"/>
    <origin xyz="0.08 0 0" rpy="-1.5707963 0 -1.5707963"/></joint>
  <joint name="s1" type="revolute"><parent link="torso_link"/><child link="l1"/>
    <origin xyz="0.1 -0.25 0.4" rpy="1.5707963 0 0"/><axis xyz="0 0 1"/>
    <limit lower="-2" upper="2" effort="1" velocity="1"/></joint>
  <joint name="s2" type="revolute"><parent link="l1"/><child link="l2"/>
    <origin xyz="0 0 0.12" rpy="-1.5707963 0 0"/><axis xyz="0 0 1"/>
    <limit lower="-2" upper="2" effort="1" velocity="1"/></joint>
  <joint name="e1" type="revolute"><parent link="l2"/><child link="l3"/>
    <origin xyz="0.3 0 0" rpy="1.5707963 0 0"/><axis xyz="0 0 1"/>
    <limit lower="-2" upper="2" effort="1" velocity="1"/></joint>
  <joint name="e2" type="revolute"><parent link="l3"/><child link="l4"/>
    <origin xyz="0 0.02 0.28" rpy="-1.5707963 0 0"/><axis xyz="0 0 1"/>
    <limit lower="-2" upper="2" effort="1" velocity="1"/></joint>
  <joint name="w1" type="revolute"><parent link="l4"/><child link="l5"/>
    <origin xyz="0.12 0 0" rpy="1.5707963 0 0"/><axis xyz="0 0 1"/>
    <limit lower="-2" upper="2" effort="1" velocity="1"/></joint>
  <joint name="flange" type="fixed"><parent link="l5"/><child link="tool"/><origin xyz="0 0 0.09"/></joint>
</robot>
"""


def test_a_camera_on_a_urdf_torso_link_is_placed_by_the_links_own_fixed_joints(tmp_path, run_cli):
    """A camera whose link hangs from the torso by fixed joints, named by that link: robocal's chain
    reaches its frame as the URDF's own transforms do (an independent reader, OpenCV's projection)."""
    import cv2

    from tests.independent_urdf import Urdf

    (tmp_path / "torso.urdf").write_text(TORSO_URDF)
    urdf = Urdf(TORSO_URDF)
    cam = cw.camera("head", np.eye(4), f=700.0, size=(1280, 960), dist=(-0.05, 0.01, 0.0, 0.0, 0.0))
    cam.write(tmp_path / "head.yaml")
    rng = np.random.default_rng(2)
    lines = ["q1,q2,q3,q4,q5,q6,u,v,camera,marker"]
    names = ["torso", "s1", "s2", "e1", "e2", "w1"]
    for _ in range(2000):
        q = rng.uniform(-1.2, 1.2, 6)
        values = dict(zip(names, q))
        eye = urdf.transform("world", "eye", values)
        tip = urdf.transform("world", "tool", values)[:3, 3]
        pc = eye[:3, :3].T @ (tip - eye[:3, 3]) * 1000.0  # mm in the camera's frame
        if pc[2] < 100:
            continue
        uv, _ = cv2.projectPoints(pc.reshape(1, 1, 3), np.zeros(3), np.zeros(3), cam.K, cam.dist)
        u, v = uv.ravel() + rng.normal(0, 0.3, 2)
        if 10 < u < 1270 and 10 < v < 950:
            lines.append(",".join(repr(float(np.degrees(x))) for x in q) + f",{float(u)!r},{float(v)!r},head,tip")
    assert len(lines) > 100
    (tmp_path / "rows.csv").write_text("\n".join(lines) + "\n")
    (tmp_path / "tip.csv").write_text("marker,x,y,z\ntip,0,0,90\n")  # the flange is l5; the tool 90 mm out
    base = ["calibrate", tmp_path / "torso.urdf", tmp_path / "rows.csv", "--tip-link", "tool", "--camera",
            f"head={tmp_path / 'head.yaml'},link=eye", "--markers", tmp_path / "tip.csv"]
    out = tmp_path / "fit.json"
    # its pose known at the link (0 from it): the nominal chain sees every pixel where it was drawn
    code, _, err = run_cli(*base, "--camera-pose", "head=0,0,0,0,0,0", "--out", out)
    assert code == 0, err
    fit = json.loads(out.read_text())
    assert fit["metrics"]["before"]["position"]["rms"] < 0.6
    assert fit["frames_identified"]["camera[head]"]["link"] == 1
    # unknown, it is found from the pixels: the same fit
    code, _, err = run_cli(*base, "--out", out)
    assert code == 0, err
    assert json.loads(out.read_text())["metrics"]["after"]["position"]["rms"] < 0.6
    code, _, err = run_cli(*base[:-4], "--camera", f"head={tmp_path / 'head.yaml'},link=nowhere", "--out", out)
    assert code == 2 and "nowhere" in err


def test_camera_rows_beside_tracker_rows_are_each_weighed_and_reported_in_their_unit(tmp_path, run_cli):
    """Tracker rows (an SMR, 0.02 mm) and a wall camera's rows (0.5 px) of one campaign in one file:
    the tracker's frame is the measuring frame, the camera is found in it, each kind's σ is its own,
    the headline is in mm on the tracker rows and the pixels' figures stand apart."""
    rng = np.random.default_rng(5)
    dev = independent.uniform_deviations("kr5-arc", 1.0, np.radians(0.1), rng)
    cam = cw.camera("wall", cw.look_at([2036.0, 1209, 1335], [236.0, 9, 435]))
    cell = cw.Cell("kr5-arc", dev, [cam], {"m1": (MARKER, None)})
    q = cw.poses("kr5-arc", 200, rng, CENTRE, SPREAD)
    g = independent.geometry("kr5-arc", dev)
    lines = ["q1,q2,q3,q4,q5,q6,x,y,z,u,v,camera,marker,target"]
    for qi in q[:120]:
        T = independent.pose(g, qi)
        p = T[:3, :3] @ np.array([0.0, 40, 60]) + T[:3, 3] + rng.normal(0, 0.02, 3)
        lines.append(",".join(repr(float(v)) for v in (*np.degrees(qi), *p)) + ",,,,,smr")
    for qd, uv, c, m in cell.observe(q, rng, 0.5):
        lines.append(",".join(repr(float(v)) for v in qd) + f",,,,{float(uv[0])!r},{float(uv[1])!r},{c},{m},")
    (tmp_path / "rows.csv").write_text("\n".join(lines) + "\n")
    out = tmp_path / "fit.json"
    code, stdout, err = run_cli("calibrate", "kr5-arc", tmp_path / "rows.csv", "--camera",
                                f"wall={cam.write(tmp_path / 'wall.yaml')}", "--out", out)
    assert code == 0, err
    fit = json.loads(out.read_text())
    assert fit["headline"]["unit"] == "mm" and fit["metrics"]["after"]["n"] == 120
    assert fit["metrics"]["after"]["position"]["rms"] < 0.05
    assert abs(fit["sigma_by_kind"]["tracker"] - 0.02) < 0.004 and abs(fit["sigma_by_kind"]["camera"] - 0.5) < 0.08
    assert fit["cameras"]["after"]["reprojection_rms_px"] < 0.8 < fit["cameras"]["before"]["reprojection_rms_px"]
    found = np.array(fit["frames_identified"]["camera[wall]"]["xyz_mm"])
    assert np.linalg.norm(found - cam.pose[:3, 3]) < 3.0  # the tracker's frame is the world's here
    assert "camera rows, after: reprojection rms px" in stdout and "σ by kind" in stdout


def test_square_markers_of_known_size_but_unknown_place_give_the_scale(tmp_path):
    """A wall camera and a cube of five square markers 60 mm a side, their place on the flange unknown:
    the corners' known sides and diagonals give the scale the corners alone cannot."""
    rng = np.random.default_rng(4)
    cam = cw.camera("wall", cw.look_at([1300.0, 700, 1000], [400.0, 0, 500]), f=1300, size=(1280, 960))
    squares = cw.cube_markers()
    cell = cw.Cell("kr5-arc", independent.uniform_deviations("kr5-arc", 1.0, np.radians(0.1), rng), [cam],
                   cw.square_points(squares))
    data = cw.write_rows(cell.observe(cw.poses("kr5-arc", 120, rng, CENTRE, [50, 25, 25, 120, 40, 150]), rng, 0.5,
                                      facing=0.3), tmp_path / "rows.csv")
    (tmp_path / "free.csv").write_text("marker,x,y,z,rx,ry,rz,size\n" + "".join(f"{k},,,,,,,60\n" for k in squares))
    spec = f"wall={cam.write(tmp_path / 'wall.yaml')}"
    fresh = cw.poses("kr5-arc", 200, rng, CENTRE, [50, 25, 25, 120, 40, 150])
    truth = cell.marker_in(lambda q: cam.pose, fresh, "1:0")
    errors = {}
    for label, kw in (("corners", {}), ("squares", {"markers": str(tmp_path / "free.csv")})):
        result = _calibrate("kr5-arc", str(data), spec, **kw)
        errors[label] = np.sqrt(np.mean(np.sum((result.robot.positions(fresh, ["1:0"] * 200) - truth) ** 2, axis=1)))
        said = " ".join(result.notes + result.warnings)
        assert ("scale: from the markers' known sizes" in said) == (label == "squares")
    assert errors["squares"] < 0.7 * errors["corners"], errors


def test_a_charuco_board_on_the_flange_detects_and_calibrates_with_its_place_found(tmp_path, run_cli):
    """A ChArUco board (5 × 7 squares of 40 mm) held on the flange where nobody measured it: robocal detect
    finds its corners and writes its layout as one body; the calibration finds its place and takes the
    scale from its known geometry, as the exact pixels of the same corners would."""
    import cv2

    rng = np.random.default_rng(6)
    cam = cw.camera("wall", cw.look_at([1300.0, 700, 1000], [400.0, 0, 500]), f=1300, dist=(0, 0, 0, 0, 0),
                    size=(1280, 960))
    board = cv2.aruco.CharucoBoard((5, 7), 40.0, 30.0, cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_4X4_50))
    from scipy.spatial.transform import Rotation

    pose = np.eye(4)  # the board 90 mm out, turned, its face towards −z of the flange turned about x
    pose[:3, :3] = Rotation.from_euler("xyz", [180, 0, 20], degrees=True).as_matrix()
    pose[:3, 3] = [-100.0, -140.0, 90.0]
    cell = cw.Cell("kr5-arc", independent.uniform_deviations("kr5-arc", 1.0, np.radians(0.1), rng), [cam], {})
    folder = tmp_path / "images"
    folder.mkdir()
    log, exact = ["image," + ",".join(f"q{i + 1}" for i in range(6))], []
    for i, q in enumerate(cw.poses("kr5-arc", 60, rng, [0, -60, 90, 0, 30, 0], [50, 25, 25, 60, 35, 90])):
        image, rows = cw.render_board(cell, cam, q, pose, board)
        cv2.imwrite(str(folder / f"p{i:03d}.png"), image)
        log.append(f"p{i:03d}.png," + ",".join(repr(float(v)) for v in np.degrees(q)))
        exact += rows
    (tmp_path / "joints.csv").write_text("\n".join(log) + "\n")
    detected, layout = tmp_path / "detected.csv", tmp_path / "board.csv"
    code, _, err = run_cli("detect", folder, "--joints", tmp_path / "joints.csv", "--camera", "wall", "--aruco",
                           "4X4_50", "--charuco", "5x7,40,30", "--markers-out", layout, "--out", detected)
    assert code == 0, err
    from robocal.io.measurements import load_measurements

    found = load_measurements(detected, n_joints=6)
    truth = {(tuple(np.round(q, 9)), m): uv for q, uv, _, m in exact}
    miss = np.array([found.pixels[i] - truth[(tuple(np.round(np.degrees(found.q[i]), 9)), found.targets[i])]
                     for i in range(found.n_poses)])
    assert found.n_poses >= 0.8 * len(exact) and len(exact) > 200  # a corner is found where its markers are
    assert np.sqrt(np.mean(np.sum(miss ** 2, axis=1))) < 0.3
    spec = f"wall={cam.write(tmp_path / 'wall.yaml')}"
    result = _calibrate("kr5-arc", str(detected), spec, markers=str(layout))
    said = " ".join(result.notes + result.warnings)
    assert "scale: from the markers' known sizes" in said
    # the board's corners found where they are on the flange
    corners = np.asarray(board.getChessboardCorners(), float)
    placed = (pose[:3, :3] @ corners.T).T + pose[:3, 3]
    found_at = np.array([result.robot.targets[f"C:{k}"][:3, 3] for k in range(len(corners))
                         if f"C:{k}" in result.robot.targets])
    assert len(found_at) >= 20
    # (a calibration moves the flange frame with the chain's last parameters: compare the board's shape)
    d_found = np.linalg.norm(found_at[:, None] - found_at[None], axis=-1)
    d_true = np.linalg.norm(placed[:len(found_at), None] - placed[None, :len(found_at)], axis=-1)
    assert np.abs(d_found - d_true).max() < 0.5


def test_a_calibrated_stereo_rig_on_the_link_predicts_depth_within_the_floor(tmp_path):
    """The two torso cameras as a rig whose relative pose is known (NAME@OTHER): the pair triangulates,
    and new poses are predicted along the optical axis too within 1.5× of the fit that knows both
    cameras' mounting."""
    from robocal.math.se3 import transform_to_xyz_rpy

    cell, data, specs, markers, rng = _torso_cell(7, tmp_path, 150)
    left, right = cell.cameras
    xyz, rpy = transform_to_xyz_rpy(np.linalg.inv(left.pose) @ right.pose)
    pose = "right@left=" + ",".join(f"{v:.12g}" for v in (*xyz, *np.degrees(rpy)))
    result = _calibrate("kr5-arc", data, *specs, markers=str(markers), camera_poses=(pose,))
    assert "camera-pose" not in " ".join(result.warnings)
    assert any("fixed as given (a calibrated rig)" in n for n in result.notes)
    known = robocal.load_robot("kr5-arc").replace(cameras={c.name: CameraMount(1, c.pose, known=True)
                                                           for c in cell.cameras})
    floor = _calibrate(known, data, *specs, markers=str(markers))
    fresh = cw.poses("kr5-arc", 200, rng, CENTRE, SPREAD_TORSO)
    seen = cell.seen_from(left, fresh, "m1")
    ours, best = _in_camera(result.robot, "left", fresh) - seen, _in_camera(floor.robot, "left", fresh) - seen
    rms = lambda e: float(np.sqrt(np.mean(np.sum(e ** 2, axis=1))))  # noqa: E731
    assert rms(ours[:, :2]) <= 1.5 * rms(best[:, :2]) and rms(ours[:, 2:]) <= 1.5 * rms(best[:, 2:])
    saved = result.to_dict()["frames_identified"]["camera[right]"]
    assert saved["known"] and saved["of"] == "left" and saved["link"] == 1


def test_a_subset_of_rows_keeps_each_rows_camera_whichever_camera_comes_first(tmp_path):
    """A fold of the rows whose first row another camera saw predicts its rows as the whole data
    does: each row's camera is found by name, not by the order the rows name them in."""
    from robocal.calibration.config import CalibrationConfig
    from robocal.calibration.fit.parametric import fit_parametric, term_spec
    from robocal.calibration.inputs import load_inputs

    _, data, specs, markers, _ = _torso_cell(11, tmp_path, 30)
    config = CalibrationConfig(cameras=specs, markers=str(markers))
    inputs = load_inputs("kr5-arc", str(data), None, config, None)
    fit = fit_parametric(inputs, config, term_spec((), inputs.meas, config))
    problem, x = fit.estimate.problem, fit.estimate.x
    meas = problem.meas
    order = np.argsort(np.asarray(meas.camera) != "right", kind="stable")  # the right camera's rows first
    assert meas.camera[0] == "left" and meas.camera[order[0]] == "right"
    sub = problem.setup.with_measurements(meas.subset(order)).problem(problem.names)
    np.testing.assert_allclose(sub.errors(x)[0], problem.errors(x)[0][order], atol=1e-9)
    np.testing.assert_allclose(sub.residual_jacobian(x), problem.residual_jacobian(x).reshape(len(meas.q), 3, -1)
                               [order].reshape(3 * len(order), -1), atol=1e-9)


def test_a_camera_calibrations_export_loads_everywhere_and_reproduces_its_held_out_figure(tmp_path, run_cli):
    """The export carries the cameras' poses and the markers: evaluate reads camera rows with it and
    gives the validation figure calibrate gave; compensate, filter and load_robot take it."""
    cell, data, specs, markers, rng = _torso_cell(21, tmp_path, 60)
    held = cw.write_rows(cell.observe(cw.poses("kr5-arc", 40, rng, CENTRE, SPREAD_TORSO), rng, 0.5),
                         tmp_path / "held.csv")
    out, export = tmp_path / "fit.json", tmp_path / "cal.toml"
    cams = [a for s in specs for a in ("--camera", s)]
    code, _, err = run_cli("calibrate", "kr5-arc", data, *cams, "--markers", markers, "--validate", held,
                           "--out", out, "--export", export, "-q")
    assert code == 0, err
    saved = json.loads(out.read_text())
    robot = robocal.load_robot(str(export))
    assert set(robot.cameras) == {"left", "right"} and all(m.link == 1 for m in robot.cameras.values())
    assert robot.uncertainty is not None and any(n.startswith("camera[") for n in robot.uncertainty.names)
    plain = [s.split(",")[0] for s in specs]  # the link is the model's: NAME=FILE is enough
    code, stdout, err = run_cli("evaluate", export, held, *[a for s in plain for a in ("--camera", s)], "--json")
    assert code == 0, err
    validation = saved["metrics"]["validation_after"]["position"]["rms"]
    assert json.loads(stdout)["position"]["rms"] == pytest.approx(validation, rel=1e-9)
    # a link that is not the model's, and a camera the model has no pose for, are one line each
    code, _, err = run_cli("evaluate", export, held, "--camera", plain[0] + ",link=2", "--camera", plain[1])
    assert code == 2 and "on link 2, but the model has it on link 1" in err
    code, _, err = run_cli("evaluate", "kr5-arc", held, *[a for s in plain for a in ("--camera", s)])
    assert code == 2 and "has no pose for it" in err and len(err.strip().splitlines()) == 1
    # the other commands take it as any calibrated model
    q = np.radians([[0, -60, 90, 0, 30, 0], [10, -50, 80, 20, 40, 10]])
    goals = tmp_path / "goals.csv"
    goals.write_text("q1,q2,q3,q4,q5,q6\n" + "\n".join(",".join(f"{v:.6f}" for v in np.degrees(r)) for r in q) + "\n")
    code, _, err = run_cli("compensate", "kr5-arc", export, goals, "--out", tmp_path / "c.csv", "-q")
    assert code in (0, 3), err
    program = tmp_path / "p.src"
    program.write_text("DEF p()\n  PTP {A1 0, A2 -60, A3 90, A4 0, A5 30, A6 0}\nEND\n")
    code, _, err = run_cli("filter", export, program, "--nominal", "kr5-arc", "--out", tmp_path / "f.src", "-q")
    assert code in (0, 3), err


def test_a_bias_a_poses_markers_share_is_found_and_counted_once(tmp_path):
    """A detector bias of 1.5 px common to the markers one camera saw at one pose, beside 0.5 px of each
    row's own: robocal notices and says both, and weighs the pose's rows as sharing it, so that the σ it
    states of a new pose's marker is the spread of the truth over 30 robots drawn from the prior
    (weighed as independent rows, the twelve markers of a pose would count their bias twelve times)."""
    zs, said = [], []
    for draw in range(30):
        cell, data, specs, markers, rng = _torso_cell(2000 + draw, tmp_path, 40, bias=1.5)
        result = _calibrate("kr5-arc", data, *specs, markers=str(markers), params="all")
        said += [n for n in result.notes if n.startswith("a pose's camera rows share an error")]
        zs.append(_z_scores(cell, result, cw.poses("kr5-arc", 10, rng, CENTRE, SPREAD_TORSO)))
    assert len(said) == 30
    shared = [float(n.split("σ ")[1].split(" px")[0]) for n in said]
    own = [float(n.split("pose, ")[1].split(" px")[0]) for n in said]
    assert abs(np.mean(shared) - 1.5) < 0.15 and abs(np.mean(own) - 0.5) < 0.03, (np.mean(shared), np.mean(own))
    z = np.concatenate(zs)
    assert 0.8 <= np.std(z) <= 1.25, np.std(z)


def test_what_the_pixels_mean_at_the_markers_is_said_in_millimetres(tmp_path):
    """Beside every figure in px: the error at the marker (pixel error × depth ÷ focal length, against
    the independent cell's own depths) and the markers' predicted σ in their camera's frame (against
    finite differences of the calibrated model through the posterior covariance)."""
    from robocal.calibration.config import CalibrationConfig
    from robocal.calibration.fit.camera_scale import marker_sigma
    from robocal.calibration.fit.parametric import fit_parametric, term_spec
    from robocal.calibration.inputs import load_inputs
    from robocal.model.metrics import pixel_scale, pose_errors

    cell, data, specs, markers, rng = _torso_cell(31, tmp_path, 40)
    result = _calibrate("kr5-arc", data, *specs, markers=str(markers), params="all")
    meas = result.measurements
    left = np.flatnonzero(np.array(meas.camera) == "left")
    depth = np.array([cell.seen_from(cell.cameras[0], meas.q[i:i + 1], meas.targets[i])[0, 2] for i in left])
    scale = pixel_scale(result.robot, meas)[left]
    np.testing.assert_allclose(scale, depth / 1100.5, rtol=2e-3)  # f = 1100 and 1100 × 1.002
    after = result.metrics["after"]
    e = np.linalg.norm(pose_errors(result.robot, meas)[0], axis=1)
    mm = e * pixel_scale(result.robot, meas)
    assert after.at_marker["rms"] == pytest.approx(float(np.sqrt(np.mean(mm ** 2))), rel=1e-9)
    assert "mm at the markers" in result.headline_text()
    # the σ in the camera's frame, analytic, against finite differences through the covariance
    config = CalibrationConfig(cameras=specs, markers=str(markers), params="all")
    inputs = load_inputs("kr5-arc", str(data), None, config, None)
    fit = fit_parametric(inputs, config, term_spec((), inputs.meas, config))
    problem = fit.estimate.problem
    sigma = marker_sigma(problem, fit.estimate.x, fit.covariance)
    space, at = problem.space, problem.full(fit.estimate.x)  # the covariance's own parameters: deviations
    index = space.index(problem.names)
    q, target = problem.meas.q[left[:8]], [problem.meas.targets[i] for i in left[:8]]

    def seen(r):
        T = r.camera_frames(["left"] * len(q), q)
        return np.einsum("mji,mj->mi", T[:, :3, :3], r.positions(q, target) - T[:, :3, 3])

    J = np.empty((8, 3, len(index)))
    for j, i in enumerate(index):
        step = np.zeros(space.size)
        step[i] = 1e-6
        J[:, :, j] = (seen(space.apply(at + step)) - seen(space.apply(at - step))) / 2e-6
    expected = np.sqrt(np.einsum("mai,ij,maj->m", J, fit.covariance, J))
    np.testing.assert_allclose(sigma[left[:8]], expected, rtol=1e-4)


def test_the_image_example_detects_and_calibrates_to_the_pixels_it_was_drawn_from(tmp_path, run_cli):
    """examples/cameras/render.py draws a planted cell's images through the wall camera's lens; detect and
    calibrate as the guide shows, and the model from the images predicts the exact pixels the images
    were drawn from within the detection's own noise."""
    import subprocess
    import sys
    from pathlib import Path

    from robocal.io.measurements import load_measurements

    root = Path(__file__).parents[2] / "examples" / "cameras"
    cell = tmp_path / "cell"
    done = subprocess.run([sys.executable, str(root / "render.py"), "--out", str(cell), "--poses", "40"],
                          capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    code, out, err = run_cli("detect", cell / "images", "--joints", cell / "joints.csv", "--camera", "wall",
                             "--aruco", "4X4_50", "--out", cell / "detected.csv")
    assert code == 0, err
    assert "the corners of 5 markers (1, 2, 3, 4, 5), in 40 images" in out
    spec, markers = f"wall={root / 'wall.yaml'}", root / "markers.csv"
    code, _, err = run_cli("calibrate", "kr5-arc", cell / "detected.csv", "--camera", spec, "--markers", markers,
                           "--export", cell / "calibrated.toml", "-q")
    assert code == 0, err
    # the detection's noise: the detected corners against the exact ones
    found, exact = (load_measurements(cell / f, n_joints=6) for f in ("detected.csv", "exact.csv"))
    drawn = {(p, m): uv for p, m, uv in zip(exact.pose_ids, exact.targets, exact.pixels)}
    miss = np.array([uv - drawn[(p, m)] for p, m, uv in zip(found.pose_ids, found.targets, found.pixels)])
    noise = float(np.sqrt(np.mean(np.sum(miss ** 2, axis=1))))
    code, stdout, err = run_cli("evaluate", cell / "calibrated.toml", cell / "exact.csv", "--camera", spec, "--json")
    assert code == 0, err
    figures = json.loads(stdout)
    assert figures["position"]["rms"] < noise < 0.6, (figures["position"]["rms"], noise)
    assert figures["at_marker_mm"]["rms"] < 0.5
