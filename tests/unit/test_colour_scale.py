"""An error map's colour scale: one far pose must not set it for all the others."""

import numpy as np

from robocal.report.figures import OUTLIER_FACTOR, ROBUST_PERCENTILE, robust_limit


def test_a_far_value_is_an_outlier_and_a_narrow_spread_keeps_its_whole_range():
    rng = np.random.default_rng(0)
    typical = rng.uniform(0.0, 0.3, 1000)
    with_outlier = np.r_[typical, 1.44]
    assert robust_limit(with_outlier) == np.percentile(with_outlier, ROBUST_PERCENTILE)
    narrow = rng.uniform(0.45, 0.52, 2000)  # the largest within OUTLIER_FACTOR of the percentile
    assert narrow.max() <= OUTLIER_FACTOR * np.percentile(narrow, ROBUST_PERCENTILE)
    assert robust_limit(narrow) == narrow.max()
    assert robust_limit(np.array([0.1, 0.2, 5.0])) == 5.0  # too few to call any an outlier
    assert robust_limit(np.zeros(10)) == 1.0
