"""The noise model's reweighting: the linearised settling lands where a chain of full refits does."""

import math

import numpy as np

from robocal.calibration.config import CalibrationConfig
from robocal.calibration.fit.methods import fit_lm
from robocal.calibration.fit.noise import NoiseModel, block_sigmas, settle
from robocal.calibration.fit.problem import Setup
from robocal.io.robotfile import load_robot
from robocal.model.parameters import ParameterSpace
from robocal.presets import wen2019
from robocal.simulation import simulate


def test_settle_matches_a_chain_of_refits():
    robot = load_robot("er10l-c10")
    sim = simulate(robot, 60, deviations="paper", noise=0.03, angle_noise=math.radians(0.002), seed=3)
    names = list(wen2019.PARAMETERS)  # identifiable from full poses
    cfg = CalibrationConfig()
    problem = Setup(ParameterSpace.of(robot), sim.measurements, 1.0, 0.01).problem(names)
    x0 = fit_lm(problem, np.zeros(problem.n_params), cfg).x
    # the reference: re-estimate and refit by LM until nothing moves any more
    chain, x = problem, x0
    for _ in range(60):
        sigmas = block_sigmas(chain, x, NoiseModel())
        chain = chain.setup.with_noise(*sigmas).problem(names)
        x_new = fit_lm(chain, x, cfg).x
        if np.abs(x_new - x).max() < 1e-14:
            break
        x = x_new
    target = settle(problem, x0, NoiseModel())
    np.testing.assert_allclose(target.sigmas, sigmas, rtol=2e-3)
    covariance = np.linalg.inv(chain.residual_jacobian(x).T @ chain.residual_jacobian(x))
    assert np.abs((x0 + target.step - x) / np.sqrt(np.diag(covariance))).max() < 0.05


def test_setups_made_from_one_share_the_model_s_jacobian_at_a_solution_and_no_other(monkeypatch):
    """Another noise or prior weighs the same model's Jacobian: the setups made from one share it
    (computed once at a solution), whitened each its own way; other measurements, or a vector
    changed in place after the call, are never served another's."""
    robot = load_robot("er10l-c10")
    sim = simulate(robot, 30, deviations="paper", noise=0.03, angle_noise=math.radians(0.002), seed=4)
    names = list(wen2019.PARAMETERS)
    setup = Setup(ParameterSpace.of(robot), sim.measurements, 1.0, 0.01)
    x = np.random.default_rng(0).normal(0, 1e-3, len(names))
    fresh = Setup(ParameterSpace.of(robot), sim.measurements, 0.5, 0.02).problem(names).residual_jacobian(x)
    calls = []
    columns = ParameterSpace.jacobian_columns
    monkeypatch.setattr(ParameterSpace, "jacobian_columns", lambda *a, **k: calls.append(1) or columns(*a, **k))
    setup.problem(names).residual_jacobian(x)
    shared = setup.with_noise(0.5, 0.02).problem(names).residual_jacobian(x)
    assert len(calls) == 1
    np.testing.assert_array_equal(shared, fresh)  # whitened by its own σ
    setup.with_measurements(sim.measurements.subset(np.arange(20))).problem(names).residual_jacobian(x)
    assert len(calls) == 2
    y = x.copy()
    before = setup.problem(names).residual_jacobian(y)  # still kept
    assert len(calls) == 2
    y += 1e-3  # a solver that reuses its buffer
    after = setup.problem(names).residual_jacobian(y)
    assert len(calls) == 3 and not np.array_equal(before, after)


def test_a_setup_sent_to_a_worker_leaves_its_kept_jacobians_behind():
    import pickle

    robot = load_robot("er10l-c10")
    sim = simulate(robot, 30, deviations="paper", seed=4)
    names = list(wen2019.PARAMETERS)
    setup = Setup(ParameterSpace.of(robot), sim.measurements, 1.0, 0.01)
    setup.problem(names).residual_jacobian(np.zeros(len(names)))
    assert len(setup.evaluated) == 1
    again = pickle.loads(pickle.dumps(setup))
    assert len(again.evaluated) == 0 and len(pickle.dumps(setup)) < len(pickle.dumps(dict(setup.evaluated)))
    np.testing.assert_array_equal(again.problem(names).residual_jacobian(np.zeros(len(names))),
                                  setup.problem(names).residual_jacobian(np.zeros(len(names))))
