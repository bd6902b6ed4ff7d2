"""Workload W6 of robocal's speed targets: --model auto on the UR10 half split (series C, 1386 full poses),
beside a geometric LM on the same poses.  Run from the source tree: python benchmarks/bench_w6.py [REPEATS]"""

import sys

from robocal.bench.timing import print_rows
from robocal.bench.workloads import w6_auto

print_rows(w6_auto(int(sys.argv[1]) if len(sys.argv) > 1 else 1))
