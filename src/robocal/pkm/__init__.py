"""The 4-DOF 2TPR&2TPS parallel mechanism of Chen et al. (paper 003).

- :mod:`.geometry` — joint points, rod zero lengths, platform poses.
- :mod:`.kinematics` — inverse kinematics, its Jacobian, forward kinematics (Newton), workspace.
- :mod:`.sensitivity` — pose errors of the 28-parameter error model; the paper's Fig. 4–9 study.
- :mod:`.identify` — the identifiable subset of the 28 parameters from measured positions.
- :mod:`.compensation` — the paper's eq. 18 correction, its iteration, model-based compensation.
- :mod:`.files` — mechanism TOML and CSV files.
"""
