"""The prior of the identification (MODEL §3.1) against planted truths of the independent
simulator (tests/independent.py): what the data cannot pin stays where the prior puts it, what
they fix is unchanged by it, its posterior σ are calibrated, and the verdict on physicality is
a requirement a script can hold a calibration to.

The UR-type wrist below is the case of a real UR5 laser-tracker set: joint 5 barely moves and
joint 6 not at all, the reflector sits on the flange axis, only positions are measured.  Its
wrist parameters are then nearly dependent; plain least squares walks along that valley to
tens of millimetres and degrees, and harmonics of joint 6 to hundreds of degrees.
"""

from __future__ import annotations

import json
import math
import warnings

import independent as ind
import numpy as np
import pytest

from robocal.calibration import calibrate
from robocal.io.robotfile import load_robot, parse_robot
from robocal.model.measurements import Measurements

LENGTH, ANGLE, ZERO = 1.0, math.radians(0.1), math.radians(1.0)  # the default widths, written here


def _width(name: str) -> float:
    return LENGTH if name[0] in "ad" and not name.startswith("alpha") else ZERO if name.startswith("theta") else ANGLE


def _prior_truth(rng) -> dict[str, float]:
    """Deviations of a, d, α, θ drawn from the default prior itself."""
    out = {}
    for i in range(1, 7):
        out[f"a{i}"], out[f"d{i}"] = rng.normal(0.0, LENGTH, 2)
        out[f"alpha{i}"], out[f"theta{i}"] = rng.normal(0.0, ANGLE), rng.normal(0.0, ZERO)
    return out


def _wrist_campaign(n: int, seed: int, truth: dict[str, float]) -> Measurements:
    """A UR5 whose joint 5 moves ±3° and joint 6 ±3°, a reflector 33.7 mm along the flange axis,
    positions in a tracker's frame with 0.02 mm noise."""
    rng = np.random.default_rng(seed)
    q = np.column_stack([rng.uniform(-1.5, 1.5, n), rng.uniform(-2.5, -0.6, n), rng.uniform(0.5, 2.2, n),
                         rng.uniform(-2.5, -0.5, n), -math.pi / 2 + rng.uniform(-0.05, 0.05, n),
                         rng.uniform(-0.05, 0.05, n)])
    base = ind._trans(1200.0, -300.0, 400.0) @ ind._rz(0.3)
    g = ind.geometry("ur5", truth)
    p = np.array([ind.pose(g, qi, base=base, tool=ind._trans(0.0, 0.0, 33.7))[:3, 3] for qi in q])
    return Measurements(q=q, position=p + rng.normal(0.0, 0.02, (n, 3)), source="<ur5 wrist>")


def _ur5():
    return parse_robot(ind.robot_toml("ur5", {}), source="ur5 (planted)")


def _fit(robot, meas, **kw):
    with warnings.catch_warnings(record=True) as said:
        warnings.simplefilter("always")
        res = calibrate(robot, meas, "lm", frames="base+tool", **kw)
    return res, [str(w.message) for w in said]


def _misses(res, truth) -> dict[str, float]:
    """|estimate − truth| / prior width of every joint parameter, the truth regrouped as the
    estimate is (a kept parameter estimates itself plus what the dropped ones it absorbs moved)."""
    out = {}
    for name, x in zip(res.names, res.x):
        if name.startswith(("base", "tool")):
            continue
        planted = truth.get(name, 0.0) + sum(c * truth.get(d, 0.0) for d, c in res.identifiability.absorbed_by(name))
        out[name] = abs(float(x) - planted) / _width(name)
    return out


