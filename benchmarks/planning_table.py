"""The pose-planning table of docs/calibrate.md: the plan's predicted validation RMS beside the
median of 20 random 30-pose sets, and both confirmed by simulation (the plan under 8 noise
draws, 12 random sets), each calibrated and judged on 500 fresh poses.

Run: python benchmarks/planning_table.py
"""

import math
import warnings

import numpy as np

from robocal.calibration import calibrate
from robocal.io.robotfile import load_robot
from robocal.plan import plan_poses
from robocal.simulation import random_joints, simulate

NOISE, ANGLE_NOISE = 0.02, math.radians(0.001)


def validation_rms(robot, truth, val, q, seed, measure):
    sim = simulate(truth, len(q), q=q, noise=NOISE, angle_noise=ANGLE_NOISE, seed=seed, measure=measure)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = calibrate(robot, sim.measurements, "lm", validate=val, k=(NOISE / ANGLE_NOISE) ** 2)
    return res.metrics["validation_after"].position["rms"]


def main() -> None:
    for name, measure, errors in [("kr5-arc", "position", "uniform:0.25,0.05"), ("er10l-c10", "pose", "paper")]:
        robot = load_robot(name)
        plan = plan_poses(robot, 30, candidates=2000, measure=measure, seed=0)
        truth = simulate(robot, 1, deviations=errors, seed=11).truth
        val = simulate(truth, 500, seed=12, measure=measure).measurements
        planned = np.mean([validation_rms(robot, truth, val, plan.q, s, measure) for s in range(8)])
        rng = np.random.default_rng(7)
        random = np.median([validation_rms(robot, truth, val, random_joints(robot, 30, rng), 100 + s, measure)
                            for s in range(12)])
        print(f"{name} {measure}: predicted {plan.predicted_rms:.4f} / {np.median(plan.random_rms):.4f} mm, "
              f"simulated {planned:.4f} / {random:.4f} mm")


if __name__ == "__main__":
    main()
