"""IPSO's Halton start without importing scipy.stats: the same numbers as scipy.stats.qmc.Halton, scrambled
(with the generator left as scipy leaves it) and plain, to the last bit."""

import numpy as np
import pytest
from scipy.stats import qmc

from robocal.optimize.halton import halton, primes


@pytest.mark.parametrize("d", [1, 2, 7, 24, 30, 61])
@pytest.mark.parametrize("seed", [0, 1, 12345])
def test_the_scrambled_sequence_is_scipys_and_leaves_the_generator_as_scipy_does(d, seed):
    ours, theirs = np.random.default_rng(seed), np.random.default_rng(seed)
    expected = qmc.Halton(d=d, scramble=True, seed=theirs).random(40)
    np.testing.assert_array_equal(halton(40, d, ours), expected)
    np.testing.assert_array_equal(ours.random(5), theirs.random(5))  # the swarm's draws after it


@pytest.mark.parametrize("d", [1, 5, 24])
def test_the_plain_sequence_is_scipys_past_its_origin(d):
    engine = qmc.Halton(d=d, scramble=False)
    engine.fast_forward(1)
    np.testing.assert_array_equal(halton(60, d, start=1), engine.random(60))


def test_the_bases_are_the_primes():
    assert primes(10) == [2, 3, 5, 7, 11, 13, 17, 19, 23, 29]