def test_a_wrist_the_poses_cannot_see_stays_within_its_prior_and_says_so():
    truth = _prior_truth(np.random.default_rng(5))
    meas = _wrist_campaign(400, 6, truth)
    res, said = _fit(_ur5(), meas)
    misses = _misses(res, truth)
    assert max(misses.values()) < 3.0, misses
    assert res.physical.physical and not any(s.startswith("implausible") for s in said)
    # the parameters the poses do not pin are named, in the JSON and the table
    assert {"a5", "alpha5"} <= set(res.held)
    params = {p["name"]: p for p in res.to_dict()["parameters"]}
    assert params["a5"]["pinned_by"] == "prior" and params["a5"]["prior_share"] > 0.5
    assert params["a2"]["pinned_by"] == "data" and params["a2"]["prior_share"] < 0.01
    from robocal.report.tables import HELD_NOTE, parameter_rows

    rows = {r[0]: r for r in parameter_rows(res)}
    assert HELD_NOTE in rows["a5"][-1] and HELD_NOTE not in rows["a2"][-1]
    # without the prior the same data walk the wrist along its valley: the verdict says so
    free, said = _fit(_ur5(), meas, prior="all=free", max_evaluations=300)
    assert max(_misses(free, truth).values()) > 5.0
    assert not free.physical.physical and any(s.startswith("implausible") for s in said)
    # the prior costs the fit nothing: the held-out poses say the same
    assert res.metrics["predicted"].position["rms"] <= 1.01 * free.metrics["predicted"].position["rms"]


def test_harmonics_the_poses_cannot_separate_are_held_not_chosen_at_hundreds_of_degrees():
    truth = _prior_truth(np.random.default_rng(5))
    meas = _wrist_campaign(400, 6, truth)
    res, _ = _fit(_ur5(), meas, model="harmonics")
    turns = {p["name"]: abs(p["error"]) for p in res.to_dict()["parameters"] if p["name"].startswith("harmonic")}
    assert max(turns.values()) < math.radians(0.2) and res.physical.physical
    assert "harmonic6_sin1" in res.held
    free, _ = _fit(_ur5(), meas, model="harmonics", prior="all=free", max_evaluations=300)
    assert not free.physical.physical and "° of turn" in free.physical.sentence()


def test_a_chain_the_data_fix_is_unchanged_by_the_prior():
    """Full poses of the ER10L-C10 over its whole joint ranges, 0.005 mm and 0.0005° noise: every
    parameter is measured far more finely than any prior states it, and the prior moves none of
    them by more than a thousandth of its standard uncertainty."""
    deviations = {k: v for k, v in ind.uniform_deviations("er10l-c10", 0.3, 0.001, np.random.default_rng(7)).items()}
    c = ind.campaign("er10l-c10", deviations, 200, np.random.default_rng(8), noise=0.005,
                     angle_noise=math.radians(0.0005))
    meas = Measurements(q=c["q"], position=c["position"], rotation=c["rotation"])
    kw = {"frames": "none", "noise": 0.005, "angle_noise": math.radians(0.0005)}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = calibrate("er10l-c10", meas, "lm", **kw)
        free = calibrate("er10l-c10", meas, "lm", prior="all=free", **kw)
    assert res.names == free.names and not res.held
    shift = np.abs(res.x - free.x) / free.uncertainty
    assert np.max(shift) < 1e-3, dict(zip(res.names, shift))


@pytest.mark.slow
def test_posterior_uncertainties_match_the_spread_over_draws_from_the_prior():
    """Forty robots drawn from the prior, each calibrated on its own wrist campaign: the errors of
    the estimates over their posterior σ have a spread of one, held parameters included (FIGAROH's
    check of standard errors, with the prior's draws as the population)."""
    robot = _ur5()
    z, held = [], []
    for draw in range(40):
        truth = _prior_truth(np.random.default_rng(100 + draw))
        res, _ = _fit(robot, _wrist_campaign(200, 200 + draw, truth))
        for name, x, u in zip(res.names, res.x, res.uncertainty):
            if name.startswith(("base", "tool")):
                continue
            planted = truth.get(name, 0.0) + sum(c * truth.get(d, 0.0)
                                                 for d, c in res.identifiability.absorbed_by(name))
            z.append((float(x) - planted) / u)
            held.append(name in res.held)
    z, held = np.array(z), np.array(held)
    assert held.any() and (~held).any()
    assert 0.8 <= np.std(z) <= 1.25, np.std(z)
    assert 0.7 <= np.std(z[held]) <= 1.4, np.std(z[held])


