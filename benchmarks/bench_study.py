"""A 2000-run study in this process and on Dask clusters of 1, 2 and 4 local workers, side by
side: runs per second, scaling efficiency, and what 10⁵ runs would take on 64 workers at the
measured per-worker rate.

    python benchmarks/bench_study.py [RUNS]

Each configuration runs the same study into a fresh folder (nothing resumed) through a
scheduler address, as on a real cluster; the cluster is started before the clock and the
time is the study's.  On a 2-core machine 4 workers share 2 cores: that row says what
oversubscription costs.
"""

import os
import sys
import tempfile
import time
from pathlib import Path

from robocal.study.driver import run_study
from robocal.study.spec import parse_study

RUNS = int(sys.argv[1]) if len(sys.argv) > 1 else 2000
SEEDS = RUNS // 2  # two noise cells
STUDY = f"""
robot = "kr5-arc"
errors = "uniform:0.25,0.05"
measure = "position"
poses = [30]
noise = [0.0, 0.02]
methods = ["lm"]
seeds = {SEEDS}
validate = 100
"""


def main() -> None:
    spec = parse_study(STUDY, source="bench-study.toml")
    n = len(spec.runs())
    from dask.distributed import LocalCluster

    rates = {}
    with tempfile.TemporaryDirectory() as tmp:
        start = time.perf_counter()
        run_study(spec, Path(tmp) / "here", workers=1)
        here = n / (time.perf_counter() - start)
        print(f"{n} runs in this process (no Dask): {n / here:7.1f} s, {here:6.2f} runs/s", flush=True)
        for workers in (1, 2, 4):
            with LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                              dashboard_address=None) as cluster:
                start = time.perf_counter()
                result = run_study(spec, Path(tmp) / f"w{workers}", scheduler=cluster.scheduler_address)
                elapsed = time.perf_counter() - start
            assert result.ran == n
            rates[workers] = n / elapsed
            efficiency = rates[workers] / (workers * rates[1])
            print(f"{n} runs, {workers} Dask worker{'s' if workers > 1 else ''}: {elapsed:7.1f} s, "
                  f"{rates[workers]:6.2f} runs/s, scaling efficiency {100 * efficiency:5.1f} %", flush=True)
    cores = os.cpu_count() or 1
    best = max(w for w in rates if w <= cores)
    per_worker = rates[best] / best
    hours = 1e5 / (64 * per_worker) / 3600
    print(f"10^5 runs on 64 workers at {per_worker:.2f} runs/s per worker (measured with {best} on {cores} cores): "
          f"{hours * 60:.0f} min")


if __name__ == "__main__":
    main()
