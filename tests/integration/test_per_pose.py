"""Per-pose output and leaving poses out: the rows add up to the summary metrics, outliers and
poses outside the calibrated region are flagged, an excluded pose is recorded or refused."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest


def _rows(path):
    with open(path) as fh:
        return list(csv.DictReader(fh))


def test_calibrate_and_evaluate_write_every_pose(tmp_path, run_cli):
    data, val = tmp_path / "d.csv", tmp_path / "v.csv"
    assert run_cli("simulate", "kr5-arc", "--poses", "50", "--errors", "uniform:0.3,0.003", "--noise", "0.02",
                   "--angle-noise", "0.001", "--out", data, "--seed", "3", "--range", "-40,40")[0] == 0
    assert run_cli("simulate", "kr5-arc", "--poses", "30", "--errors", "uniform:0.3,0.003", "--noise", "0.02",
                   "--angle-noise", "0.001", "--out", val, "--seed", "4")[0] == 0
    text = data.read_text().splitlines()
    text = [text[0] + ",pose_id"] + [f"{line},P{i}" for i, line in enumerate(text[1:])]
    data.write_text("\n".join(text) + "\n")
    code, _, err = run_cli("calibrate", "kr5-arc", data, "--validate", val, "--frames", "none", "--exclude", "P3,P7",
                           "--poses-out", tmp_path / "p.csv", "--out", tmp_path / "r.json")
    assert code == 0, err
    result = json.loads((tmp_path / "r.json").read_text())
    assert result["excluded"] == ["P3", "P7"] and "2 pose(s) left out as asked" in err
    rows = _rows(tmp_path / "p.csv")
    cal = [r for r in rows if r["set"] == "calibration"]
    assert len(cal) == 48 and {"P3", "P7"}.isdisjoint(r["pose_id"] for r in cal)
    rms = np.sqrt(np.mean([float(r["error_mm"]) ** 2 for r in cal]))
    assert rms == pytest.approx(result["metrics"]["after"]["position"]["rms"], rel=1e-9)
    v = [r for r in rows if r["set"] == "validation"]
    assert np.sqrt(np.mean([float(r["error_mm"]) ** 2 for r in v])) == pytest.approx(
        result["metrics"]["validation_after"]["position"]["rms"], rel=1e-9)
    # the validation poses reach beyond the calibrated joint ranges: flagged with how far, and the
    # model's predicted uncertainty there is larger than at its calibration poses
    assert any(float(r["outside_region_deg"]) > 0 for r in v)
    far = [float(r["sigma_mm"]) for r in v if float(r["outside_region_deg"]) > 20]
    assert far and np.median(far) > 2 * np.median([float(r["sigma_mm"]) for r in cal])
    assert "poses have a predicted position uncertainty above 3× its median" in err
    code, _, err = run_cli("calibrate", "kr5-arc", data, "--exclude", "P99")
    assert code == 2 and "excluded pose 'P99' is not in the data" in err


def test_contact_rows_carry_their_point_and_setup_and_every_row_an_id(tmp_path, run_cli):
    """The tracker-free Panda data: each row names the socket it touched and the placement; a
    file without pose ids gets the row's own name, as the messages say it."""
    from pathlib import Path

    folder = Path(__file__).resolve().parents[2] / "examples" / "mukca-panda2"
    code, _, err = run_cli("calibrate", folder / "panda.urdf", folder / "panda_2.csv", "--tip-link", "ball_link",
                           "--joint-unit", "rad", "--point-distance", "hole_0,hole_1=50", "--quiet",
                           "--poses-out", tmp_path / "p.csv")
    assert code == 0, err
    rows = _rows(tmp_path / "p.csv")
    with open(folder / "panda_2.csv") as fh:
        source = list(csv.DictReader(fh))
    assert len(rows) == len(source)
    for r in rows:
        original = source[int(r["row"]) - 2]  # the file's row: its header is row 1
        assert r["contact"] == f"point {original['point']}" and r["setup"] == original["setup"]
        assert r["pose_id"] == f"row {r['row']}"
