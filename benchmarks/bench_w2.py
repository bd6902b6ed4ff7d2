"""Workload W2 of robocal's speed targets; prints its rows. Run: python benchmarks/bench_w2.py"""

from robocal.bench import format_value, w2

for row in w2():
    print(f"{row.workload:55s} {format_value(row):>12s}  target {row.target}  {row.peer} {row.note}")
