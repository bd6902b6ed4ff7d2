"""Workload W1 of robocal's speed targets (Wen 2019's IPSO, 20 × 2000, 32 full poses): warm,
beside a straightforward numpy IPSO and robocal's own numpy path; and as the first run after
install meets it (an empty numba cache), beside the same naive IPSO.  Prints its rows.

Run: python benchmarks/bench_w1.py
"""

from robocal.bench.timing import print_rows
from robocal.bench.workloads import busy_cores, w1_first_run, w1_ipso, w1_naive_ratio, w1_whole_process

rows = w1_ipso() + w1_naive_ratio(5) + w1_first_run(3) + w1_whole_process(5)
with busy_cores() as busy:
    rows += w1_naive_ratio(3, label=f" ({busy.n} busy)", target=0.10)
print_rows(rows)
