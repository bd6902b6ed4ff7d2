"""Monte-Carlo method studies: many seeded runs over methods, noise levels and pose counts,
on local worker processes or a Dask cluster (:mod:`robocal.study.engine`).

- :mod:`.spec` — the study file and its runs;
- :mod:`.runs` — one run, and runs.csv;
- :mod:`.engine` — mapping runs over Dask;
- :mod:`.summary` — medians, confidence intervals, paired comparisons;
- :mod:`.driver` — :func:`run_study`, what ``robocal study`` calls.
"""
