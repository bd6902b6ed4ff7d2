"""Covariance, F-test and outlier screening against direct computations."""

import numpy as np
import pytest
from scipy.stats import f as f_dist

from robocal.calibration.statistics import covariance, f_test, robust_outliers, standard_uncertainties


def test_covariance_from_jacobian_and_from_information_equal_the_direct_inverse(rng):
    J = rng.normal(size=(500, 6)) * [1, 10, 100, 0.1, 1, 3]
    direct = 2.5 * np.linalg.inv(J.T @ J)
    np.testing.assert_allclose(covariance(J, variance=2.5), direct, rtol=1e-9)
    np.testing.assert_allclose(covariance(information=J.T @ J, variance=2.5), direct, rtol=1e-9)
    np.testing.assert_allclose(standard_uncertainties(J), np.sqrt(np.diag(direct / 2.5)), rtol=1e-9)


def test_undetermined_parameters_get_infinite_uncertainty(rng):
    J = rng.normal(size=(50, 3))
    J = np.column_stack([J, J[:, 0] + J[:, 1]])
    u = standard_uncertainties(J)
    assert np.all(np.isinf(u[[0, 1, 3]])) and np.isfinite(u[2])


def test_f_test_equals_scipy_distribution():
    p = f_test(120.0, 100.0, 2, 50)
    stat = (20.0 / 2) / (100.0 / 50)
    assert p == pytest.approx(f_dist.sf(stat, 2, 50))
    assert f_test(100.0, 100.0, 1, 10) == 1.0


def test_robust_outliers_find_gross_errors_only(rng):
    dp = rng.normal(0.0, 0.02, (200, 3))
    dp[[5, 77]] += 3.0
    flagged, sigma = robust_outliers(dp)
    assert list(flagged) == [5, 77]
    assert sigma == pytest.approx(0.02, rel=0.15)
