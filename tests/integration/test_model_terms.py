"""Models beyond geometry against planted truths of the independent simulator (tests/independent.py).

- Compliance planted on a KR5 with torques in the file is recovered, fresh poses are
  predicted near the noise floor, and joints that carry no load keep no significant compliance.
- ``--model auto`` chooses what is there and nothing that is not: geometry alone for
  geometric data, harmonics (not compliance) for transmission errors, compliance (not
  harmonics) for deflection under load.
- A model that lacks the planted effect is told so by the misfit warning.
- Every command uses the whole model: an exported model (joint terms, residual process in its
  sibling file) evaluates to the calibration's own validation figure, and compensation
  through it lands the simulated true robot on its goals.
"""

import json
import math
import warnings

import independent as ind
import numpy as np
import pytest

from robocal.calibration import calibrate
from robocal.compensation import compensate
from robocal.evaluation import evaluate
from robocal.io.goals import Goals
from robocal.io.measurements import save_measurements
from robocal.io.robotfile import load_robot
from robocal.model.measurements import Measurements
from robocal.model.metrics import Metrics
from robocal.simulation import simulate

NOISE = 0.02
PLANTED = {2: 5e-6, 3: 8e-6}  # rad/(N·m)
# the simulator's own mass model (kg; centres mm in each link's frame), unrelated to robocal's
MASSES = [25.0, 18.0, 9.0, 4.0, 2.0, 0.5]
CENTRES = [(-90, 30, 0), (-300, 0, 60), (-40, -20, 10), (0, 80, 0), (0, 0, 20), (0, 0, 0)]


def _compliant_kr5(n, seed, compliance=PLANTED, harmonic=None):
    """KR5 position data whose joints give way under the simulator's own gravity torques
    (Δq = c τ at the commanded joints), with the torques in the file; harmonic: {joint: (a, b)}
    rad of cos(q) and sin(q) planted too."""
    g = ind.geometry("kr5-arc")

    def torques(q):
        return np.array([ind.gravity_torques(g, qi, MASSES, CENTRES) for qi in q])

    def deflection(q):
        dq = torques(q) * np.array([compliance.get(j + 1, 0.0) for j in range(6)])
        for j, (a, b) in (harmonic or {}).items():
            dq[:, j - 1] += a * np.cos(q[:, j - 1]) + b * np.sin(q[:, j - 1])
        return dq

    c = ind.campaign("kr5-arc", {}, n, np.random.default_rng(seed), noise=NOISE, measure="position",
                     joint_error=deflection)
    return Measurements(q=c["q"], position=c["position"], torques=torques(c["q"]))


def _calibrate(robot, meas, **kw):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        result = calibrate(robot, meas, "lm", **kw)
    return result, [str(w.message) for w in caught] + result.notes  # what it said: warnings and notes


@pytest.fixture(scope="module")
def compliant():
    return _compliant_kr5(200, 1), _compliant_kr5(200, 2)


def test_planted_compliance_is_recovered_and_fresh_poses_reach_the_floor(compliant):
    meas, fresh = compliant
    res, _ = _calibrate("kr5-arc", meas, frames="none", model="compliance", validate=fresh)
    assert res.model == "compliance"
    for j, c in PLANTED.items():
        assert res.parameter(f"compliance{j}") == pytest.approx(c, rel=0.15)
    # the floor: the noise of the fresh poses themselves, what the true model leaves
    floor = NOISE * math.sqrt(3)
    assert res.metrics["validation_after"].position["rms"] <= 1.3 * floor
    # joints that carry no load (1: a vertical axis; 6: nothing beyond it) are dropped or not significant
    for j in (1, 6):
        name = f"compliance{j}"
        assert name in res.identifiability.dropped or res.significant(res.names.index(name)) is False
    # unplanted compliances of joints that do carry load are consistent with zero
    for j in (4, 5):
        name = f"compliance{j}"
        if name in res.names:
            i = res.names.index(name)
            assert abs(res.x[i]) < 3 * res.uncertainty[i]
    exported = {p["name"]: p for p in res.to_dict()["parameters"]}
    assert exported["compliance2"]["unit"] == "rad/(N·m)"


def test_auto_chooses_compliance_and_not_harmonics_for_deflection_under_load(compliant):
    meas, fresh = compliant
    res, said = _calibrate("kr5-arc", meas, frames="none", model="auto", validate=fresh)
    assert res.model == "compliance"  # no harmonics, and no residual process fitted to noise
    rows = {r.model: r for r in res.model_selection}
    assert {"geometric", "harmonics", "compliance", "compliance+harmonics"} <= set(rows)
    assert rows["compliance"].cv_rms_mm < 0.5 * rows["geometric"].cv_rms_mm
    assert any(s.startswith("model auto: ") for s in said)
    budget = [r.model for r in res.error_budget]
    assert budget[:2] == ["nominal geometry, frames fitted", "geometric calibration"]


