"""Workload W3 of robocal's speed targets; prints its rows. Run: python benchmarks/bench_w3.py"""

from robocal.bench import format_value, w3

for row in w3():
    print(f"{row.workload:55s} {format_value(row):>12s}  target {row.target}  {row.peer} {row.note}")
