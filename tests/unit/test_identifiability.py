"""The identifiability analysis: observability figures and structured reasons."""

import numpy as np
import pytest

from robocal.calibration.judge.identifiability import DEPENDENT, NO_EFFECT, Reason, analyse, observability


def test_observability_figures_match_direct_svd(rng):
    J = rng.normal(size=(60, 5))
    s = np.linalg.svd(J, compute_uv=False)
    o = observability(J, 20)
    assert o["O1"] == pytest.approx(np.prod(s) ** (1 / 5) / np.sqrt(20))
    assert o["O2"] == pytest.approx(s[-1] / s[0])
    assert o["O3"] == pytest.approx(s[-1])
    assert o["O4"] == pytest.approx(s[-1] ** 2 / s[0])


def test_zero_and_dependent_columns_get_structured_reasons(rng):
    J = rng.normal(size=(30, 4))
    J = np.column_stack([J, np.zeros(30), J[:, 0] - 2 * J[:, 1]])
    names = ["a1", "d1", "a2", "d2", "d3", "a3"]
    ident = analyse(J, names, np.zeros(6, bool), 10, 1000.0)
    assert ident.reasons["d3"] == Reason(NO_EFFECT)
    # a3 = a1 − 2 d1; the scan offers joints from the flange back, so a3 stays and a1 or d1 goes
    dep = [n for n, r in ident.reasons.items() if r.kind == DEPENDENT]
    assert len(dep) == 1 and set(ident.reasons[dep[0]].related) <= {"a1", "d1", "a3"}
    assert len(ident.kept) == 4 and len(ident.dropped) == 2
    assert "zero" in ident.reasons["d3"].text() and "dependent on" in ident.reasons[dep[0]].text()


def test_prefer_changes_which_of_two_equal_columns_stays(rng):
    J = rng.normal(size=(20, 3))
    J = np.column_stack([J, J[:, 0]])
    names = ["d2", "a1", "a2", "d3"]
    assert "d2" in analyse(J, names, np.zeros(4, bool), 5, 1.0).dropped
    assert "d3" in analyse(J, names, np.zeros(4, bool), 5, 1.0, prefer=["d2"]).dropped


def test_regrouped_parameters_carry_what_they_absorb(rng):
    """d2 and d3 of parallel axes have one column: d3 keeps it and estimates d3 + d2."""
    J = rng.normal(size=(40, 3)) * [1.0, 2.0, 0.5]
    J = np.column_stack([J[:, 0], 3.0 * J[:, 1], J[:, 1], J[:, 2]])  # d2 moves the data 3× as d3 does
    ident = analyse(J, ["a1", "d2", "d3", "a3"], np.zeros(4, bool), 10, 1.0)
    assert ident.dropped == ["d2"] and ident.reasons["d2"].related == ("d3",)
    assert ident.absorbed_by("d3") == [("d2", pytest.approx(3.0))]
    assert ident.absorbed_by("a1") == []
