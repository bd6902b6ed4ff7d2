"""Camera rows in the model: the pixel a robot with cameras predicts against an independent cell
(tests.camera_world: its own kinematics, OpenCV's projection), and the residuals' Jacobian against
finite differences, cameras fixed and on a link."""

import numpy as np
import pytest

from robocal.calibration.fit.problem import Setup
from robocal.io.camera import load_camera
from robocal.io.robotfile import load_robot
from robocal.model.camera import CameraMount
from robocal.model.measurements import Measurements
from robocal.model.metrics import pose_errors
from robocal.model.parameters import ParameterSpace
from tests import camera_world as cw
from tests import independent

pytest.importorskip("cv2")


def _cell(rng, tmp_path):
    dev = independent.uniform_deviations("kr5-arc", 1.0, np.radians(0.1), rng)
    wall = cw.camera("wall", cw.look_at([2000.0, 1200, 1300], [240.0, 10, 440]))
    rider = cw.camera("rider", cw.look_at([300.0, -600, 900], [700.0, 0, 300]), link=1)
    # the rider's partner on a rig: 120 mm to its right, turned 5° towards it (its pose in the rider's frame)
    from robocal.math.se3 import homogeneous as _h
    from robocal.math.so3 import exp_so3

    rig = _h(exp_so3(np.array([0.0, np.radians(-5.0), 0.0])), np.array([120.0, 0.0, 0.0]))
    partner = cw.camera("partner", rider.pose @ rig, link=1)
    markers = {"m1": (np.array([20.0, 10, 80]), None), "m2": (np.array([-40.0, 30, 60]), None)}
    cell = cw.Cell("kr5-arc", dev, [wall, rider, partner], markers)
    q = cw.poses("kr5-arc", 80, rng, centre_deg=[0, -60, 90, 0, 30, 0], spread_deg=[50, 25, 25, 80, 35, 80])
    rows = cell.observe(q, rng, 0.0)
    intrinsics = {c.name: load_camera(c.write(tmp_path / f"{c.name}.yaml"), c.name) for c in cell.cameras}
    meas = Measurements(np.radians([r[0] for r in rows]), np.full((len(rows), 3), np.nan),
                        targets=tuple(r[3] for r in rows), camera=tuple(r[2] for r in rows),
                        pixels=np.array([r[1] for r in rows]), intrinsics=intrinsics)
    from robocal.math.se3 import homogeneous

    g = independent.geometry("kr5-arc", dev)
    nominal = load_robot("kr5-arc")
    geometry = nominal.geometry.copy()
    geometry[:, :4] = np.column_stack([g["a"], g["alpha"], g["theta"], g["d"]])
    true = nominal.replace(geometry=geometry, targets={k: homogeneous(np.eye(3), p) for k, (p, _) in markers.items()},
                           cameras={"wall": CameraMount(0, wall.pose), "rider": CameraMount(1, rider.pose),
                                    "partner": CameraMount(1, rig, known=True, of="rider")})
    return true, meas


def test_a_robot_with_cameras_predicts_the_pixels_of_an_independent_cell(rng, tmp_path):
    true, meas = _cell(rng, tmp_path)
    assert set(meas.camera) == {"wall", "rider", "partner"} and meas.n_poses > 60
    dp, _ = pose_errors(true, meas)
    np.testing.assert_allclose(dp, 0.0, atol=1e-6)  # measured pixels (noise-free) are the predicted ones


def test_camera_rows_jacobian_is_its_finite_difference(rng, tmp_path):
    true, meas = _cell(rng, tmp_path)
    from dataclasses import replace

    # a body of known shape: the two markers' offsets 70 mm apart (a rod: its placement takes 5 of their 6 values)
    meas = replace(meas, shapes=((("m1", "m2"), np.array([[0.0, 0, 0], [70.0, 0, 0]])),))
    space = ParameterSpace.of(true, ("m1", "m2"))
    cameras = ("wall", "rider", "partner")
    assert {n for n in space.names if n.startswith("camera[")} == {f"camera[{c}]_{a}" for c in cameras
                                                                   for a in ("x", "y", "z", "rx", "ry", "rz")}
    problem = Setup(space, meas, use_orientation=False).problem(space.names)
    x = rng.normal(0, 1e-3, space.size)
    J = problem.residual_jacobian(x)
    h = 1e-6
    for i in range(space.size):
        e = np.zeros(space.size)
        e[i] = h
        fd = (problem.residuals(x + e) - problem.residuals(x - e)) / (2 * h)
        np.testing.assert_allclose(J[:, i], fd, rtol=1e-4, atol=1e-4 * max(1.0, np.abs(fd).max()),
                                   err_msg=space.names[i])
    # a camera on link 1 sees neither the base nor joint 1's parameters
    rider = np.array([c in ("rider", "partner") for c in meas.camera])
    rows = np.repeat(rider, 3)
    for name in ("base_x", "base_rz", "d1", "theta1"):
        assert np.abs(J[:len(rows)][rows, space.names.index(name)]).max() < 1e-9
    # pixels: two values a row, and the rod's length one (its six residual rows less its placement's five)
    assert problem.n_shapes == 6 and problem.n_values == 2 * meas.n_poses + 1
    d = np.linalg.norm(true.targets["m1"][:3, 3] - true.targets["m2"][:3, 3])
    # each end is off the rod placed on them by half the length missed
    assert np.linalg.norm(problem.residuals(np.zeros(space.size))[-6:]) == pytest.approx(
        abs(d - 70.0) / np.sqrt(2) / meas.shape_sigma)
