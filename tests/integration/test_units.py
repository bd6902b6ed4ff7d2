"""Joint units told by the robot's limits: radians read as degrees and degrees read as radians are
refused on one line naming --joint-unit, before anything is written; a robot file given as the data
is said to be one."""

from pathlib import Path

import numpy as np
import pytest

from robocal.io.measurements import load_measurements, save_measurements
from robocal.io.robotfile import load_robot
from robocal.simulation import simulate

ROOT = Path(__file__).parents[2]


@pytest.fixture(scope="module")
def kr5(tmp_path_factory):
    """A full-pose KR5 campaign in degrees, and the same numbers of its joints in radians."""
    folder = tmp_path_factory.mktemp("units")
    sim = simulate(load_robot("kr5-arc"), 40, deviations="uniform:0.3,0.003", seed=5, noise=0.02, angle_noise=1e-4)
    degrees = folder / "deg.csv"
    save_measurements(sim.measurements, degrees)
    lines = degrees.read_text().splitlines()
    head = lines[0].split(",")
    joints = [i for i, h in enumerate(head) if h.startswith("q")]
    out = [lines[0]]
    for line in lines[1:]:
        cells = line.split(",")
        for i in joints:
            cells[i] = repr(float(np.radians(float(cells[i]))))
        out.append(",".join(cells))
    radians = folder / "rad.csv"
    radians.write_text("\n".join(out) + "\n")
    return degrees, radians


def _refused(result, *words):
    code, out, err = result
    assert code == 2 and len(err.strip().splitlines()) == 1, err
    for w in words:
        assert w in err, err


def test_radians_read_as_degrees_are_refused_naming_the_joint_unit(kr5, tmp_path, run_cli):
    degrees, radians = kr5
    _refused(run_cli("calibrate", "kr5-arc", radians, "--out", tmp_path / "r.json"), "look like radians",
             "--joint-unit rad", str(radians))
    assert not (tmp_path / "r.json").exists()
    code, _, err = run_cli("calibrate", "kr5-arc", radians, "--joint-unit", "rad", "--out", tmp_path / "r.json")
    assert code == 0, err
    code, _, err = run_cli("calibrate", "kr5-arc", degrees, "--out", tmp_path / "d.json")
    assert code == 0, err


def test_degrees_read_as_radians_are_refused_naming_the_joint_unit(kr5, run_cli):
    degrees, _ = kr5
    _refused(run_cli("calibrate", "kr5-arc", degrees, "--joint-unit", "rad"), "look like degrees",
             "--joint-unit rad out")
    _refused(run_cli("evaluate", "kr5-arc", degrees, "--joint-unit", "rad"), "look like degrees")


def test_the_panda_example_without_its_joint_unit_says_so(run_cli):
    panda = ROOT / "examples" / "mukca-panda2"
    _refused(run_cli("calibrate", panda / "panda.urdf", panda / "panda_2.csv", "--tip-link", "ball_link",
                     "--point-distance", "hole_0,hole_1=50"), "look like radians", "--joint-unit rad")


def test_a_robot_file_given_as_the_data_is_said_to_be_one(tmp_path, run_cli):
    robot = tmp_path / "arm.toml"
    from robocal.io.robotfile import save_robot

    save_robot(load_robot("kr5-arc"), robot)
    _refused(run_cli("calibrate", "kr5-arc", robot), "is a robot file (TOML)", "give it as the robot")
    _refused(run_cli("calibrate", "kr5-arc", ROOT / "examples" / "mukca-panda2" / "panda.urdf"),
             "is a robot file (URDF)")
    with pytest.raises(Exception, match="robot file"):
        load_measurements(robot, n_joints=6)
