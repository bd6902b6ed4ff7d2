"""Workload W5 of robocal's speed targets; prints its rows. Run: python benchmarks/bench_w5.py"""

from robocal.bench.timing import print_rows
from robocal.bench.workloads import w5_pkm

print_rows(w5_pkm())