def test_require_physical_exits_4_naming_what_is_not(tmp_path, run_cli):
    """A nominal file with a link 30 mm off: the data pin the deviation, and a model 30 mm from its
    drawing is not a clean result."""
    truth = {"a2": 0.3, "theta3": 0.002}
    c = ind.campaign("kr5-arc", truth, 60, np.random.default_rng(3), noise=0.01, measure="position")
    data = tmp_path / "d.csv"
    lines = ["q1,q2,q3,q4,q5,q6,x,y,z"] + [",".join(f"{v:.9g}" for v in [*np.degrees(q), *p])
                                          for q, p in zip(c["q"], c["position"])]
    data.write_text("\n".join(lines) + "\n")
    wrong = tmp_path / "wrong.toml"
    wrong.write_text(ind.robot_toml("kr5-arc", {"a2": -30.0}))
    code, out, err = run_cli("calibrate", wrong, data, "--frames", "none", "--require", "physical", "--json")
    assert code == 4, err
    assert "requirement not met: physical (the calibrated model is not physical: a2 +30" in err
    assert json.loads(out)["physical"]["physical"] is False
    right = tmp_path / "right.toml"
    right.write_text(ind.robot_toml("kr5-arc", {}))
    code, out, err = run_cli("calibrate", right, data, "--frames", "none", "--require", "physical", "--json")
    assert code == 0, err
    assert json.loads(out)["physical"]["physical"] is True


def test_widths_from_the_robot_file_and_the_command_line(tmp_path, run_cli):
    truth = _prior_truth(np.random.default_rng(5))
    meas = _wrist_campaign(150, 6, truth)
    data = tmp_path / "d.csv"
    data.write_text("q1,q2,q3,q4,q5,q6,x,y,z\n" + "\n".join(
        ",".join(f"{v:.10g}" for v in [*np.degrees(q), *p]) for q, p in zip(meas.q, meas.position)) + "\n")
    robot = tmp_path / "ur5.toml"
    robot.write_text(ind.robot_toml("ur5", {}) + '[prior]\nlength = 0.5\na5 = 0.2\nharmonic = "free"\n')
    assert load_robot(robot).prior.widths == {"length": 0.5, "a5": 0.2, "harmonic": math.inf}
    out, exported = tmp_path / "r.json", tmp_path / "cal.toml"
    code, _, err = run_cli("calibrate", robot, data, "--frames", "base+tool", "--prior", "zero=0.5",
                           "--prior", "d5=free", "--out", out, "--export", exported)
    assert code == 0, err
    params = {p["name"]: p for p in json.loads(out.read_text())["parameters"]}
    assert params["a5"]["prior_sigma"] == pytest.approx(0.2)
    assert params["a2"]["prior_sigma"] == pytest.approx(0.5)
    assert params["theta2"]["prior_sigma"] == pytest.approx(math.radians(0.5))  # in the JSON's unit, rad
    assert params["d5"]["prior_sigma"] is None and params["d5"]["pinned_by"] == "free"
    assert params["alpha2"]["prior_sigma"] == pytest.approx(math.radians(0.1))  # the default
    # the calibrated robot file keeps what its nominal stated, for the next calibration
    assert load_robot(exported).prior.widths == {"length": 0.5, "a5": 0.2, "harmonic": math.inf}
    for bad, what in ((("--prior", "a9=1"), "names parameter 'a9'"), (("--prior", "lenght=1"), "unknown prior key"),
                      (("--prior", "length=-1"), "width > 0"), (("--prior", "base=1"), "takes no prior")):
        code, _, err = run_cli("calibrate", robot, data, *bad, "--out", tmp_path / "bad.json")
        assert code == 2 and what in err and len(err.strip().splitlines()) == 1, err
        assert not (tmp_path / "bad.json").exists()
    typo = tmp_path / "typo.toml"
    typo.write_text(ind.robot_toml("ur5", {}) + "[prior]\nlenght = 1.0\n")
    code, _, err = run_cli("calibrate", typo, data)
    assert code == 2 and "[prior]" in err and "lenght" in err


