"""The residual model: its own prediction equals scikit-learn's, it survives JSON, it turns with
the base, and it does not learn noise."""

import json

import numpy as np
import pytest
from sklearn.gaussian_process import GaussianProcessRegressor

from robocal.calibration.residual import MIN_NOISE, fit_residual
from robocal.model.residual import ResidualModel


def _smooth(q):
    return np.column_stack([0.3 * np.sin(q[:, 0]) * np.cos(q[:, 1]), 0.2 * np.cos(2 * q[:, 2]), 0.1 * q[:, 1]])


def test_stored_prediction_equals_scikit_learn(rng):
    q = rng.uniform(-2, 2, (150, 6))
    e = _smooth(q) + rng.normal(0, 0.01, (150, 3))
    model, kernels = fit_residual(q, e, seed=1)
    reference = GaussianProcessRegressor(kernels[0], normalize_y=True, optimizer=None).fit(q, e)
    fresh = rng.uniform(-2, 2, (40, 6))
    np.testing.assert_allclose(model.predict(fresh), reference.predict(fresh), atol=1e-10)
    # and it learnt the function, not the noise
    assert np.sqrt(np.mean((model.predict(fresh) - _smooth(fresh)) ** 2)) < 0.02


def test_json_round_trip_and_orientation_block(rng):
    q = rng.uniform(-2, 2, (80, 6))
    e = np.concatenate([_smooth(q), 1e-3 * _smooth(q)[:, ::-1]], axis=1) + rng.normal(0, 1e-4, (80, 6))
    model, kernels = fit_residual(q, e, seed=2)
    assert len(kernels) == 2 and model.outputs == 6
    back = ResidualModel.from_dict(json.loads(json.dumps(model.to_dict())))
    fresh = rng.uniform(-2, 2, (25, 6))
    np.testing.assert_array_equal(back.predict(fresh), model.predict(fresh))


def test_the_correction_turns_with_the_base(rng):
    """Learnt in one measuring frame, the same robot seen from a frame turned by R gives the same
    correction turned by R: it belongs to the robot, not to where the tracker stood."""
    from robocal.math.so3 import exp_so3
    from robocal.model.residual import Block

    q = rng.uniform(-2, 2, (20, 6))
    model = ResidualModel(q, (Block(rng.normal(size=(20, 3)), np.ones(6), 1.0, np.zeros(3), np.ones(3)),))
    R0 = exp_so3(np.array([0.1, -0.3, 1.2]))
    model = ResidualModel(q, model.blocks, R0.T)  # fitted where the base had orientation R0
    p, R = np.zeros((5, 3)), np.broadcast_to(np.eye(3), (5, 3, 3))
    _, p0 = model.correct(q[:5], R, p, R0)
    np.testing.assert_allclose(p0, model.predict(q[:5]), atol=1e-12)  # in its own frame, as learnt
    turn = exp_so3(np.array([0.0, 0.4, -0.7]))
    _, p1 = model.correct(q[:5], R, p, turn @ R0)
    np.testing.assert_allclose(p1, p0 @ turn.T, atol=1e-12)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_pure_noise_is_left_as_noise(seed):
    rng = np.random.default_rng(seed)
    q = rng.uniform(-2, 2, (200, 6))
    e = rng.normal(0, 0.02, (200, 3))
    model, kernels = fit_residual(q, e, seed=seed)
    fresh_q, fresh_e = rng.uniform(-2, 2, (200, 6)), rng.normal(0, 0.02, (200, 3))
    # predicting fresh noise with the process is no better than predicting zero
    assert np.sqrt(np.mean((fresh_e - model.predict(fresh_q)) ** 2)) >= 0.98 * np.sqrt(np.mean(fresh_e**2))
    assert kernels[0].k2.noise_level >= MIN_NOISE
