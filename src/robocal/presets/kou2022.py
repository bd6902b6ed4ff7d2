"""Kou Bin, Guo Shijie, Ren Dongcheng (2022): PSO against LDPSO-BT on the KUKA KR5 arc (paper 001).

The paper's constants, in one place: the settings of both swarms, the error range,
and the published figures.  The reproduction is in
:mod:`robocal.papers.kou2022.reproduce`.
"""

#: Table 3: standard PSO, 240 particles, w 0.8, c1 = c2 = 1.49, 500 iterations
PSO = {"particles": 240, "iterations": 500, "w": 0.8, "c1": 1.49, "c2": 1.49}
#: §3: LDPSO-BT, population 240 → 40 linearly, w1 0.8 until 0.8·T, then w2 0.4 (social only)
LDPSO_BT = {"particles": 240, "min_particles": 40, "iterations": 500, "w1": 0.8, "w2": 0.4, "switch": 0.8,
            "c1": 1.49, "c2": 1.49}
#: errors uniform in ±0.25 mm (lengths) and ±0.05 rad (angles): also the swarm search box
BOX = (0.25, 0.05)
DEVIATIONS = "uniform:0.25,0.05"
#: the experiment: 30 joint sets, position only, objective Σ|δp| (eq. 4)
POSES = 30
KINDS = ("a", "d", "alpha", "theta")


def parameters(n_joints: int = 6) -> tuple[str, ...]:
    """Δa, Δd, Δα, Δθ of every joint: the 24 errors the paper identifies for 6 joints."""
    return tuple(f"{k}{i + 1}" for i in range(n_joints) for k in KINDS)


PUBLISHED = {
    "before": (47.1, 51.8, 52.8),  # max |error| X/Y/Z, mm
    "pso": (0.14, 0.13, 0.10),
    "ldpso-bt": (0.18, 0.18, 0.15),
    "time_reduction_pct": 41.85,
}
