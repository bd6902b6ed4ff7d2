"""Terms that depend on the measuring order (backlash, drift) against planted truths of the
independent simulator (tests/independent.py): the directions of approach and the clock are
worked out here, from the campaign's own order, not by robocal."""

from __future__ import annotations

import math
import warnings

import independent as ind
import numpy as np
import pytest

from robocal.calibration import calibrate
from robocal.evaluation import evaluate
from robocal.io.measurements import load_measurements, save_measurements
from robocal.io.robotfile import load_robot, save_robot
from robocal.model.measurements import Measurements

NOISE = 0.01
BACKLASH_DEG = {1: 0.02, 2: 0.03, 3: 0.025}
DRIFT_DEG_PER_H = {2: 0.03, 3: -0.04}
INTERVAL_S = 20.0


def _signs_of_moves(q: np.ndarray) -> np.ndarray:
    """+1/−1 of each joint's move into each row from the row before; the first row's unknown (0)."""
    d = np.zeros_like(q)
    d[1:] = np.sign(q[1:] - q[:-1])
    return d


def _backlash_campaign(n, seed, backlash=BACKLASH_DEG):
    b = np.radians([backlash.get(j + 1, 0.0) for j in range(6)])
    c = ind.campaign("kr5-arc", {"a2": 0.3, "theta3": 0.002}, n, np.random.default_rng(seed), noise=NOISE,
                     measure="position", joint_error=lambda q: _signs_of_moves(q) * b)
    return Measurements(q=c["q"], position=c["position"], source=f"<backlash campaign {seed}>")


def _drift_campaign(n, seed, start_s=0.0, end_s=None, time_column=True):
    """Poses every INTERVAL_S from start_s; the joints are right at end_s (default the last pose)."""
    rates = np.radians([DRIFT_DEG_PER_H.get(j + 1, 0.0) for j in range(6)]) / 3600.0  # rad/s
    t = start_s + INTERVAL_S * np.arange(n)
    end = t[-1] if end_s is None else end_s
    c = ind.campaign("kr5-arc", {"a2": 0.3, "theta3": 0.002}, n, np.random.default_rng(seed), noise=NOISE,
                     measure="position", joint_error=lambda q: (t - end)[:, None] * rates)
    return Measurements(q=c["q"], position=c["position"], time=t if time_column else None,
                        source=f"<drift campaign {seed}>")


def _fit(meas, **kw):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        result = calibrate("kr5-arc", meas, "lm", frames="none", **kw)
    return result, [str(w.message) for w in caught] + result.notes  # what it said: warnings and notes


def _values(result, prefix):
    out = {p["name"]: p for p in result.to_dict()["parameters"] if p["name"].startswith(prefix)}
    return out


FLOOR = math.sqrt(3) * NOISE  # rms of 3-D position noise


def test_planted_backlash_is_recovered_per_joint_and_fresh_poses_reach_the_floor():
    result, said = _fit(_backlash_campaign(400, 1), model="backlash", validate=_backlash_campaign(300, 2),
                        row_order=True)
    values = _values(result, "backlash")
    for j, planted in BACKLASH_DEG.items():
        p = values[f"backlash{j}"]
        assert p["unit"] == "deg"
        assert p["value"] == pytest.approx(planted, rel=0.15), j
    assert any("direction of approach from the rows' order" in s for s in said)
    assert result.metrics["validation_after"].position["rms"] < 1.15 * FLOOR
    # the geometric model alone does not reach it: the planted effect is real
    geometric, _ = _fit(_backlash_campaign(400, 1), validate=_backlash_campaign(300, 2))
    assert geometric.metrics["validation_after"].position["rms"] > 1.5 * FLOOR


