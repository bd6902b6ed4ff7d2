"""Convert the IPA UR10 laser-tracker export to a robocal measurement file.

The export (christianlandgraf/ipa-robot-accuracy, MIT license, LICENSE.md here) is
`;`-separated with decimal commas; joints are in radians in the order of the UR10's DH
table; the T-Mac pose is x, y, z in mm and rx, ry, rz in degrees as intrinsic X-Y-Z Euler
angles (scipy ``Rotation.from_euler("XYZ", …)``).  robocal's files give joints in degrees
and orientations as rpy with R = Rz(rz) Ry(ry) Rx(rx), so the rotation is converted, not
relabelled.  Each row is one pose; ``pose_id`` numbers them from 1 in file order.

Run: python examples/ur10-ipa/convert.py SOURCE.csv OUT.csv
"""

from __future__ import annotations

import csv
import sys

import numpy as np
from scipy.spatial.transform import Rotation

JOINTS = ("shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint", "wrist_1_joint", "wrist_2_joint",
          "wrist_3_joint")


def convert(source: str, out: str) -> int:
    with open(source, encoding="utf-8") as fh:
        rows = list(csv.DictReader(fh, delimiter=";"))

    def column(name):
        return np.array([float(r[name].replace(",", ".")) for r in rows])

    q = np.degrees(np.column_stack([column(j) for j in JOINTS]))
    xyz = np.column_stack([column(f"measurement_{a}") for a in "xyz"])
    euler = np.column_stack([column(f"measurement_r{a}") for a in "xyz"])
    R = Rotation.from_euler("XYZ", euler, degrees=True)
    rpy = R.as_euler("ZYX", degrees=True)[:, ::-1]  # robocal's rpy: R = Rz(rz) Ry(ry) Rx(rx)
    with open(out, "w", encoding="utf-8", newline="") as fh:
        w = csv.writer(fh, lineterminator="\n")
        w.writerow(["pose_id", "q1", "q2", "q3", "q4", "q5", "q6", "x", "y", "z", "rx", "ry", "rz"])
        for i in range(len(rows)):
            w.writerow([f"C{i + 1:04d}", *(f"{v:.6f}" for v in q[i]), *(f"{v:.5f}" for v in xyz[i]),
                        *(f"{v:.6f}" for v in rpy[i])])
    return len(rows)


if __name__ == "__main__":
    print(f"wrote {convert(sys.argv[1], sys.argv[2])} poses to {sys.argv[2]}")
