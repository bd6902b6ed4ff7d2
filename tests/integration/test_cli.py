"""simulate → evaluate end to end, and the planted truth."""

import json
import subprocess
import sys

import numpy as np

from robocal.io.measurements import load_measurements
from robocal.io.robotfile import load_robot
from robocal.model.metrics import Metrics
from robocal.presets.wen2019 import TABLE2_DEVIATIONS as WEN2019_ERRORS
from robocal.simulation import simulate


def test_issue_example_truth_evaluates_to_noise_only(tmp_path, run_cli):
    d, t = tmp_path / "d.csv", tmp_path / "t.toml"
    code, _, err = run_cli(
        "simulate", "er10l-c10", "--errors", "paper", "--poses", 32, "--seed", 1, "--out", d, "--truth", t
    )
    assert code == 0, err
    code, out, _ = run_cli("evaluate", t, d, "--json")
    truth = json.loads(out)
    assert truth["n"] == 32
    assert truth["position"]["max"] < 1e-9 and truth["orientation"]["z"]["max"] < 1e-9
    code, out, _ = run_cli("evaluate", "er10l-c10", d, "--json")
    nominal = json.loads(out)
    assert nominal["position"]["mean"] > 1.0  # millimetres of uncalibrated error
    # the truth file carries exactly the paper's Table 2 errors
    true_robot, nom = load_robot(t), load_robot("er10l-c10")
    np.testing.assert_allclose(true_robot.a - nom.a, [WEN2019_ERRORS[f"a{i}"] for i in range(1, 7)], atol=1e-12)
    np.testing.assert_allclose(true_robot.beta[1], WEN2019_ERRORS["beta2"], atol=1e-15)


def test_noise_levels_show_in_evaluation(tmp_path):
    robot = load_robot("kr5-arc")
    sim = simulate(robot, 400, deviations="uniform:0.25,0.05", noise=0.02, angle_noise=1e-4, seed=3)
    m = Metrics.of(sim.truth, sim.measurements)
    # |δp| of isotropic Gaussian noise σ: rms = σ√3
    assert abs(m.position["rms"] - 0.02 * np.sqrt(3)) < 0.003
    assert 0.5e-4 < np.radians(m.orientation["x"]["mean"]) < 1.2e-4
    # joints inside the KR5 limits
    q = np.degrees(sim.measurements.q)
    assert q[:, 0].min() >= -155 and q[:, 1].max() <= 65 and q[:, 2].min() >= -15


def test_simulate_is_reproducible_and_position_only(tmp_path, run_cli):
    a, b = tmp_path / "a.csv", tmp_path / "b.csv"
    for f in (a, b):
        assert (
            run_cli(
                "simulate",
                "kr5-arc",
                "--errors",
                "uniform:0.25,0.05",
                "--poses",
                30,
                "--seed",
                7,
                "--measure",
                "position",
                "--out",
                f,
            )[0]
            == 0
        )
    assert a.read_text() == b.read_text()
    m = load_measurements(a)
    assert not m.full_pose and m.n_poses == 30


def test_frames_and_joint_noise_in_simulation():
    robot = load_robot("er10l-c10")
    sim = simulate(robot, 50, base=(2000.0, -1000.0, 300.0, 0.1, 0.2, 1.0), tool=(0.0, 30.0, 100.0), seed=1)
    np.testing.assert_allclose(sim.truth.base[:3, 3], [2000, -1000, 300])
    noisy = simulate(robot, 50, joint_noise_uniform=0.1, seed=1)
    # the paper's U(±0.1 rad) joint "noise" makes even the true model miss by tens of mm
    assert Metrics.of(noisy.truth, noisy.measurements).position["mean"] > 20


def test_bad_simulate_arguments_write_nothing(tmp_path, run_cli):
    out = tmp_path / "d.csv"
    for args in (
        ["--errors", "paper"],
        ["--errors", "uniform:x"],
        ["--noise", "-1"],
        ["--range", "5"],
        ["--measure", "both"],
        ["--poses", "0"],
    ):
        code, _, err = run_cli("simulate", "kr5-arc", *args, "--out", out)
        assert code == 2 and err.count("\n") == 1, (args, err)
        assert not out.exists()


def test_console_script_runs():
    proc = subprocess.run([sys.executable, "-m", "robocal", "robots"], capture_output=True, text=True)
    assert proc.returncode == 0 and "er10l-c10" in proc.stdout


