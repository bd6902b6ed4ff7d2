"""Workload W4 of robocal's speed targets; prints its rows. Run: python benchmarks/bench_w4.py"""

from robocal.bench import format_value, w4

for row in w4():
    print(f"{row.workload:55s} {format_value(row):>12s}  target {row.target}  {row.peer} {row.note}")
