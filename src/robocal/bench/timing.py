"""Timing helpers: medians of repeated runs, one row per figure, peak memory of a subprocess."""

from __future__ import annotations

import json
import statistics
import subprocess
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np


@dataclass
class Row:
    """One benchmark figure: value in seconds (unit "s"), a rate (e.g. "M/s") or a ratio ("×")."""

    workload: str
    value: float
    unit: str
    target: str
    met: bool | None
    peer: str = ""
    note: str = ""


def median_time(fn: Callable[[], object], repeats: int) -> float:
    """Median wall time (s) of ``repeats`` calls."""
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return statistics.median(times)


def run_measured(code: str) -> tuple[dict, float]:
    """Run Python ``code`` in a fresh interpreter; it prints one JSON object as its last line.

    Returns that object and the interpreter's peak resident memory in GB, so a memory figure
    is the workload's own and not that of whatever ran before in this process.  On Linux the peak
    is the new process image's own (VmHWM): ``ru_maxrss`` keeps, across the exec, the resident
    size of the process it was forked from (a bench parent holding W6's models made W7 read 0.6
    GB where the filter takes 0.2).
    """
    wrapper = (code + "\nimport resource as _r, json as _j\n"
               "try:\n"
               "    _p = [int(l.split()[1]) for l in open('/proc/self/status') if l.startswith('VmHWM:')][0]\n"
               "except (OSError, IndexError, ValueError):\n"
               "    _p = _r.getrusage(_r.RUSAGE_SELF).ru_maxrss\n"
               "print(_j.dumps({'__peak_kb': _p}))\n")
    proc = subprocess.run([sys.executable, "-c", wrapper], capture_output=True, text=True, check=True)
    lines = [ln for ln in proc.stdout.splitlines() if ln.startswith("{")]
    result, peak = json.loads(lines[-2]) if len(lines) > 1 else {}, json.loads(lines[-1])["__peak_kb"]
    return result, peak / 1e6  # ru_maxrss is in kB on Linux


def format_value(r: Row) -> str:
    if not np.isfinite(r.value):
        return "—"
    if r.unit == "s":
        return f"{r.value * 1000:.1f} ms" if r.value < 1 else f"{r.value:.2f} s"
    if r.unit == "×":
        return f"{r.value:.3f}"
    return f"{r.value:.2f} {r.unit}"


def print_rows(rows: list[Row]) -> None:
    """Plain-text rows, for the scripts in ``benchmarks/``."""
    for row in rows:
        print(f"{row.workload:55s} {format_value(row):>12s}  target {row.target}  {row.peer} {row.note}")