def test_a_stated_noise_too_small_never_widens_a_parameter_beyond_its_prior(tmp_path, run_cli):
    """The UR5 wrist measured with 0.02 mm noise, stated as 0.005 (4× too small): the data's information
    is scaled by the reduced χ² it shows, the prior's counted once, so no posterior σ is wider than its
    prior width (the old s·(JᵀJ + P)⁻¹ put a5 at ±3.5 mm against its 1 mm prior); χ²'s p-value is printed
    only where σ was stated, and a width no computer can weigh is refused on one line."""
    truth = _prior_truth(np.random.default_rng(8))
    meas = _wrist_campaign(300, 9, truth)
    res, said = _fit(_ur5(), meas, noise=0.005)
    assert res.goodness_of_fit.reduced_chi2 > 10  # the misfit is said, and the σ scaled
    assert any(s.startswith("model misfit") for s in said)
    prior = res.prior_sigma
    held = np.isfinite(prior)
    assert np.all(res.uncertainty[held] <= prior[held] * (1 + 1e-9)), \
        {n: (u, p) for n, u, p in zip(res.names, res.uncertainty, prior) if u > p}
    assert "p_value" in res.to_dict()["goodness_of_fit"]
    estimated, _ = _fit(_ur5(), meas)
    assert "p_value" not in estimated.to_dict()["goodness_of_fit"]
    from robocal.report.tables import noise_line

    assert ", p " in noise_line(res) and ", p " not in noise_line(estimated)
    data = tmp_path / "wrist.csv"
    from robocal.io.measurements import save_measurements

    save_measurements(meas, data)
    robot = tmp_path / "ur5.toml"
    robot.write_text(ind.robot_toml("ur5", {}))
    code, _, err = run_cli("calibrate", robot, data, "--joint-unit", "rad", "--prior", "a5=1e-160")
    assert code == 2 and len(err.strip().splitlines()) == 1 and "below 1e-06" in err and "Traceback" not in err


def test_a_loosely_built_arm_has_its_length_width_sized_by_the_data():
    """An arm whose lengths are off by 8 mm (σ), not the 1 mm of a machined one: the data widen the
    length prior to what they show (said as a note), the model predicts new poses as the free fit does,
    and it is judged physical against the width used; a stated width wins and is not sized."""
    rng = np.random.default_rng(2)
    truth = {}
    for i in range(1, 7):
        truth[f"a{i}"], truth[f"d{i}"] = rng.normal(0.0, 8.0, 2)
        truth[f"alpha{i}"], truth[f"theta{i}"] = rng.normal(0.0, ANGLE), rng.normal(0.0, ZERO)

    def campaign(n, seed):
        c = ind.campaign("kr5-arc", truth, n, np.random.default_rng(seed), noise=0.05, measure="position",
                         base=ind._trans(1500.0, 200.0, 0.0), tool=ind._trans(0.0, 0.0, 80.0))
        return Measurements(q=c["q"], position=c["position"])

    robot = parse_robot(ind.robot_toml("kr5-arc", {}), source="kr5-arc (planted)")
    data, fresh = campaign(60, 1), campaign(300, 2)
    sized, said = _fit(robot, data, validate=fresh)
    width = [n for n in sized.notes if n.startswith("prior widths from the data: length")]
    assert width and 4.0 < float(width[0].split("length ")[1].split(" mm")[0]) < 12.0, width
    assert sized.physical.physical and not any(s.startswith("implausible") for s in said)
    free, said = _fit(robot, data, validate=fresh, prior="length=free")
    held, _ = _fit(robot, data, validate=fresh, prior="length=1")
    assert not free.physical.physical  # the fixed 10 mm bound alone would call the real arm not physical
    assert not [n for n in held.notes if n.startswith("prior widths from the data")]
    rms = {k: r.metrics["validation_after"].position["rms"] for k, r in (("sized", sized), ("free", free),
                                                                          ("held", held))}
    assert rms["sized"] <= 1.01 * rms["free"] and rms["sized"] < rms["held"], rms
