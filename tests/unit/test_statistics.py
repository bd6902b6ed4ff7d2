"""Covariance, F-test and outlier screening against direct computations."""

import numpy as np
import pytest
from scipy.stats import f as f_dist

from robocal.calibration.judge.statistics import covariance, f_test, robust_outliers, standard_uncertainties


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


def test_the_outlier_test_reads_each_kind_of_row_with_its_own_law():
    """Plane rows (one value: |e| is χ with one degree of freedom) and point rows (three: Maxwell)
    with different σ: over many draws of good rows none is called an outlier; read as one kind
    with the Maxwell law, the plane rows' σ comes out low and good rows are flagged."""
    rng = np.random.default_rng(0)
    kinds = np.repeat([1, 2], [60, 90])
    flagged_by_kind = flagged_pooled = 0
    for _ in range(400):
        point = rng.normal(0.0, 0.3, (60, 3))
        normal = rng.normal(size=(90, 3))
        normal /= np.linalg.norm(normal, axis=1, keepdims=True)
        plane = normal * rng.normal(0.0, 0.02, (90, 1))
        e = np.vstack([point, plane])
        flagged_by_kind += len(robust_outliers(e, kinds, {1: 3, 2: 1})[0])
        flagged_pooled += len(robust_outliers(plane)[0])
    assert flagged_by_kind == 0
    assert flagged_pooled > 0
    # a gross error among plane rows stands out all the same
    e = np.vstack([rng.normal(0.0, 0.3, (60, 3)), normal * rng.normal(0.0, 0.02, (90, 1))])
    e[100] = normal[40] * 0.5
    assert list(robust_outliers(e, kinds, {1: 3, 2: 1})[0]) == [100]