def test_auto_chooses_backlash_in_measuring_order_and_not_when_the_rows_are_shuffled():
    meas = _backlash_campaign(300, 3)
    result, _ = _fit(meas, model="auto", row_order=True)
    assert result.model == "backlash"
    shuffled = meas.subset(np.random.default_rng(0).permutation(meas.n_poses))
    # the order is lost: each row's predecessor is not the pose the joint came from
    shuffled = Measurements(q=shuffled.q, position=shuffled.position, source="<shuffled>")
    result, _ = _fit(shuffled, model="auto", row_order=True)
    assert "backlash" not in result.model


def test_without_an_order_stated_auto_does_not_guess_one_and_says_so():
    """A file without time or dir columns may be in any order (a grid scan written row by row):
    auto leaves the terms of time and direction out, and says what would let it try them."""
    meas = _backlash_campaign(300, 3)
    result, said = _fit(meas, model="auto")
    assert "backlash" not in result.model and "drift" not in result.model
    assert not any("backlash" in r.model or "drift" in r.model for r in result.model_selection)
    assert any(s.startswith("model auto: backlash and drift not tried") and "--row-order" in s for s in said)
    with pytest.raises(Exception, match="backlash term needs the direction each joint approached"):
        _fit(meas, model="backlash")


def test_direction_columns_override_the_row_order(tmp_path):
    meas = _backlash_campaign(300, 4)
    # the true directions as columns, then the rows shuffled: the columns still say how each pose was reached
    lines = save_and_read(meas, tmp_path / "a.csv").splitlines()
    dirs = _signs_of_moves(meas.q)
    header = lines[0] + "," + ",".join(f"dir{j + 1}" for j in range(6))
    rows = [line + "," + ",".join(f"{d:+.0f}" for d in dirs[i]) for i, line in enumerate(lines[1:])]
    order = np.random.default_rng(1).permutation(len(rows))
    (tmp_path / "b.csv").write_text("\n".join([header] + [rows[i] for i in order]) + "\n")
    result, said = _fit(load_measurements(tmp_path / "b.csv", n_joints=6), model="backlash")
    values = _values(result, "backlash")
    assert values["backlash2"]["value"] == pytest.approx(BACKLASH_DEG[2], rel=0.15)
    assert any("dir1..dirN columns" in s for s in said)


def save_and_read(meas, path):
    save_measurements(meas, path)
    return path.read_text()


def test_planted_drift_is_recovered_and_later_poses_are_predicted_at_their_time():
    calibration = _drift_campaign(400, 5)
    # validation measured during the same campaign, on the same clock
    validation = _drift_campaign(200, 6, start_s=5.0, end_s=INTERVAL_S * 399)
    result, said = _fit(calibration, model="drift", validate=validation)
    values = _values(result, "drift")
    for j, planted in DRIFT_DEG_PER_H.items():
        assert values[f"drift{j}"]["unit"] == "deg/h"
        assert values[f"drift{j}"]["value"] == pytest.approx(planted, rel=0.15), j
    assert any("time column" in s and "t = 7980 s" in s for s in said)
    assert result.metrics["validation_after"].position["rms"] < 1.15 * FLOOR
    geometric, _ = _fit(calibration, validate=validation)
    assert geometric.metrics["validation_after"].position["rms"] > 1.5 * FLOOR
    auto, _ = _fit(calibration, model="auto")
    assert auto.model == "drift"


def test_drift_on_the_row_clock_predicts_other_files_at_the_last_pose_and_says_so(tmp_path, quiet):
    calibration = _drift_campaign(400, 7, time_column=False)
    result, said = _fit(calibration, model="drift", row_order=True)
    assert any("row numbers stand for time" in s for s in said)
    values = _values(result, "drift")
    # 20 s a row: the rate per 1000 rows is 1000 · 20 s / 3600 s/h times the rate per hour
    per_1000_rows = {j: r * 1000 * INTERVAL_S / 3600 for j, r in DRIFT_DEG_PER_H.items()}
    assert values["drift2"]["unit"] == "deg/1000 rows"
    assert values["drift3"]["value"] == pytest.approx(per_1000_rows[3], rel=0.15)
    save_robot(result.robot, tmp_path / "cal.toml")
    text = (tmp_path / "cal.toml").read_text()
    assert 'clock = "row"' in text
    robot = load_robot(tmp_path / "cal.toml")
    # a later campaign whose joints stand where the calibration's last pose left them
    later = _drift_campaign(200, 8, start_s=0.0, time_column=False)
    later = Measurements(q=later.q, position=later.position, source="later.csv")
    ev = evaluate(robot, later)
    assert any("later.csv has no rows of the calibration file" in n for n in ev.notes)


