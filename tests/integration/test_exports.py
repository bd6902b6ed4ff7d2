"""Reading a tracker's own export: ';' cells, decimal commas, radians, intrinsic Euler angles with their
σ, and columns robocal does not use, mapped by name (written here from robocal's UR10 file)."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from robocal.io.measurements import load_measurements

DATA = Path(__file__).parents[2] / "examples" / "ur10-ipa" / "series_c.csv"
MAP = {"shoulder_pan_joint": "q1", "shoulder_lift_joint": "q2", "elbow_joint": "q3", "wrist_1_joint": "q4",
       "wrist_2_joint": "q5", "wrist_3_joint": "q6", "measurement_x": "x", "measurement_y": "y", "measurement_z": "z",
       "measurement_rx": "rx", "measurement_ry": "ry", "measurement_rz": "rz", "measurement_std_x": "sx",
       "measurement_std_y": "sy", "measurement_std_z": "sz"}


def _export(tmp_path, n=60):
    """The first n poses as the tracker software writes them."""
    ref = load_measurements(DATA, n_joints=6).subset(np.arange(n))
    euler = Rotation.from_matrix(ref.rotation).as_euler("XYZ", degrees=True)
    head = ["Timestamp", *MAP]
    rows = []
    for i in range(n):
        values = [*ref.q[i], *ref.position[i], *euler[i], *ref.sigma_position[i]]
        rows.append(["2,02011E+13", *(repr(float(v)).replace(".", ",") for v in values)])
    path = tmp_path / "export.csv"
    path.write_text(";".join(head) + "\n" + "\n".join(";".join(r) for r in rows) + "\n")
    return path, ref


def test_a_tracker_export_loads_as_it_is_with_a_column_map(tmp_path):
    path, ref = _export(tmp_path)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        meas = load_measurements(path, n_joints=6, columns=MAP, delimiter=";", decimal=",", joint_unit="rad",
                                 euler="XYZ")
    assert meas.q == pytest.approx(ref.q, abs=1e-9)
    assert meas.position == pytest.approx(ref.position, abs=1e-9)
    assert meas.rotation == pytest.approx(ref.rotation, abs=1e-9)
    assert meas.sigma_position == pytest.approx(ref.sigma_position)
    assert any("1 column(s) not used by robocal were ignored: Timestamp" in str(w.message) for w in caught)


def test_euler_sigmas_become_the_rotation_vectors(tmp_path):
    # a σ on one Euler angle only: the rotation vector's σ is that angle's axis, as the rotation turns it
    path = tmp_path / "e.csv"
    path.write_text("q1,q2,x,y,z,rx,ry,rz,srx,sry,srz\n" + "".join(
        f"{10 * i},{5 * i},{i},0,0,0,90,0,0.01,0.0001,0.0001\n" for i in range(1, 40)))
    meas = load_measurements(path, n_joints=2, euler="XYZ")
    # intrinsic X, Y' = 90°, Z'': the first angle turns about x, the second about y, the third (after
    # the 90° about y) about x again: σ_x² = σ_1² + σ_3², σ_y = σ_2, σ_z = 0
    expected = np.radians([np.hypot(0.01, 0.0001), 0.0001, 0.0])
    assert meas.sigma_orientation[0] == pytest.approx(expected, rel=1e-3, abs=1e-12)


def test_the_command_line_reads_an_export_and_says_how_to(tmp_path, run_cli):
    path, _ = _export(tmp_path)
    code, _, err = run_cli("evaluate", "ur10", path)
    assert code == 2 and "--delimiter ';'" in err
    mapping = ",".join(f"{k}={v}" for k, v in MAP.items())
    code, out, err = run_cli("evaluate", "ur10", path, "--delimiter", ";", "--decimal", ",", "--joint-unit", "rad",
                             "--euler", "XYZ", "--column", mapping, "--frames", "base+tool", "--json")
    assert code == 0, err
    code, _, err = run_cli("evaluate", "ur10", path, "--euler", "XXY")
    assert code == 2 and "--euler" in err
