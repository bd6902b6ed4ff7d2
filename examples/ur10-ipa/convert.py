"""Convert the IPA UR10 laser-tracker export to a robocal measurement file.

The export (christianlandgraf/ipa-robot-accuracy, MIT license, LICENSE.md here) is
`;`-separated with decimal commas; joints are in radians in the order of the UR10's DH
table; the T-Mac pose is x, y, z in mm and rx, ry, rz in degrees as intrinsic X-Y-Z Euler
angles (scipy ``Rotation.from_euler("XYZ", …)``).  robocal's files give joints in degrees
and orientations as rpy with R = Rz(rz) Ry(ry) Rx(rx), so the rotation is converted, not
relabelled.  Each row is one pose; ``pose_id`` numbers them from 1 in file order, named by the
series (``C0001`` for series C, ``D0001`` for D).

The export's own standard deviations come along as robocal's σ columns: ``sx, sy, sz`` (mm,
unchanged) and ``srx, sry, srz``, the σ of the orientation as a rotation vector about the
tracker's axes (deg), propagated from the σ of the three Euler angles through the map from
Euler-angle rates to angular velocity (taken per axis; their small correlations dropped).
``dir1..dir6`` are the signs of each joint's move into the pose from the one before in
measuring order (the export's row order), so that a random half of the rows still knows how
each pose was approached; ``temperature`` (°C) is the tracker's.

Run: python examples/ur10-ipa/convert.py SOURCE.csv OUT.csv
"""

from __future__ import annotations

import csv
import sys
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from robocal.model.measurements import move_directions

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
    s_xyz = np.column_stack([column(f"measurement_std_{a}") for a in "xyz"])
    s_rot = rotation_vector_sigma(euler, np.column_stack([column(f"measurement_std_r{a}") for a in "xyz"]))
    directions = move_directions(np.radians(q))
    temperature = column("measurement_temperature")
    with open(out, "w", encoding="utf-8", newline="") as fh:
        w = csv.writer(fh, lineterminator="\n")
        w.writerow(["pose_id", "q1", "q2", "q3", "q4", "q5", "q6", "x", "y", "z", "rx", "ry", "rz", "sx", "sy", "sz",
                    "srx", "sry", "srz", *(f"dir{j}" for j in range(1, 7)), "temperature"])
        # pose ids name their series: series_c_… → C0001, series_d_… → D0001
        series = Path(source).name.split("_")
        prefix = series[1][:1].upper() if len(series) > 1 and series[0] == "series" else "P"
        for i in range(len(rows)):
            w.writerow([f"{prefix}{i + 1:04d}", *(f"{v:.6f}" for v in q[i]), *(f"{v:.5f}" for v in xyz[i]),
                        *(f"{v:.6f}" for v in rpy[i]), *(f"{v:.6g}" for v in s_xyz[i]),
                        *(f"{v:.6g}" for v in s_rot[i]), *(f"{v:+.0f}" for v in directions[i]),
                        f"{temperature[i]:.4f}"])
    return len(rows)


def rotation_vector_sigma(euler_deg: np.ndarray, sigma_deg: np.ndarray, step: float = 1e-4) -> np.ndarray:
    """σ (m, 3) deg of the orientation as a rotation vector about the measuring frame's axes,
    from σ of intrinsic X-Y-Z Euler angles: δω = E δφ with E's columns the rotation vectors
    log(R(φ + h e_k) R(φ)ᵀ)/h, and Σ_ω = E diag(σ²) Eᵀ."""
    R0 = Rotation.from_euler("XYZ", euler_deg, degrees=True)
    E = np.stack([(Rotation.from_euler("XYZ", euler_deg + step * np.eye(3)[k], degrees=True) * R0.inv()).as_rotvec()
                  / np.radians(step) for k in range(3)], axis=-1)  # (m, 3, 3) rad per rad
    cov = np.einsum("mik,mk,mjk->mij", E, sigma_deg**2, E)
    return np.sqrt(np.einsum("mii->mi", cov))


if __name__ == "__main__":
    print(f"wrote {convert(sys.argv[1], sys.argv[2])} poses to {sys.argv[2]}")