def test_a_drift_model_written_and_read_back_predicts_the_same(tmp_path):
    calibration = _drift_campaign(300, 9)
    result, _ = _fit(calibration, model="drift")
    save_robot(result.robot, tmp_path / "cal.toml")
    robot = load_robot(tmp_path / "cal.toml")
    assert robot.terms.clock == ("s", pytest.approx(INTERVAL_S * 299))
    inputs = calibration.inputs
    a = result.robot.fk(calibration.q, None, inputs)[:, :3, 3]
    b = robot.fk(calibration.q, None, inputs)[:, :3, 3]
    assert np.max(np.abs(a - b)) < 1e-6


# --- terms the poses did not make visible ---------------------------------------------------

def _one_way_campaign(n, seed):
    """Every joint approached from below (a pose sequence sorted per joint): the directions the
    rows' order gives are +1 everywhere but the first pose (unknown, 0)."""
    c = ind.campaign("kr5-arc", {"a2": 0.3, "theta3": 0.002}, n, np.random.default_rng(seed), noise=NOISE,
                     measure="position")
    q = np.sort(c["q"], axis=0)  # each joint rises from row to row
    g = ind.geometry("kr5-arc", {"a2": 0.3, "theta3": 0.002})
    b = np.radians([BACKLASH_DEG.get(j + 1, 0.0) for j in range(6)])
    rng = np.random.default_rng(seed + 100)
    pos = np.array([ind.pose(g, qi + b)[:3, 3] for qi in q]) + rng.normal(0, NOISE, (n, 3))
    return Measurements(q=q, position=pos, source="<one-way campaign>")


def test_backlash_from_one_way_motion_is_dropped_with_what_would_show_it():
    meas = _one_way_campaign(200, 11)
    assert np.all(np.diff(meas.q, axis=0) >= 0)
    result, said = _fit(meas, model="backlash", row_order=True)
    ident = result.identifiability
    for j in range(1, 7):
        assert f"backlash{j}" in ident.dropped
        text = ident.reasons[f"backlash{j}"].text()
        assert "at 1 pose only" in text and f"both sides (a dir{j} column" in text
    assert not _values(result, "backlash")  # nothing reported as if measured
    assert any("backlash1 dropped" in s for s in said)
    # given both directions, the same joints' backlash is identified
    result, _ = _fit(_backlash_campaign(200, 11), model="backlash", row_order=True)
    assert "backlash2" in result.names


def test_drift_over_constant_time_is_dropped():
    meas = _drift_campaign(120, 12)
    still = Measurements(q=meas.q, position=meas.position, time=np.full(meas.n_poses, 50.0), source="<one time>")
    result, _ = _fit(still, model="drift")
    reason = result.identifiability.reasons["drift2"]
    assert reason.kind == "unvaried" and "at no pose" in reason.text() and "measure over time" in reason.text()
    # one pose at another time: a column constant but for one row rests on that pose alone
    t = np.full(meas.n_poses, 50.0)
    t[-1] = 900.0
    late = Measurements(q=meas.q, position=meas.position, time=t, source="<one late pose>")
    result, _ = _fit(late, model="drift")
    assert "drift2" in result.identifiability.dropped and "at 1 pose only" in \
        result.identifiability.reasons["drift2"].text()
