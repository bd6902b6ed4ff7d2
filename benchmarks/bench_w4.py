"""Workload W4 of robocal's speed targets; prints its rows. Run: python benchmarks/bench_w4.py"""

from robocal.bench.timing import print_rows
from robocal.bench.workloads import w4_fk

print_rows(w4_fk())
