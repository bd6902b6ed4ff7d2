"""W7: filtering a 10 000-robtarget RAPID module for an IRB 120, beside one batched FK of as many
poses, quiet and with one busy process per core (peak memory of a fresh interpreter); and on the
command line (its default output) beside ``robocal evaluate`` of as many poses; and the reading of
as many targets in each language.

Run from the source tree: python benchmarks/bench_w7.py
"""

from robocal.bench.timing import print_rows
from robocal.bench.workloads import busy_cores, w7_command_line, w7_filter, w7_languages

rows = w7_filter(3) + w7_command_line(3) + w7_languages(3)
with busy_cores() as busy:
    rows += w7_filter(3, label=f" ({busy.n} busy)")
print_rows(rows)