def test_auto_keeps_geometry_alone_on_geometric_data():
    c = ind.campaign("kr5-arc", {"a2": 0.2, "theta3": 0.002, "d4": -0.15}, 150, np.random.default_rng(5),
                     noise=NOISE, measure="position")
    res, _ = _calibrate("kr5-arc", Measurements(q=c["q"], position=c["position"]), frames="none", model="auto")
    assert res.model == "geometric"
    assert res.robot.geometric


def test_auto_chooses_harmonics_for_transmission_errors():
    # first harmonics of joints 1 (a vertical axis: gravity cannot mimic it) and 4
    amplitude = math.radians(0.02)

    def transmission(q):
        dq = np.zeros_like(q)
        dq[:, 0] = amplitude * np.cos(q[:, 0]) - 0.5 * amplitude * np.sin(q[:, 0])
        dq[:, 3] = amplitude * np.sin(q[:, 3])
        return dq

    c = ind.campaign("kr5-arc", {}, 200, np.random.default_rng(6), noise=NOISE, measure="position",
                     joint_error=transmission)
    res, _ = _calibrate("kr5-arc", Measurements(q=c["q"], position=c["position"]), frames="none", model="auto")
    assert res.model == "harmonics"
    assert res.parameter("harmonic1_cos1") == pytest.approx(amplitude, rel=0.15)


def test_a_model_without_the_planted_effect_is_called_a_misfit(compliant):
    meas, _ = compliant
    _, said = _calibrate("kr5-arc", meas, frames="none", model="harmonics", noise=NOISE)
    assert any(s.startswith("model misfit") for s in said)
    _, said = _calibrate("kr5-arc", meas, frames="none", model="compliance", noise=NOISE)
    assert not any(s.startswith("model misfit") for s in said)


def test_the_exported_model_with_its_residual_file_evaluates_to_the_validation_figure(compliant, tmp_path,
                                                                                      run_cli):
    meas, fresh = compliant
    res, _ = _calibrate("kr5-arc", meas, frames="none", model="compliance+harmonics+residual", validate=fresh)
    assert res.robot.residual is not None and res.robot.terms is not None
    written = res.export(tmp_path / "cal.toml")
    assert [p.name for p in written] == ["cal.toml", "cal.residual.json"]
    assert 'residual = "cal.residual.json"' in (tmp_path / "cal.toml").read_text()
    figure = res.metrics["validation_after"].position["rms"]
    assert evaluate(tmp_path / "cal.toml", fresh).metrics.position["rms"] == pytest.approx(figure, rel=1e-9)
    # the same from the command line, run from another directory: the sibling is found beside the robot file
    save_measurements(fresh, tmp_path / "fresh.csv")
    code, out, err = run_cli("evaluate", tmp_path / "cal.toml", tmp_path / "fresh.csv", "--json")
    assert code == 0 and json.loads(out)["position"]["rms"] == pytest.approx(figure, rel=1e-9)
    # without its torque columns the compliance cannot act, and evaluate says so
    save_measurements(Measurements(q=fresh.q, position=fresh.position), tmp_path / "no_tau.csv")
    code, out, err = run_cli("evaluate", tmp_path / "cal.toml", tmp_path / "no_tau.csv")
    assert code == 0 and "no tau1..tauN columns" in err
    # a robot file whose residual file is missing is an input error naming it
    (tmp_path / "cal.residual.json").unlink()
    code, out, err = run_cli("evaluate", tmp_path / "cal.toml", tmp_path / "fresh.csv")
    assert code == 2 and "cal.toml" in err and "cal.residual.json" in err and len(err.strip().splitlines()) == 1


def test_compensation_through_the_full_model_lands_the_true_robot(quiet):
    robot = load_robot("kr5-arc")
    sim = simulate(robot, 250, compliance={2: 6e-6, 3: 9e-6}, harmonics={1: [(3e-4, -2e-4)]}, noise=0.01,
                   measure="position", seed=3)
    res = calibrate(robot, sim.measurements, "lm", frames="none", model="compliance+harmonics")
    goals_sim = simulate(robot, 60, measure="position", seed=4, compliance={2: 6e-6, 3: 9e-6})
    goals = Goals(q=goals_sim.measurements.q, position=None, rotation=None,
                  ids=[str(i) for i in range(60)], torques=goals_sim.measurements.torques)
    out = compensate(robot, res.robot, goals, truth=sim.truth, position_only=True)
    val = out.validation()
    before = val["nominal_commands"].position["rms"]
    after = val["compensated_commands"].position["rms"]
    assert before > 0.2 and after < 0.05 * before
    assert not out.warnings
    # without torques at the goals, the compliance cannot act: said, and the answer is worse
    bare = compensate(robot, res.robot, Goals(q=goals.q, position=None, rotation=None, ids=goals.ids),
                      truth=sim.truth, position_only=True)
    assert any("no tau1..tauN" in w for w in bare.warnings)


