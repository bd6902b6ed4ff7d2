"""Workload W1 of robocal's speed targets; prints its rows. Run: python benchmarks/bench_w1.py"""

from robocal.bench import format_value, w1

for row in w1():
    print(f"{row.workload:55s} {format_value(row):>12s}  target {row.target}  {row.peer} {row.note}")
