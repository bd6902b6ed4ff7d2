"""Wen Xiulan et al. (2019): IPSO calibration of the Efort ER10L-C10 (paper 000).

The paper's constants, in one place: the errors of Table 2, the 24 identified errors,
the IPSO settings and search box, and the published figures.  The reproduction is in
:mod:`robocal.papers.wen2019.reproduce`.
"""

#: Table 2: true geometric errors of the ER10L-C10 (mm, rad)
TABLE2_DEVIATIONS: dict[str, float] = {
    "a1": -0.4751, "alpha1": 0.0058, "theta1": 0.0091, "d1": -0.4221,
    "a2": 0.2565, "alpha2": 0.0092, "theta2": -0.0003, "d2": 0.0, "beta2": -0.0028,
    "a3": -0.3366, "alpha3": 0.0031, "theta3": 0.0060, "d3": 0.3409,
    "a4": -0.1827, "alpha4": -0.0093, "theta4": -0.0072, "d4": 0.1420,
    "a5": -0.1117, "alpha5": 0.0070, "theta5": -0.0016, "d5": 0.1753,
    "a6": -0.2536, "alpha6": 0.0087, "theta6": 0.0083, "d6": 0.1531,
}

#: §1.2: the 24 errors identified for the ER10L-C10 (axes 2 ∥ 3): d2 and β1, β3..6 left out
PARAMETERS: tuple[str, ...] = (
    tuple(f"a{i}" for i in range(1, 7))
    + ("d1",) + tuple(f"d{i}" for i in range(3, 7))
    + tuple(f"alpha{i}" for i in range(1, 7))
    + ("beta2",)
    + tuple(f"theta{i}" for i in range(1, 7))
)

#: §3.1.2: IPSO with 20 particles, c1 = c2 = 2.05 (constriction K = 0.7298), 2000 generations
IPSO = {"particles": 20, "iterations": 2000, "c1": 2.05, "c2": 2.05}
#: §3.1.2: initial positions within ±0.5 mm (lengths) and ±0.01 rad (angles)
BOX = (0.5, 0.01)
#: the experiment: 32 joint sets uniform in [−π, π], full pose, U(±0.1 rad) "joint noise"
POSES = 32
JOINT_NOISE_UNIFORM = 0.1

#: published figures (Table 3 and the text)
PUBLISHED = {
    "time_s": 220.0,  # 2000 generations, MATLAB on an i5-4570
    "real_before": {"mean": 9.6794, "std": 5.2230, "max": 12.0781},
    "real_after": {"mean": 1.7785, "std": 0.4820, "max": 4.6433},
    "real_orientation_before": {"x": (0.5543, 0.0932, 0.7376), "y": (0.2381, 0.0960, 0.3904),
                                "z": (1.5737, 0.0579, 1.6989)},
    "real_orientation_after": {"x": (0.3885, 0.0974, 0.5810), "y": (0.2148, 0.0951, 0.4103),
                               "z": (0.0578, 0.0471, 0.1785)},
}