def test_gravity_form_needs_no_torques_and_matches_the_torque_form(compliant, quiet):
    meas, fresh = compliant
    bare = Measurements(q=meas.q, position=meas.position)
    res = calibrate("kr5-arc", bare, "lm", frames="none", model="compliance", validate=Measurements(
        q=fresh.q, position=fresh.position))
    assert any(n.startswith("gravity2_") for n in res.names)
    torque_form = calibrate("kr5-arc", meas, "lm", frames="none", model="compliance", validate=fresh)
    assert res.metrics["validation_after"].position["rms"] < 1.3 * torque_form.metrics["validation_after"].position[
        "rms"]
    assert res.metrics["validation_after"].position["rms"] < 0.5 * Metrics.of(
        load_robot("kr5-arc"), fresh).position["rms"]


def test_simulate_plants_terms_and_the_command_line_recovers_them(tmp_path, run_cli):
    data, truth, out = tmp_path / "d.csv", tmp_path / "truth.toml", tmp_path / "r.json"
    code, _, err = run_cli("simulate", "kr5-arc", "--poses", "150", "--measure", "position", "--noise", "0.01",
                           "--compliance", "2=5e-6,3=8e-6", "--harmonic", "1:1=0.02,-0.01", "--out", data,
                           "--truth", truth, "--seed", "4")
    assert code == 0, err
    assert "tau1" in data.read_text().splitlines()[0]
    assert "compliance = 5e-06" in truth.read_text() and "harmonics = [[0.02, -0.01]]" in truth.read_text()
    code, stdout, err = run_cli("evaluate", truth, data, "--json")
    assert code == 0 and json.loads(stdout)["position"]["rms"] < 0.03  # the true robot: noise only
    code, stdout, err = run_cli("calibrate", "kr5-arc", data, "--frames", "none", "--model", "auto", "--out", out)
    assert code == 0, err
    assert "model selection" in stdout and "chosen" in stdout
    result = json.loads(out.read_text())
    assert result["model"] == "compliance+harmonics"
    values = {p["name"]: p["value"] for p in result["parameters"]}
    assert values["compliance2"] == pytest.approx(5e-6, rel=0.15)
    assert values["compliance3"] == pytest.approx(8e-6, rel=0.15)
    assert math.degrees(values["harmonic1_cos1"]) == pytest.approx(0.02, rel=0.15)
    # forward selection: geometry, each term alone (cheaper first), then further terms on the best
    tried = [r["model"] for r in result["model_selection"]]
    # (backlash and drift only where the file gives time or directions, or --row-order says its order is the
    # measuring order: this file is in no particular order)
    assert tried[:3] == ["geometric", "harmonics", "compliance"]
    assert "compliance+harmonics" in tried and not any("backlash" in m or "drift" in m for m in tried)


IIWA = """
name = "7-joint arm (iiwa-like)"
convention = "dh"
[[joint]]
a = 0.0
alpha = -90.0
d = 340.0
theta = 0.0
limits = [-170.0, 170.0]
[[joint]]
a = 0.0
alpha = 90.0
d = 0.0
theta = 0.0
limits = [-120.0, 120.0]
[[joint]]
a = 0.0
alpha = 90.0
d = 400.0
theta = 0.0
limits = [-170.0, 170.0]
[[joint]]
a = 0.0
alpha = -90.0
d = 0.0
theta = 0.0
limits = [-120.0, 120.0]
[[joint]]
a = 0.0
alpha = -90.0
d = 400.0
theta = 0.0
limits = [-170.0, 170.0]
[[joint]]
a = 0.0
alpha = 90.0
d = 0.0
theta = 0.0
limits = [-120.0, 120.0]
[[joint]]
a = 0.0
alpha = 0.0
d = 126.0
theta = 0.0
limits = [-175.0, 175.0]
[tool]
xyz = [30.0, -20.0, 60.0]
"""


@pytest.mark.parametrize("measure", ["pose", "position"])
def test_a_seven_joint_arm_with_torque_columns(tmp_path, measure, quiet):
    """The same machinery, untuned, on a redundant arm whose controller reports joint torques."""
    path = tmp_path / "arm7.toml"
    path.write_text(IIWA)
    robot = load_robot(path)
    planted = {2: 4e-6, 4: 6e-6}
    kw = dict(deviations="uniform:0.2,0.002", compliance=planted, noise=0.02, angle_noise=math.radians(0.001),
              measure=measure)
    meas = simulate(robot, 500, seed=11, **kw).measurements
    fresh = meas.subset(np.arange(300, 500))
    res = calibrate(robot, meas.subset(np.arange(300)), "lm", frames="none", model="auto", validate=fresh)
    assert res.model == "compliance"
    for j, c in planted.items():
        assert res.parameter(f"compliance{j}") == pytest.approx(c, rel=0.15)
    geometric = res.error_budget[1].validation_rms_mm
    assert res.metrics["validation_after"].position["rms"] < 0.5 * geometric
    assert res.metrics["validation_after"].position["rms"] < 1.3 * NOISE * math.sqrt(3)
