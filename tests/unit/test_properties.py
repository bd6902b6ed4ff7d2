"""Property-based tests: any text given to the loaders yields a valid object or robocal's own InputError."""

import string

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from robocal.exceptions import InputError
from robocal.io.goals import parse_goals
from robocal.io.measurements import parse_measurements
from robocal.io.robotfile import load_robot as _load
from robocal.io.robotfile import parse_robot, robot_to_toml
from robocal.model.measurements import Measurements

GOOD_ROBOT = robot_to_toml(_load("kr5-arc"))
GOOD_CSV = (
    "pose_id,target,q1,q2,q3,q4,q5,q6,x,y,z,rx,ry,rz\n"
    "P1,A,10,-20,30,40,50,60,800,100,900,10,20,30\n"
    "P1,A,10,-20,30,40,50,60,800.01,100,900,10,20,30\n"
    "P2,B,-15,-40,60,-30,20,10,700,-150,1000,-5,0,90\n"
)
ALPHABET = string.ascii_letters + string.digits + " ,.;:=-+_[]{}\"'#\n\t" + "é∞"


def _mutate(base: str, edits) -> str:
    text = base
    for pos, length, insert in edits:
        pos %= len(text) + 1
        text = text[:pos] + insert + text[pos + length :]
    return text


edits = st.lists(st.tuples(st.integers(0, 10_000), st.integers(0, 12), st.text(ALPHABET, max_size=8)), max_size=6)
SETTINGS = settings(deadline=None, suppress_health_check=[HealthCheck.too_slow])  # examples: see conftest


@SETTINGS
@given(st.text(ALPHABET, max_size=400))
def test_robot_loader_on_arbitrary_text(text):
    try:
        robot = parse_robot(text, source="fuzz.toml")
    except InputError:
        return
    assert np.all(np.isfinite(robot.geometry))


@SETTINGS
@given(edits)
def test_robot_loader_on_mutated_files(e):
    try:
        robot = parse_robot(_mutate(GOOD_ROBOT, e), source="fuzz.toml")
    except InputError:
        return
    assert robot.n_joints >= 1 and np.all(np.isfinite(robot.geometry))
    assert np.all(robot.limits[:, 0] < robot.limits[:, 1])


@SETTINGS
@given(st.text(ALPHABET, max_size=400))
def test_measurement_loader_on_arbitrary_text(text):
    try:
        m = parse_measurements(text, source="fuzz.csv")
    except InputError:
        return
    assert isinstance(m, Measurements) and np.all(np.isfinite(m.q)) and np.all(np.isfinite(m.position))


@SETTINGS
@given(edits, st.sampled_from([None, 6, 5]))
def test_measurement_loader_on_mutated_files(e, n_joints):
    try:
        m = parse_measurements(_mutate(GOOD_CSV, e), source="fuzz.csv", n_joints=n_joints)
    except InputError:
        return
    assert m.n_poses >= 1 and np.all(np.isfinite(m.position))
    if m.rotation is not None:
        eye = np.broadcast_to(np.eye(3), m.rotation.shape)
        np.testing.assert_allclose(m.rotation @ np.swapaxes(m.rotation, -1, -2), eye, atol=1e-9)


@SETTINGS
@given(edits)
def test_goals_loader_on_mutated_files(e):
    try:
        t = parse_goals(_mutate(GOOD_CSV.replace("pose_id,target,", "pose_id,"), e), source="fuzz.csv")
    except InputError:
        return
    assert t.n >= 1
