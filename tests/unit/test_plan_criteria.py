"""Pose-planning criteria against a direct SVD."""

import math

import numpy as np
import pytest

from robocal.plan import criterion_value


def test_criteria_match_a_direct_svd(rng):
    J = rng.normal(size=(90, 7))
    scale = rng.uniform(0.5, 3.0, 7)
    s = np.linalg.svd(J, compute_uv=False)
    ss = np.linalg.svd(J * scale, compute_uv=False)
    M = J.T @ J
    assert criterion_value(M, "D", scale, 30) == pytest.approx(2 * np.sum(np.log(s)))
    assert criterion_value(M, "O1", scale, 30) == pytest.approx(np.prod(s) ** (1 / 7) / math.sqrt(30))
    assert criterion_value(M, "O2", scale, 30) == pytest.approx(ss[-1] / ss[0])
    assert criterion_value(M, "O3", scale, 30) == pytest.approx(ss[-1])
    assert criterion_value(M, "O4", scale, 30) == pytest.approx(ss[-1] ** 2 / ss[0])
