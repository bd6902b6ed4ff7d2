"""Forward kinematics of the DH family against hand-computed poses and a textbook 4×4 product."""

import numpy as np
import pytest

from robocal.io.robotfile import load_robot
from robocal.math.se3 import homogeneous, xyz_rpy_to_transform
from robocal.math.so3 import rot_x, rot_y, rot_z
from robocal.model.dh import CONVENTIONS  # the DH family (urdf: tests/unit/test_urdf.py)
from robocal.model.kinematics import chain_pose
from robocal.model.robot import Robot

# Poses worked out by hand, frame by frame, from the DH tables (see comments in each case): the
# zero pose, and single-joint motions whose effect is a plain rotation of the distal part of
# the arm about a known axis through a known point.
HAND_POSES = [
    # ER10L-C10: o1=(170,0,0), x2 up → o2=(170,0,780), o3=(170,0,920), d4 along +x → (1230,0,920),
    # d6 along +x → (1355,0,920); flange x up, z along +x.
    ("er10l-c10", [0, 0, 0, 0, 0, 0], [1355, 0, 920], [[0, 0, 1], [0, -1, 0], [1, 0, 0]]),
    ("er10l-c10", [90, 0, 0, 0, 0, 0], [0, 1355, 920], None),
    # q2 = 90°: (1185,0,920) from o1 rotated +90° about +y → (920,0,-1185), plus o1.
    ("er10l-c10", [0, 90, 0, 0, 0, 0], [1090, 0, -1185], None),
    # q5 = 90°: axis 6 turns from +x to −z about the wrist centre (1230,0,920).
    ("er10l-c10", [0, 0, 0, 0, 90, 0], [1230, 0, 795], None),
    # KR5 arc: o1=(180,0,400), o2=(180,0,1000), o3=(180,0,1120), d4=−620 along z3=−x → (800,0,1120),
    # d6=−115 along z5=−x → (915,0,1120).
    ("kr5-arc", [0, 0, 0, 0, 0, 0], [915, 0, 1120], [[0, 0, 1], [0, -1, 0], [1, 0, 0]]),
    ("kr5-arc", [90, 0, 0, 0, 0, 0], [0, 915, 1120], None),
    # q3 = 90°: (735,0,120) from o2 rotated +90° about +y → (120,0,−735), plus o2.
    ("kr5-arc", [0, 0, 90, 0, 0, 0], [300, 0, 265], None),
    # IRB 120 at its calibration position: TCP of the bare flange at (374, 0, 630) (ABB data).
    ("irb120", [0, 0, 0, 0, 0, 0], [374, 0, 630], [[0, 0, 1], [0, 1, 0], [-1, 0, 0]]),
    ("irb120", [-90, 0, 0, 0, 0, 0], [0, -374, 630], None),
    # UR10 zero pose: (−1184.3, −256.141, 11.6) (UR's published forward kinematics).
    ("ur10", [0, 0, 0, 0, 0, 0], [-1184.3, -256.141, 11.6], [[1, 0, 0], [0, 0, -1], [0, 1, 0]]),
    # q2 = −90° about z1 = −y: the vector (−1184.3, −256.141, −115.7) from the shoulder
    # (0, 0, 127.3) maps (x, y, z) → (z, y, −x): links point up, d5 now along −x.
    ("ur10", [0, -90, 0, 0, 0, 0], [-115.7, -256.141, 127.3 + 1184.3], None),
    # PUMA 560 (Corke): (452.1, −150.05, 671.8 + 431.8).
    ("puma560", [0, 0, 0, 0, 0, 0], [452.1, -150.05, 1103.6], [[1, 0, 0], [0, 1, 0], [0, 0, 1]]),
    ("puma560", [90, 0, 0, 0, 0, 0], [150.05, 452.1, 1103.6], None),
]


@pytest.mark.parametrize("name,q_deg,p,R", HAND_POSES)
def test_builtin_robots_against_hand_computed_poses(name, q_deg, p, R):
    T = load_robot(name).fk(np.radians([q_deg]))[0]
    np.testing.assert_allclose(T[:3, 3], p, atol=1e-9)
    if R is not None:
        np.testing.assert_allclose(T[:3, :3], R, atol=1e-12)


def naive_fk(convention, geom, q, base, tool):
    """Product of 4×4 elementary matrices, one pose at a time (the textbook form)."""
    T = base.copy()
    for (a, al, th, d, be), qi in zip(geom, q):
        Rz = homogeneous(rot_z(qi + th), np.zeros(3))
        Tz = homogeneous(np.eye(3), [0, 0, d])
        Tx = homogeneous(np.eye(3), [a, 0, 0])
        Rx = homogeneous(rot_x(al), np.zeros(3))
        Ry = homogeneous(rot_y(be), np.zeros(3))
        T = T @ {"dh": Rz @ Tz @ Tx @ Rx, "hayati": Rz @ Tz @ Tx @ Rx @ Ry, "craig": Rx @ Tx @ Rz @ Tz}[convention]
    return T @ tool


@pytest.mark.parametrize("convention", CONVENTIONS)
@pytest.mark.parametrize("n", [1, 3, 7])
def test_batched_fk_equals_loop_over_single_poses(convention, n, rng):
    particles, poses = 4, 9
    geom = rng.normal(size=(particles, n, 5)) * [300, 1, 1, 300, 0.2]
    q = rng.uniform(-np.pi, np.pi, size=(poses, n))
    base = xyz_rpy_to_transform(rng.normal(size=(particles, 3)) * 1000, rng.normal(size=(particles, 3)))
    tool = xyz_rpy_to_transform([10, -20, 80], [0.1, 0.2, -0.3])
    R, p = chain_pose(convention, geom, q, base, tool[None, None])
    assert R.shape == (particles, poses, 3, 3) and p.shape == (particles, poses, 3)
    for i in range(particles):
        for j in range(poses):
            T = naive_fk(convention, geom[i], q[j], base[i], tool)
            np.testing.assert_allclose(p[i, j], T[:3, 3], atol=1e-9)
            np.testing.assert_allclose(R[i, j], T[:3, :3], atol=1e-12)


