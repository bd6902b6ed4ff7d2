"""Split series C into a calibration half and a validation half, as the README does.

    python examples/ur10-ipa/split.py examples/ur10-ipa/series_c.csv OUT_DIR

Poses are shuffled by ``numpy.random.default_rng(0).permutation`` (seed 0 unless --seed) and
cut in two: the first half calibrates (OUT_DIR/calibration.csv), the second validates
(OUT_DIR/validation.csv).  Rows keep their pose_id and their order in the file.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("data", type=Path)
    parser.add_argument("out", type=Path)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    header, *rows = args.data.read_text(encoding="utf-8").splitlines()
    order = np.random.default_rng(args.seed).permutation(len(rows))
    half = len(rows) // 2
    args.out.mkdir(parents=True, exist_ok=True)
    for name, index in (("calibration", order[:half]), ("validation", order[half:])):
        lines = [header] + [rows[i] for i in np.sort(index)]
        (args.out / f"{name}.csv").write_text("\n".join(lines) + "\n", encoding="utf-8")
        print(f"{args.out / name}.csv: {len(index)} poses")


if __name__ == "__main__":
    main()
