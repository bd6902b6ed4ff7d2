"""Optimizers: Levenberg–Marquardt and the particle-swarm family of the papers.

- :mod:`.result` — :class:`OptimizeResult`, modelled on scipy's: ``x`` and ``fun`` agree,
  ``success`` is False whenever a cap stopped the run, ``method`` names what ran.
- :mod:`.lm` — Levenberg–Marquardt (MINPACK through scipy, TRF for robust losses, normal
  equations for very tall problems).
- :mod:`.swarm` — one swarm engine (single or batched swarms, numpy or numba) and the
  methods built on it: PSO, IPSO (Wen 2019), LDPSO-BT (Kou 2022), batched PSO (Chen).
"""
