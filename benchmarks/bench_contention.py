"""W1 (compiled kernels beside a naive numpy IPSO) and W6 (--model auto beside a geometric LM), quiet
and with one busy process per core, side by side in one run.

Run from the source tree: python benchmarks/bench_contention.py [--no-w6]
"""

import sys

from robocal.bench.timing import print_rows
from robocal.bench.workloads import busy_cores, w1_naive_ratio, w6_auto

w6 = "--no-w6" not in sys.argv
rows = w1_naive_ratio(5) + (w6_auto() if w6 else [])
with busy_cores() as busy:
    rows += w1_naive_ratio(5, label=f" ({busy.n} busy)", target=0.10)
    if w6:
        rows += [r.__class__(f"{r.workload} ({busy.n} busy)", r.value, r.unit, r.target, r.met, r.peer, r.note)
                 for r in w6_auto()]
print_rows(rows)