def test_valid_but_ugly_files_calibrate(tmp_path, run_cli):
    d = tmp_path / "d.csv"
    run_cli("simulate", "kr5-arc", "--errors", "uniform:0.1,0.002", "--poses", 30, "--measure", "position",
            "--seed", 4, "--out", d)
    ugly = tmp_path / "ugly.csv"
    ugly.write_bytes(b"\xef\xbb\xbf" + d.read_text().replace("\n", "\r\n").encode() + b"\r\n\r\n\n")
    code, out, err = run_cli("calibrate", "kr5-arc", ugly, "--quiet", "--out", tmp_path / "r.json")
    assert code == 0, err
    assert json.loads((tmp_path / "r.json").read_text())["n_poses"] == 30


def test_stated_units_and_column_lists(tmp_path, run_cli):
    robot = load_robot("kr5-arc")
    sim = simulate(robot, 30, deviations="uniform:0.1,0.002", seed=5, measure="position",
                   joint_range=(np.radians(-60), np.radians(60)))  # a small work cell: every joint within ±π deg
    q, p = np.degrees(sim.measurements.q), sim.measurements.position
    rows = ["J1,J2,J3,J4,J5,J6,X,Y,Z"] + [",".join(f"{v:.9f}" for v in (*np.radians(q[i]), *(p[i] / 1000)))
                                         for i in range(30)]
    f = tmp_path / "metres_radians.csv"
    f.write_text("\n".join(rows) + "\n")
    columns = "J1=q1,J2=q2,J3=q3,J4=q4,J5=q5,J6=q6,X=x,Y=y,Z=z"
    code, _, err = run_cli("calibrate", "kr5-arc", f, "--column", columns, "--quiet")
    assert code == 2 and "look like radians" in err and "joint unit" in err
    code, _, err = run_cli("calibrate", "kr5-arc", f, "--column", columns, "--joint-unit", "rad", "--quiet")
    assert code == 2 and "look like metres" in err
    out = tmp_path / "r.json"
    code, _, err = run_cli("calibrate", "kr5-arc", f, "--column", columns, "--joint-unit", "rad", "--length-unit", "m",
                           "--quiet", "--out", out)
    assert code == 0, err
    assert json.loads(out.read_text())["metrics"]["after"]["position"]["rms"] < 1e-5
    # a work cell in degrees, within ±π: stating the unit lets it load
    deg = tmp_path / "degrees.csv"
    deg.write_text("q1,q2,q3,q4,q5,q6,x,y,z\n" + "\n".join(",".join(f"{v:.9f}" for v in (*q[i] / 60, *p[i]))
                                                            for i in range(30)) + "\n")
    assert "look like radians" in run_cli("evaluate", "kr5-arc", deg)[2]
    assert run_cli("evaluate", "kr5-arc", deg, "--joint-unit", "deg")[0] == 0


def test_exported_robot_files_are_clean(tmp_path, run_cli):
    d, cal = tmp_path / "d.csv", tmp_path / "cal.toml"
    run_cli("simulate", "kr5-arc", "--errors", "uniform:0.1,0.002", "--poses", 40, "--measure", "position",
            "--seed", 6, "--out", d)
    assert run_cli("calibrate", "kr5-arc", d, "--export", cal, "--quiet")[0] == 0
    text = cal.read_text()
    assert "-0.0," not in text and "-0.0]" not in text and "= -0.0\n" not in text
    assert "limits = [-155.0, 155.0]" in text and "9999999" not in text
    assert load_robot(cal).convention == "hayati"  # DH + β on the parallel axes 2 ∥ 3


def test_several_reflectors_get_their_own_figures(tmp_path, run_cli):
    robot = load_robot("kr5-arc")
    sim = simulate(robot, 25, deviations="uniform:0.1,0.002", seed=7, measure="position")
    from robocal.io.measurements import save_measurements
    from robocal.model.measurements import Measurements

    q, pos, tg = [], [], []
    for name, xyz in {"A": (0.0, 0.0, 100.0), "B": (60.0, 0.0, 80.0), "C": (0.0, 70.0, 90.0)}.items():
        T = sim.truth.replace(tool=np.eye(4))
        T.tool[:3, 3] = xyz
        q.append(sim.measurements.q)
        pos.append(T.positions(sim.measurements.q))
        tg += [name] * 25
    f = tmp_path / "three.csv"
    save_measurements(Measurements(q=np.vstack(q), position=np.vstack(pos), targets=tuple(tg)), f)
    out = tmp_path / "r.json"
    code, stdout, err = run_cli("calibrate", "kr5-arc", f, "--out", out)
    assert code == 0, err
    assert "per reflector" in stdout
    assert "frames auto: reflector 'A' has no tool frame" in err
    r = json.loads(out.read_text())
    assert set(r["metrics_per_target"]) == {"A", "B", "C"} and r["frames"] == "base+tool"
    assert r["poses"] == "25 poses × 3 reflectors (75 measured points)"
