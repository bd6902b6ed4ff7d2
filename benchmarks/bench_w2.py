"""Workload W2 of robocal's speed targets; prints its rows. Run: python benchmarks/bench_w2.py"""

from robocal.bench.timing import print_rows
from robocal.bench.workloads import w2_swarms

print_rows(w2_swarms())
