"""Honest statistics against a planted truth from the independent simulator (tests/independent.py).

- Standard uncertainties match the spread of the estimates: over many draws the z-scores
  (estimate − truth) / uncertainty have a standard deviation near 1 for every parameter,
  with stated and with estimated noise, full-pose and position-only.
- Goodness of fit: χ² matches its degrees of freedom on purely geometric data; an
  unmodelled joint deflection is called a misfit and traced to its joint.
- DH robots with parallel axes get β: a planted misalignment is fitted to the noise floor.
"""

import math
import warnings

import independent as ind
import numpy as np
import pytest

from robocal.calibration import calibrate
from robocal.io.robotfile import load_robot
from robocal.model.measurements import Measurements
from robocal.model.metrics import Metrics
from robocal.presets.wen2019 import TABLE2_DEVIATIONS

DRAWS = 60
NOISE, ANGLE_NOISE = 0.02, math.radians(0.001)


def _measurements(c: dict) -> Measurements:
    return Measurements(q=c["q"], position=c["position"], rotation=c["rotation"])


def _calibrate(robot, meas, **kw):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        result = calibrate(robot, meas, "lm", **kw)
    return result, [str(w.message) for w in caught]


def _kr5_identifiable_deviations(seed: int) -> dict[str, float]:
    """Deviations on the parameters robocal keeps for position-only KR5 data (the others are
    planted zero, so every kept estimate has a plain truth to compare with)."""
    rng = np.random.default_rng(seed)
    planted = {f"{k}{i}": rng.uniform(-0.25, 0.25) if k in ("a", "d") else rng.uniform(-0.005, 0.005)
               for i in range(1, 7) for k in ("a", "d", "alpha", "theta")}
    for name in ("d2", "a5", "alpha5", "alpha6", "theta6"):
        planted.pop(name)
    return planted


CASES = {
    "er10l-c10 full pose": ("er10l-c10", "pose", {k: v for k, v in TABLE2_DEVIATIONS.items() if k != "d2"}),
    "kr5-arc position only": ("kr5-arc", "position", _kr5_identifiable_deviations(7)),
}


@pytest.mark.slow
@pytest.mark.parametrize("case", CASES)
@pytest.mark.parametrize("noise", ["stated", "estimated"])
def test_uncertainties_match_the_spread_of_the_estimates(case, noise):
    name, measure, planted = CASES[case]
    robot = load_robot(name)
    stated = {"noise": NOISE, "angle_noise": ANGLE_NOISE} if measure == "pose" else {"noise": NOISE}
    z: dict[str, list[float]] = {}
    for draw in range(DRAWS):
        c = ind.campaign(name, planted, 40, np.random.default_rng(1000 + draw), noise=NOISE, angle_noise=ANGLE_NOISE,
                         measure=measure)
        res, _ = _calibrate(robot, _measurements(c), **(stated if noise == "stated" else {}))
        assert res.noise.source == noise
        for n, x, u in zip(res.names, res.x, res.uncertainty):
            z.setdefault(n, []).append((x - planted.get(n, 0.0)) / u)
    spread = {n: float(np.std(v, ddof=1)) for n, v in z.items() if len(v) == DRAWS}
    assert len(spread) >= 20
    assert all(0.7 <= s <= 1.4 for s in spread.values()), spread


def test_estimated_noise_is_the_planted_noise_per_block():
    robot = load_robot("er10l-c10")
    c = ind.campaign("er10l-c10", TABLE2_DEVIATIONS, 300, np.random.default_rng(5), noise=0.05,
                     angle_noise=math.radians(0.003))
    res, _ = _calibrate(robot, _measurements(c))
    assert res.noise.position == pytest.approx(0.05, rel=0.06)
    assert res.noise.orientation == pytest.approx(math.radians(0.003), rel=0.06)
    assert res.k == pytest.approx((0.05 / math.radians(0.003)) ** 2, rel=0.15)
    assert res.goodness_of_fit.reduced_chi2 == pytest.approx(1.0, abs=0.02)


