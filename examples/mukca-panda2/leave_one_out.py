"""Each placement of the two-socket tool held out in turn: calibrate the Panda on the other eight
and predict the held-out one (its sockets are new unknowns), beside the nominal URDF.

Run: python examples/mukca-panda2/leave_one_out.py
"""

import warnings
from pathlib import Path

import numpy as np

from robocal.calibration import calibrate
from robocal.io.measurements import load_measurements
from robocal.io.robotfile import load_robot

HERE = Path(__file__).parent


def main() -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        nominal = load_robot(HERE / "panda.urdf", tip_link="ball_link")
    meas = load_measurements(HERE / "panda_2.csv", n_joints=7, joint_unit="rad").with_distances(
        [("hole_0", "hole_1", 50.0)])
    rows = {"nominal": [], "calibrated": []}
    for setup in dict.fromkeys(meas.setup):
        held = np.array([s == setup for s in meas.setup])
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            fit = calibrate(nominal, meas.subset(~held), "lm")
        test = meas.subset(held)
        for name, robot in (("nominal", nominal), ("calibrated", fit.robot)):
            rows[name].append(test.constraints.figures(robot.positions(test.q)))
        print(f"{setup:13s} nominal {rows['nominal'][-1]['point_spread_rms']:.3f} mm, calibrated "
              f"{rows['calibrated'][-1]['point_spread_rms']:.3f} mm spread")
    for name, figures in rows.items():
        spread = np.sqrt(np.mean([f["point_spread_rms"] ** 2 for f in figures]))
        miss = np.sqrt(np.mean([f["distance_error_rms"] ** 2 for f in figures]))
        print(f"held-out placements, {name}: point spread {spread:.3f} mm RMS, distance error {miss:.3f} mm RMS")


if __name__ == "__main__":
    main()
