"""Workload W1 of robocal's speed targets; prints its rows. Run: python benchmarks/bench_w1.py"""

from robocal.bench.timing import print_rows
from robocal.bench.workloads import w1_ipso

print_rows(w1_ipso())