@pytest.mark.parametrize("measure", ["pose", "position"])
def test_geometric_data_fit_to_the_stated_noise_without_a_warning(measure):
    robot = load_robot("kr5-arc")
    c = ind.campaign("kr5-arc", _kr5_identifiable_deviations(3), 60, np.random.default_rng(9), noise=NOISE,
                     angle_noise=ANGLE_NOISE, measure=measure)
    res, said = _calibrate(robot, _measurements(c), noise=NOISE, angle_noise=ANGLE_NOISE)
    gof = res.goodness_of_fit
    assert gof.noise_source == "stated" and 0.6 <= gof.reduced_chi2 <= 1.5
    # the data's values less the parameters' effective number: the prior takes a sliver of the ones the
    # poses barely see (their prior shares), never more than it leaves
    n = res.measurements.n_poses * (6 if measure == "pose" else 3) - len(res.names)
    assert 0.001 < gof.p_value < 0.999 and n <= gof.dof == pytest.approx(n + float(np.sum(res.prior_share)))
    assert not any("misfit" in s for s in said)
    d = res.to_dict()["goodness_of_fit"]
    assert set(d) == {"chi2", "dof", "reduced_chi2", "p_value", "noise_source"}


def test_an_unmodelled_joint_deflection_is_a_misfit_traced_to_its_joint():
    robot = load_robot("kr5-arc")

    def sag(q):  # joint 2 gives way like a spring under the arm's weight: about 0.5 mm at the tool
        dq = np.zeros_like(q)
        dq[:, 1] = 5e-4 * np.cos(q[:, 1])
        return dq

    c = ind.campaign("kr5-arc", _kr5_identifiable_deviations(3), 60, np.random.default_rng(9), noise=NOISE,
                     measure="position", joint_error=sag)
    res, said = _calibrate(robot, _measurements(c), noise=NOISE)
    assert res.goodness_of_fit.reduced_chi2 > 3
    misfit = [s for s in said if s.startswith("model misfit:")]
    assert len(misfit) == 1 and "joint 2 periodic in q2" in misfit[0]
    # uncertainties are scaled by the reduced χ², and said to be
    assert "scaled by" in misfit[0]
    unscaled, _ = _calibrate(robot, _measurements(c), noise=NOISE * math.sqrt(res.goodness_of_fit.reduced_chi2))
    np.testing.assert_allclose(res.uncertainty, unscaled.uncertainty, rtol=0.05)


def _misaligned_kr5(frames: str, seed: int):
    """A DH KR5 whose axes 2 and 3 are misaligned by 0.15° (β2), measured with 0.02 mm noise."""
    planted = {**_kr5_identifiable_deviations(seed), "beta2": math.radians(0.15)}
    base = np.eye(4)
    tool = np.eye(4)
    if frames != "none":
        base[:3, 3], tool[:3, 3] = (1500.0, -800.0, 200.0), (30.0, -20.0, 110.0)
    rng = np.random.default_rng(seed)
    cal = ind.campaign("kr5-arc", planted, 60, rng, noise=NOISE, measure="position", base=base, tool=tool)
    val = ind.campaign("kr5-arc", planted, 300, rng, noise=0.0, measure="position", base=base, tool=tool)
    return _measurements(cal), _measurements(val)


@pytest.mark.parametrize("frames", ["none", "base+tool"])
def test_parallel_axes_of_a_dh_robot_get_beta_and_reach_the_floor(frames):
    dh = load_robot("kr5-arc")
    meas, val = _misaligned_kr5(frames, 21)
    default, said = _calibrate(dh, meas, frames=frames)
    floor, _ = _calibrate(dh.replace(convention="hayati"), meas, frames=frames)
    without_beta, _ = _calibrate(dh, meas, frames=frames, params="kou2022")
    rms = {k: Metrics.of(r.robot, val).position["rms"] for k, r in
           (("default", default), ("floor", floor), ("dh only", without_beta))}
    assert default.robot.convention == "hayati" and "beta2" in default.names
    assert rms["default"] <= max(1.3 * rms["floor"], rms["floor"] + 0.005), rms
    assert rms["dh only"] > 3 * rms["floor"], rms  # the incomplete model cannot reach it
    assert not any(s.startswith("implausible") for s in said)
    assert all(abs(x) < (0.1 if n.startswith(("alpha", "theta", "beta")) else 10) for n, x in
               zip(default.names, default.x) if not n.startswith(("base", "tool")))
