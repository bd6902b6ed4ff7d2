"""How honest are robocal's standard uncertainties?  z = (estimate − truth) / uncertainty over
many noise draws; its standard deviation should be 1 for every parameter.

The truth is planted by the test suite's independent simulator (tests/independent.py, plain
4×4 products), with the settings of the noise-model tests: ER10L-C10 full pose with Wen's
Table 2 deviations and a KR5 arc position-only, 40 poses, 0.02 mm and 0.001° noise, noise
stated and estimated.  Run: python benchmarks/uncertainty_zscores.py [--draws 160]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path[:0] = [str(Path(__file__).parents[1] / "tests"), str(Path(__file__).parents[1] / "tests" / "integration")]

import independent as ind  # noqa: E402
import numpy as np  # noqa: E402
from test_noise_model import ANGLE_NOISE, CASES, NOISE, _calibrate, _measurements  # noqa: E402

from robocal.io.robotfile import load_robot  # noqa: E402


def spread(case: str, stated: bool, draws: int) -> dict[str, float]:
    name, measure, planted = CASES[case]
    robot = load_robot(name)
    kw = ({"noise": NOISE, "angle_noise": ANGLE_NOISE} if measure == "pose" else {"noise": NOISE}) if stated else {}
    z: dict[str, list[float]] = {}
    for draw in range(draws):
        c = ind.campaign(name, planted, 40, np.random.default_rng(1000 + draw), noise=NOISE, angle_noise=ANGLE_NOISE,
                         measure=measure)
        res, _ = _calibrate(robot, _measurements(c), **kw)
        for n, x, u in zip(res.names, res.x, res.uncertainty):
            z.setdefault(n, []).append((x - planted.get(n, 0.0)) / u)
    return {n: float(np.std(v, ddof=1)) for n, v in z.items() if len(v) == draws}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--draws", type=int, default=160)
    draws = parser.parse_args().draws
    for case in CASES:
        for stated in (True, False):
            s = spread(case, stated, draws)
            print(f"{case:24s} noise {'stated   ' if stated else 'estimated'}  {len(s)} parameters, "
                  f"std of z {min(s.values()):.2f}–{max(s.values()):.2f} over {draws} draws")


if __name__ == "__main__":
    main()
