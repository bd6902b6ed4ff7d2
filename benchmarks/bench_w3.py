"""Workload W3 of robocal's speed targets; prints its rows. Run: python benchmarks/bench_w3.py"""

from robocal.bench.timing import print_rows
from robocal.bench.workloads import w3_lm

print_rows(w3_lm())
