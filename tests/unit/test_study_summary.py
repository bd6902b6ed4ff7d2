"""Study statistics against direct computations: the median's confidence interval from the
binomial distribution written out, its coverage over many draws, and the paired comparison."""

import math

import numpy as np
import pytest

from robocal.study.runs import row
from robocal.study.spec import RunKey, Study
from robocal.study.summary import cell_stats, comparisons, median_interval


def _ranks_by_hand(n: int, level: float = 0.95) -> int | None:
    """The largest k with P(B ≤ k − 1) ≤ (1 − level)/2, B ~ Bin(n, ½), summing the pmf directly."""
    best = None
    for k in range(1, n // 2 + 1):
        tail = sum(math.comb(n, j) for j in range(k)) / 2**n
        if tail <= (1 - level) / 2:
            best = k
    return best


@pytest.mark.parametrize("n", [5, 6, 9, 12, 30, 101])
def test_median_interval_uses_the_binomial_order_statistics(n, rng):
    x = rng.lognormal(size=n)
    got = median_interval(x)
    k = _ranks_by_hand(n)
    assert got.median == pytest.approx(np.median(x))
    if k is None:
        assert got.low is None and got.high is None
        return
    s = np.sort(x)
    assert (got.low, got.high) == (s[k - 1], s[n - k])
    assert got.coverage == pytest.approx(1 - 2 * sum(math.comb(n, j) for j in range(k)) / 2**n)


def test_median_interval_covers_the_true_median_at_least_95_percent_of_the_time():
    rng = np.random.default_rng(7)
    true_median = math.exp(0.0)  # lognormal(0, 1)
    hits = 0
    draws = 2000
    for _ in range(draws):
        i = median_interval(rng.lognormal(size=12))
        hits += i.low <= true_median <= i.high
    assert hits / draws >= 0.95 - 2 * math.sqrt(0.05 * 0.95 / draws)


def test_paired_comparison_and_cells_match_a_direct_computation(rng):
    study = Study("kr5-arc", ("lm", "pso"), (30,), (0.02,), 10)
    a = rng.uniform(0.03, 0.05, 10)
    b = a + rng.normal(0.01, 0.005, 10)
    ta, tb = rng.uniform(0.04, 0.06, 10), rng.uniform(0.5, 0.9, 10)
    rows = [row(RunKey("lm", 30, 0.02, s), "spec", "converged", 10, 0.03, a[s], 5, 7, ta[s]) for s in range(10)]
    rows += [row(RunKey("pso", 30, 0.02, s), "spec", "completed" if s else "max_iterations", 10, 0.03, b[s], 500,
                 9000, tb[s])
             for s in range(10)]
    cells = {c.method: c for c in cell_stats(study, rows)}
    assert cells["lm"].success_rate == 1.0 and cells["pso"].success_rate == 0.9
    assert cells["pso"].validation.median == pytest.approx(np.median(b), rel=1e-9)
    (c,) = comparisons(study, rows)
    d = a - b
    assert c.pairs == 10 and c.a_wins == int(np.sum(d < 0)) and c.b_wins == int(np.sum(d > 0))
    assert c.difference.median == pytest.approx(np.median(d), rel=1e-6)
    assert c.time_ratio.median == pytest.approx(np.median(ta / tb), rel=1e-3)
    from scipy.stats import wilcoxon

    assert c.p_value == pytest.approx(wilcoxon(d).pvalue)
