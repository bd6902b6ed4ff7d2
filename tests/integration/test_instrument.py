"""The instrument's own σ per point (tests/independent.py plants the truth; the noise is drawn
here, larger for points further from the instrument, as a tracker's is)."""

from __future__ import annotations

import math
import warnings

import independent as ind
import numpy as np
import pytest

from robocal.calibration import calibrate
from robocal.calibration.fit.instrument import Instrument, paule_mandel
from robocal.model.measurements import Measurements

DEVIATIONS = {"a2": 0.3, "d4": -0.2, "theta3": 0.002, "alpha2": -0.001, "a3": 0.15}


def _sigma(position: np.ndarray) -> np.ndarray:
    """σ per axis (m, 3) mm: 2 µm plus 40 µm per metre from the instrument at the origin."""
    distance = np.linalg.norm(position, axis=1) / 1000.0
    return np.repeat((0.002 + 0.04 * distance)[:, None], 3, axis=1)


def _campaign(seed: int, n: int = 80, joint_error=None) -> Measurements:
    rng = np.random.default_rng(seed)
    c = ind.campaign("kr5-arc", DEVIATIONS, n, rng, noise=0.0, measure="position", joint_error=joint_error)
    sigma = _sigma(c["position"])
    return Measurements(q=c["q"], position=c["position"] + rng.normal(0.0, sigma), sigma_position=sigma,
                        sigma_source="planted σ")


def _fit(meas, **kw):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        result = calibrate("kr5-arc", meas, "lm", frames="none", **kw)
    return result, [str(w.message) for w in caught]


def test_the_misfit_is_within_the_instrument_noise_when_the_model_is_complete():
    result, said = _fit(_campaign(1, 200))
    inst = result.instrument
    assert inst is not None and inst.source == "planted σ"
    # χ² against the instrument alone: within the spread of a χ² on its degrees of freedom
    assert abs(inst.reduced_chi2 - 1.0) < 4 * math.sqrt(2 / inst.dof)
    assert inst.tau_position < 0.3 * inst.sigma_position[1]
    assert "instrument" in result.to_dict() and result.to_dict()["instrument"]["reduced_chi2"] == inst.reduced_chi2
    assert not any("misfit" in s for s in said)


def test_an_unmodelled_effect_shows_as_scatter_beyond_the_instrument():
    def wobble(q):  # a transmission error of joint 2 the geometric model does not contain
        dq = np.zeros_like(q)
        dq[:, 1] = 3e-4 * np.sin(2 * q[:, 1])
        return dq

    result, _ = _fit(_campaign(2, 200, wobble))
    inst = result.instrument
    assert inst.reduced_chi2 > 5
    # τ is what the residuals show beyond the instrument: near the residual scatter per axis
    assert inst.tau_position == pytest.approx(result.noise.position, rel=0.2)
    assert result.noise.label == "residual scatter σ" and "leaves" in inst.sentence()


@pytest.mark.slow
def test_uncertainties_with_per_point_sigma_match_the_spread_and_beat_equal_weights():
    z: dict[str, list[float]] = {}
    weighted, alike = [], []
    for draw in range(40):
        meas = _campaign(100 + draw, 60)
        res, _ = _fit(meas, noise=None)
        equal, _ = _fit(Measurements(q=meas.q, position=meas.position))
        for n, x, u in zip(res.names, res.x, res.uncertainty):
            z.setdefault(n, []).append((x - DEVIATIONS.get(n, 0.0)) / u)
        weighted.append([x - DEVIATIONS.get(n, 0.0) for n, x in zip(res.names, res.x)])
        alike.append([x - DEVIATIONS.get(n, 0.0) for n, x in zip(equal.names, equal.x)])
    spread = {n: float(np.std(v, ddof=1)) for n, v in z.items()}
    assert all(0.65 <= s <= 1.45 for s in spread.values()), spread
    # weighing by the instrument's σ estimates the parameters more closely than weighing alike
    ratio = np.std(np.array(weighted), axis=0) / np.std(np.array(alike), axis=0)
    assert np.median(ratio) < 0.9, ratio


def test_paule_mandel_has_the_closed_form_of_equal_sigmas():
    rng = np.random.default_rng(0)
    r = rng.normal(0.0, 0.5, 3000)
    s2 = np.full(r.size, 0.1**2)
    tau = paule_mandel(r**2, s2, r.size - 10)
    assert tau**2 == pytest.approx(np.sum(r**2) / (r.size - 10) - 0.01, rel=1e-6)
    assert paule_mandel(r**2, np.full(r.size, 1.0), r.size) == 0.0  # within the instrument: no scatter beyond


def test_an_mpe_statement_sets_sigma_by_distance():
    inst = Instrument.parse("0.015+0.006/m")
    sigma = inst.sigma(np.array([[3000.0, 4000.0, 0.0]]))  # 5 m away
    assert sigma == pytest.approx(np.full((1, 3), (0.015 + 0.006 * 5) / 2))
    assert "2 σ per axis (the default coverage)" in inst.sentence()
    assert Instrument.parse("0.02 k=3").sigma(np.zeros((1, 3)))[0, 0] == pytest.approx(0.02 / 3)
    assert "as stated" in Instrument.parse("0.02+0.01/m, k=3").sentence()


def test_the_command_line_weighs_by_the_statement_and_says_how(tmp_path, run_cli):
    data = tmp_path / "d.csv"
    code, _, err = run_cli("simulate", "kr5-arc", "--poses", "60", "--measure", "position", "--noise", "0.01",
                           "--out", data)
    assert code == 0, err
    code, out, err = run_cli("calibrate", "kr5-arc", data, "--frames", "none", "--instrument", "0.01+0.01/m",
                             "--out", tmp_path / "r.json")
    assert code == 0, err
    assert "instrument (--instrument '0.01+0.01/m'" in out and "taken as 2 σ per axis" in out
    code, _, err = run_cli("calibrate", "kr5-arc", data, "--instrument", "0.01+0.01/m", "--noise", "0.01")
    assert code == 2 and "not both" in err
