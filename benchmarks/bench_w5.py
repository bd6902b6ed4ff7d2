"""Workload W5 of robocal's speed targets; prints its rows. Run: python benchmarks/bench_w5.py"""

from robocal.bench import format_value, w5

for row in w5():
    print(f"{row.workload:55s} {format_value(row):>12s}  target {row.target}  {row.peer} {row.note}")
