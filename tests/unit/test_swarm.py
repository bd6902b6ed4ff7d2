"""The swarm engine: numba and numpy give the same particles; batched swarms equal single ones."""

import numpy as np
import pytest

from robocal.optimize.swarm import constriction, ipso, ldpso_bt, ldpso_population, pso, pso_batch
from robocal.presets import kou2022, wen2019

LO, HI = -np.ones(5), np.ones(5)


def sphere(X):
    return np.sum((X - 0.3) ** 2, axis=-1)


@pytest.mark.parametrize("method,paper", [(pso, kou2022.PSO), (ipso, wen2019.IPSO), (ldpso_bt, kou2022.LDPSO_BT)])
def test_backends_give_the_same_run(method, paper):
    kw = {**paper, "particles": 30, "iterations": 40, "seed": 3}
    if method is ldpso_bt:
        kw["min_particles"] = 10
    a = method(sphere, LO, HI, backend="numpy", **kw)
    from robocal.backend import numba_installed

    if numba_installed():
        b = method(sphere, LO, HI, backend="numba", **kw)
        np.testing.assert_array_equal(a.x, b.x)
        np.testing.assert_array_equal(a.history, b.history)
    assert a.status == "completed" and a.success
    assert a.fun == float(sphere(a.x[None])[0])  # x and fun agree
    assert np.all(np.diff(a.history) <= 0) and a.nit == 40 and np.all(np.abs(a.x - 0.3) < 0.05)


def test_batched_swarms_equal_single_swarms_in_distribution(backend):
    targets = np.array([[0.1, -0.2, 0.3, 0.0, 0.5], [-0.4, 0.4, 0.0, 0.2, -0.1]])

    def f(X):
        return np.sqrt(np.sum((X - targets[:, None, :]) ** 2, axis=-1))

    best, fbest, history = pso_batch(f, LO, HI, 2, particles=40, iterations=150, w=0.7, c1=1.5, c2=1.5, seed=1,
                                     backend=backend)
    assert history.shape == (151, 2) and np.all(np.diff(history, axis=0) <= 0)
    np.testing.assert_allclose(best, targets, atol=1e-4)
    np.testing.assert_allclose(fbest, np.linalg.norm(best - targets, axis=1))


def test_non_finite_objective_diverges():
    out = pso(lambda X: np.full(len(X), np.nan), -np.ones(3), np.ones(3), particles=10, iterations=5, w=0.8, c1=1.49,
              c2=1.49)
    assert out.status == "diverged" and not out.success


def test_population_and_constriction_follow_the_papers():
    sizes = [ldpso_population(t, 240, 40, 500) for t in range(1, 501)]
    assert sizes[0] == 240 and sizes[-1] == 40 and np.mean(sizes) == pytest.approx(140, abs=0.5)
    assert constriction(4.1) == pytest.approx(0.7298, abs=1e-4)
