"""The constants of the three source papers: their tables, settings and published figures.

A bottom-layer package (it imports nothing of robocal): the optimizers' defaults, the
calibration methods, simulation and the parallel mechanism take their paper settings from
here, and the reproductions in :mod:`robocal.papers` compare against the published figures.
``wen2019`` (IPSO, ER10L-C10), ``kou2022`` (LDPSO-BT, KR5 arc), ``chen2023`` (2TPR&2TPS).
"""
