"""Start-up time of the command line against a bare ``python -c "import numpy"``.

Target: ``robocal --help``, ``robocal --version`` and ``robocal robots`` answer within 4×
the time of importing numpy.  The commands run interleaved, ``--repeats`` rounds, so that
machine load hits all alike; the figures are medians and the ratios are medians of the
per-round ratios.  Run: python benchmarks/bench_startup.py [--repeats 15]
"""

from __future__ import annotations

import argparse
import shutil
import statistics
import subprocess
import sys
import time

TARGET_RATIO = 4.0


def _timed(cmd: list[str]) -> float:
    t = time.perf_counter()
    subprocess.run(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, check=True)
    return time.perf_counter() - t


def measure(repeats: int) -> dict[str, dict[str, float]]:
    robocal = [shutil.which("robocal")] if shutil.which("robocal") else [sys.executable, "-m", "robocal"]
    commands = {
        "python -c 'import numpy'": [sys.executable, "-c", "import numpy"],
        "robocal --help": robocal + ["--help"],
        "robocal --version": robocal + ["--version"],
        "robocal robots": robocal + ["robots"],
    }
    for cmd in commands.values():  # warm the file-system cache and .pyc files once
        _timed(cmd)
    times: dict[str, list[float]] = {name: [] for name in commands}
    for _ in range(repeats):
        for name, cmd in commands.items():
            times[name].append(_timed(cmd))
    base = times["python -c 'import numpy'"]
    return {name: {"median_s": statistics.median(t), "ratio": statistics.median(a / b for a, b in zip(t, base))}
            for name, t in times.items()}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=15)
    rows = measure(parser.parse_args().repeats)
    ok = True
    for name, r in rows.items():
        met = "" if name.startswith("python") else ("  met" if r["ratio"] <= TARGET_RATIO else "  falls short")
        ok &= r["ratio"] <= TARGET_RATIO
        print(f"{name:28s} {r['median_s'] * 1000:7.1f} ms   {r['ratio']:4.2f}× import numpy{met}")
    print(f"target: ≤ {TARGET_RATIO:g}× import numpy")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
