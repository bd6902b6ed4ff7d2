"""Chen Mingfang et al. (2023): the 2TPR&2TPS parallel mechanism (paper 003).

The paper's constants, in one place: the joint points of Table 2, the compensation PSO
settings, and the published figures.  The reproduction is in
:mod:`robocal.papers.chen2023.reproduce`.

Table 1 gives d = 292.4 mm where Table 2 has T1, T2 at x = 294.2 mm; the other entries of
both tables agree, so 294.2 (Table 2, the points actually used) is taken and 292.4 read
as a transposition of digits.
"""

#: Table 2 (mm): fixed-platform points T1..T4 and moving-platform points B1 = S1, B2 = S2, B3 = R2, B4 = R1
FIXED_POINTS = ((294.2, -192.35, 0.0), (294.2, 192.35, 0.0), (0.0, 139.25, 0.0), (0.0, -139.25, 0.0))
MOVING_POINTS = ((140.0, -40.0, 0.0), (140.0, 40.0, 0.0), (0.0, 100.0, 0.0), (0.0, -100.0, 0.0))
ROD_LIMITS = (300.0, 520.0)  # mm
HOOKE_LIMIT_DEG = 60.0

#: §4.2: the compensation PSO, N 100, c1 = c2 = 1.5, w 0.8, 200 iterations
PSO = {"particles": 100, "iterations": 200, "w": 0.8, "c1": 1.5, "c2": 1.5}
#: search box of ΔL (mm) for that PSO: the paper gives none; rod corrections of a few tenths
#: of a millimetre come from errors of that size, so ±5 mm leaves a wide margin
PSO_BOX = 5.0

PUBLISHED = {"simulation_pct": 98.148, "real_pct": 87.457}