def _dh_to_craig(robot: Robot) -> Robot:
    """The same physical arm in Craig's modified DH: row i holds (a_{i-1}, α_{i-1}, θ_i, d_i)
    and the last link's Tx(a_n) Rx(α_n) moves into the tool."""
    g = robot.geometry
    craig = np.zeros_like(g)
    craig[:, 2:4] = g[:, 2:4]
    craig[1:, 0:2] = g[:-1, 0:2]
    tail = homogeneous(np.eye(3), [g[-1, 0], 0, 0]) @ homogeneous(rot_x(g[-1, 1]), np.zeros(3))
    return Robot("craig", craig, robot.limits, base=robot.base, tool=tail @ robot.tool)


@pytest.mark.parametrize("name", ["kr5-arc", "irb120", "ur10", "puma560"])
def test_dh_and_craig_forms_of_one_robot_agree(name, rng):
    dh = load_robot(name).replace(tool=xyz_rpy_to_transform([5, 10, 150], [0.2, 0.1, 0.3]))
    q = rng.uniform(-np.pi, np.pi, size=(50, 6))
    np.testing.assert_allclose(_dh_to_craig(dh).fk(q), dh.fk(q), atol=1e-9)


def test_hayati_with_zero_beta_equals_dh(rng):
    hay = load_robot("er10l-c10")
    q = rng.uniform(-np.pi, np.pi, size=(50, 6))
    np.testing.assert_allclose(hay.fk(q), hay.replace(convention="dh").fk(q), atol=1e-9)
    g = hay.geometry.copy()
    g[1, 4] = 0.01  # and a nonzero β is Ry(β) appended to the DH link transform
    assert np.abs(hay.replace(geometry=g).fk(q) - hay.fk(q)).max() > 1.0


@pytest.mark.parametrize("convention", CONVENTIONS)
def test_a_swarm_s_chain_keeps_no_numbers_of_the_call_before_in_any_thread(convention):
    """The chain keeps its factor arrays for the next call of a swarm's shape (the allocator would
    take their pages from the system afresh): calls of one shape with other numbers, one after the
    other and from several threads at once, each give what a textbook product of 4×4s gives."""
    from concurrent.futures import ThreadPoolExecutor

    from robocal.model.dh import apply_chain

    rng = np.random.default_rng(7)
    robot = load_robot("kr5-arc")
    cases = []
    for _ in range(8):
        geom = np.broadcast_to(robot.geometry, (20,) + robot.geometry.shape).copy()
        geom[..., :5] += rng.normal(0, 0.01, geom[..., :5].shape)
        cases.append((geom, rng.uniform(-2, 2, (32, 6))))

    def textbook(geom, q):  # the flange origin, Π Rz(q+θ) Tz(d) Tx(a) Rx(α) Ry(β) or Craig's Rx(α) Tx(a) Rz(θ) Tz(d)
        out = np.empty((len(geom), len(q), 3))
        for p, g in enumerate(geom):
            for m, qm in enumerate(q):
                T = np.eye(4)
                for (a, alpha, theta, d, beta), qi in zip(g[:, :5], qm):
                    z = homogeneous(rot_z(qi + theta), [0, 0, d])
                    if convention == "craig":
                        T = T @ homogeneous(rot_x(alpha), [a, 0, 0]) @ z
                    else:
                        T = T @ z @ homogeneous(rot_x(alpha) @ (rot_y(beta) if convention == "hayati" else np.eye(3)),
                                                [a, 0, 0])
                out[p, m] = T[:3, 3]
        return out

    def ours(case):
        geom, q = case
        V = np.zeros((32, 3, 1))
        return apply_chain(convention, geom, q, np.broadcast_to(V, (20, 32, 3, 1)))[..., 0]

    with ThreadPoolExecutor(4) as pool:
        at_once = list(pool.map(ours, cases * 3))
    for k, case in enumerate(cases * 3):
        if k < len(cases):  # three particles of each against the textbook
            np.testing.assert_allclose(at_once[k][:3], textbook(case[0][:3], case[1]), rtol=0, atol=1e-8)
        np.testing.assert_array_equal(ours(case), at_once[k])


@pytest.mark.parametrize("convention", CONVENTIONS)
def test_a_large_chain_call_gives_each_pose_what_small_calls_give(convention):
    """A call too large for the kept factor arrays broadcasts each joint's constant factors rather
    than laying them out at every pose: the same numbers to the bit as calls of a few hundred poses
    (laid out), particles and a hayati β included."""
    from robocal.model.dh import SCRATCH_BYTES, apply_chain

    rng = np.random.default_rng(4)
    for particles in ((), (3,)):
        nominal = load_robot("er10l-c10").geometry
        geom = np.broadcast_to(nominal, particles + nominal.shape).copy()
        geom[..., :5] += rng.normal(0, 0.01, geom[..., :5].shape)
        m = SCRATCH_BYTES // (8 * 6 * 4) + 500  # past the kept arrays' size
        q = rng.uniform(-3, 3, particles + (m, 6))
        V = np.broadcast_to(rng.normal(size=(3, 4)), particles + (m, 3, 4)).copy()
        whole = apply_chain(convention, geom, q, V)
        parts = [apply_chain(convention, geom, q[..., k:k + 400, :], V[..., k:k + 400, :, :])
                 for k in range(0, m, 400)]
        np.testing.assert_array_equal(whole, np.concatenate(parts, axis=-3))
