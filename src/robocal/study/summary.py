"""What a study's runs say: per cell and per pair of methods, with confidence intervals.

Confidence intervals of a median are distribution-free: the order statistics x_(k) and
x_(n+1−k) with k the largest rank such that P(B < k) ≤ (1 − level)/2 for B ~ Binomial(n, ½);
their coverage is at least ``level`` whatever the distribution of the runs.  Methods are
compared on the seeds they share (the same robot, the same poses, the same noise): the median
of the paired differences of validation RMS with its interval, how often each method wins,
the Wilcoxon signed-rank test, and the median of the paired time ratios.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np

from .runs import SUCCESS
from .spec import Study, number_key

LEVEL = 0.95


@dataclass(frozen=True)
class Interval:
    """A median and its distribution-free confidence interval (None bounds: too few runs)."""

    median: float
    low: float | None
    high: float | None
    coverage: float | None


def median_interval(values, level: float = LEVEL) -> Interval:
    """The median of ``values`` with a distribution-free interval of at least ``level``."""
    from scipy.stats import binom

    x = np.sort(np.asarray([v for v in values if math.isfinite(v)], float))
    n = len(x)
    if n == 0:
        return Interval(math.nan, None, None, None)
    tail = (1 - level) / 2
    k = int(binom.ppf(tail, n, 0.5))  # P(B ≤ k−1) ≤ tail < P(B ≤ k)
    while k > 0 and binom.cdf(k - 1, n, 0.5) > tail:
        k -= 1
    if k < 1:
        return Interval(float(np.median(x)), None, None, None)
    coverage = 1 - 2 * binom.cdf(k - 1, n, 0.5)
    return Interval(float(np.median(x)), float(x[k - 1]), float(x[n - k]), float(coverage))


@dataclass(frozen=True)
class CellStats:
    method: str
    poses: int
    noise: float
    runs: int
    success_rate: float
    validation: Interval
    time: Interval


@dataclass(frozen=True)
class Comparison:
    """Method a against method b in one (poses, noise), on their shared seeds."""

    a: str
    b: str
    poses: int
    noise: float
    pairs: int
    difference: Interval  # validation RMS a − b, mm
    a_wins: int
    b_wins: int
    p_value: float | None  # Wilcoxon signed-rank, two-sided
    time_ratio: Interval  # time a / time b


def _floats(rows, column):
    return [float(r[column]) for r in rows]


def cell_stats(study: Study, rows: list[dict]) -> list[CellStats]:
    by_cell = {}
    for r in rows:
        by_cell.setdefault((r["method"], r["poses"], r["noise"]), []).append(r)
    out = []
    for m, p, n in itertools.product(study.methods, study.poses, study.noise):
        rs = by_cell.get((m, str(p), number_key(n)), [])
        if not rs:
            continue
        ok = [r for r in rs if r["status"] in SUCCESS]
        out.append(CellStats(m, p, n, len(rs), len(ok) / len(rs), median_interval(_floats(rs, "validation_rms")),
                             median_interval(_floats(rs, "time_s"))))
    return out


def comparisons(study: Study, rows: list[dict]) -> list[Comparison]:
    from scipy.stats import wilcoxon

    index = {(r["method"], r["poses"], r["noise"], r["seed"]): r for r in rows}
    out = []
    for p, n in itertools.product(study.poses, study.noise):
        for a, b in itertools.combinations(study.methods, 2):
            va, vb, ta, tb = [], [], [], []
            for s in range(study.seeds):
                ra = index.get((a, str(p), number_key(n), str(s)))
                rb = index.get((b, str(p), number_key(n), str(s)))
                if ra is None or rb is None:
                    continue
                x, y = float(ra["validation_rms"]), float(rb["validation_rms"])
                if math.isfinite(x) and math.isfinite(y):
                    va.append(x), vb.append(y), ta.append(float(ra["time_s"])), tb.append(float(rb["time_s"]))
            if not va:
                continue
            d = np.array(va) - np.array(vb)
            p_value = None
            if len(d) >= 6 and np.any(d != 0):
                p_value = float(wilcoxon(d).pvalue)
            ratio = np.array(ta) / np.maximum(np.array(tb), 1e-12)
            out.append(Comparison(a, b, p, n, len(d), median_interval(d), int(np.sum(d < 0)), int(np.sum(d > 0)),
                                  p_value, median_interval(ratio)))
    return out


def _g(x: float | None, digits: int = 4) -> str:
    if x is None or not math.isfinite(x):
        return "—"
    return f"{x:.{digits}g}"


def _interval(i: Interval, digits: int = 4) -> str:
    if i.low is None:
        return f"{_g(i.median, digits)} (too few runs for an interval)"
    return f"{_g(i.median, digits)} [{_g(i.low, digits)}, {_g(i.high, digits)}]"


def summary_markdown(study: Study, rows: list[dict], *, elapsed_s: float | None = None,
                     executor: str = "") -> str:
    """summary.md of a study."""
    cells = cell_stats(study, rows)
    lines = [f"# Study {study.name}", "",
             f"Robot {study.robot}, errors {study.errors}, {study.measure} data, frames {study.frames}; "
             f"{study.seeds} seeds per cell, {study.validate} fresh poses per run"
             + (f"; options {study.calibration}" if study.calibration else "") + ".",
             f"{len(rows)} runs" + (f" in {elapsed_s:.1f} s ({len(rows) / elapsed_s:.3g} runs/s)"
                                     if elapsed_s else "") + (f" on {executor}" if executor else "") + ".", "",
             "## Cells", "",
             f"Median over the seeds, with a distribution-free {100 * LEVEL:g} % confidence interval of the median "
             "in brackets; success: the optimizer ended by its own criterion.", "",
             "| method | poses | noise (mm) | runs | success | validation RMS (mm) | time (s) |",
             "|---|---|---|---|---|---|---|"]
    for c in cells:
        lines.append(f"| {c.method} | {c.poses} | {_g(c.noise)} | {c.runs} | {100 * c.success_rate:.0f} % | "
                     f"{_interval(c.validation)} | {_interval(c.time, 3)} |")
    comps = comparisons(study, rows)
    if comps:
        lines += ["", "## Methods compared on shared seeds", "",
                  "Paired over the seeds both methods ran: the median difference of validation RMS (a − b) with its "
                  "interval, how often each was better, the Wilcoxon signed-rank p-value (two-sided), and the median "
                  "time ratio a / b.", "",
                  "| a | b | poses | noise (mm) | pairs | Δ validation RMS (mm) | a better | b better | p | "
                  "time a / b |", "|---|---|---|---|---|---|---|---|---|---|"]
        for c in comps:
            lines.append(f"| {c.a} | {c.b} | {c.poses} | {_g(c.noise)} | {c.pairs} | {_interval(c.difference, 3)} | "
                         f"{c.a_wins} | {c.b_wins} | {_g(c.p_value, 3)} | {_interval(c.time_ratio, 3)} |")
    failed = [r for r in rows if r["status"].startswith("error")]
    if failed:
        lines += ["", f"{len(failed)} runs failed: " + ", ".join(
            f"{r['method']}/{r['poses']}/{r['noise']}/seed {r['seed']} ({r['status']})" for r in failed[:10])]
    lines += ["", "Figures: `validation_rms.png`, `time.png` (box plots per method and cell). Rows: `runs.csv`.", ""]
    return "\n".join(lines)
