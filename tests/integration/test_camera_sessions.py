"""A camera calibration judged as it is used: on sessions it did not see.  An independent cell
(tests.camera_world: its own kinematics, OpenCV's projection and camera files) plants what the
model does not contain (the marker body remounted between sessions, a detector bias shared by a
pose's markers, a lens off its file's intrinsics at the edges) and the defaults must keep the robot
physical, predict held-out sessions nearly as well as the truth does, and say so beforehand."""

import warnings

import numpy as np
import pytest

import robocal
from robocal.calibration.config import CalibrationConfig
from robocal.calibration.inputs import load_inputs
from robocal.model.camera import CameraMount
from robocal.model.metrics import Metrics
from tests import camera_world as cw
from tests import independent

pytest.importorskip("cv2")

ROBOT = "torso-kr5"
#: joint 1 (the torso) still, the arm around a pose in the head cameras' view
CENTRE, SPREAD = [0, 0, -60, 90, 0, 30, 0], [0, 60, 30, 30, 120, 50, 150]
PRIOR = {"a": 1.0, "d": 1.0, "alpha": np.radians(0.1), "beta": np.radians(0.1), "theta": np.radians(1.0)}


def _campaign(seed, folder):
    """Two cameras on the torso (link 1) seeing a dodecahedron of 20 markers on the flange, over 16
    sessions of 30 poses: the markers remounted by 0.3 mm between sessions, a 1 px bias the markers of
    a pose share in each camera, 0.5 px each, and a lens 1 px off its file at the image's corners."""
    rng = np.random.default_rng(seed)
    g = independent.geometry(ROBOT, {})
    link1 = independent.link_frames(g, np.zeros(7))[0]
    cams = [cw.camera(name, np.linalg.inv(link1) @ cw.look_at([-300.0, off, 1300.0], [340.0, 0, 430]), link=1,
                      f=1100) for name, off in (("left", -150.0), ("right", 150.0))]
    markers = cw.dodecahedron(60.0, centre=(0, 0, 90.0))
    campaign = cw.sessions(ROBOT, cams, markers, 16, 30, rng, CENTRE, SPREAD, noise=0.5, bias=1.0, remount_mm=0.3,
                           lens_px=1.0)
    folder.mkdir()
    robot = folder / "robot.toml"
    robot.write_text(independent.robot_toml(ROBOT, {}))
    specs = [f"{c.name}={c.write(folder / f'{c.name}.yaml')},link=1" for c in cams]
    calibration = cw.write_sessions(campaign, range(0, 16, 2), folder / "calibration.csv")
    held = cw.write_sessions(campaign, range(1, 16, 2), folder / "held.csv")
    return campaign, robot, specs, cw.write_markers(markers, folder / "markers.csv"), calibration, held


def test_the_defaults_stay_physical_and_predict_held_out_sessions_as_the_truth_does(tmp_path):
    campaign, robot, specs, markers, calibration, held = _campaign(5, tmp_path / "cell")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        result = robocal.calibrate(str(robot), str(calibration), cameras=specs, markers=str(markers),
                                   validate=str(held))
    said = " ".join(result.notes + result.warnings)
    assert result.physical.physical and "not physical" not in said
    # the torso never moves: what its cameras cannot tell from joint 2's zero and offset is held by their
    # prior, the cameras' own frames kept (dropping them would hand their share to d2 and θ2)
    assert not [n for n in result.identifiability.dropped if n.startswith("camera[")]
    assert {"theta2", "d2"} <= set(result.held)
    assert result.cross_validation.kind == "sessions" and result.cross_validation.k == 8
    assert "predicted on a new session (leave-one-session-out, 8 sessions)" in result.headline_text() or \
        "validation" in result.headline()[0]
    # every joint parameter within 3 of its prior σ of the truth (the pixels pin what they see; the
    # prior holds what they cannot, the torso's joint and the gauge a joint's zero makes with the cameras)
    truth = independent.geometry(ROBOT, campaign.deviations)
    calibrated = result.robot.geometry
    kinds = {"a": 0, "alpha": 1, "theta": 2, "d": 3, "beta": 4}
    for kind, column in kinds.items():
        if column >= calibrated.shape[1]:
            continue
        values = calibrated[:, column]
        off = np.abs(values - truth[kind]) / PRIOR[kind]
        assert off.max() <= 3.0, (kind, off)
    # held-out sessions within 1.1× of what the true robot, cameras and markers-as-filed give there, and
    # the cross-validated figure robocal reported beforehand within 15 % of the held-out one
    true_robot = robocal.Robot.from_dh("hayati", truth["a"], truth["alpha"], truth["theta"], truth["d"], truth["beta"],
                                       cameras={c.name: CameraMount(1, c.pose, known=True) for c in campaign.cameras})
    config = CalibrationConfig(cameras=specs, markers=str(markers))
    inputs = load_inputs(true_robot, str(held), None, config, None)
    floor = Metrics.of(inputs.nominal.replace(cameras=true_robot.cameras), inputs.meas).position["rms"]
    ours = result.metrics["validation_after"].position["rms"]
    predicted = result.metrics["predicted"].position["rms"]
    assert ours <= 1.1 * floor, (ours, floor)
    assert abs(predicted / ours - 1.0) <= 0.15, (predicted, ours)
    # what the model did not contain is noticed: the bias the markers of a pose share
    shared = [n for n in result.notes if n.startswith("a pose's camera rows share an error")]
    assert shared and abs(float(shared[0].split("σ ")[1].split(" px")[0]) - 1.0) < 0.2
    # and said in millimetres beside the pixels
    assert result.metrics["validation_after"].at_marker is not None
    assert "mm at the markers" in result.headline_text()
