"""Workload W8 of robocal's speed targets: --model auto on a UR5-sized position-only set (1000 planted poses,
the wrist seen least), beside a geometric LM on the same poses; target ≤ 20×.
Run from the source tree: python benchmarks/bench_w8.py [REPEATS]"""

import sys

from robocal.bench.timing import print_rows
from robocal.bench.workloads import w8_auto_position

print_rows(w8_auto_position(int(sys.argv[1]) if len(sys.argv) > 1 else 3))
