"""The calibration methods, one entry each: everything that differs from one method to another.

A method is an optional swarm (a function of :mod:`robocal.optimize.swarm`) and whether
Levenberg–Marquardt gives (``lm``) or finishes (``hybrid``) the estimate.  Adding one is one
entry in :data:`METHODS`: its swarm, default objective, paper settings, which of them a user
may override, its search box, and whether it is a least-squares estimate (robust losses,
joint terms, noise refits, F-tests and standard uncertainties need one).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field

from ..optimize.swarm import ipso, ldpso_bt, pso
from ..presets import kou2022, wen2019

#: generations of the swarm stage of ``hybrid`` (IPSO, paper's 20 particles): enough to land
#: in LM's basin, a fraction of the paper's 2000
HYBRID_GENERATIONS = 300


@dataclass(frozen=True)
class Method:
    """One calibration method.

    swarm: the swarm optimizer it runs (called with the settings, the search box, a seed, a
    progress callback, the backend and a start for particle 0), or None for LM alone.
    objective: its default objective, ``sum_squares`` or ``sum_norms`` (its paper's).
    settings: the paper's swarm settings; overridable: those a user may change besides
    ``particles`` and ``iterations``.  box: default search half-widths (mm, rad) around the
    initial estimate.  least_squares: LM gives or finishes the estimate.  halton: the swarm
    takes IPSO's Halton start (``halton`` option).
    """

    name: str
    swarm: Callable | None
    objective: str
    least_squares: bool
    settings: Mapping[str, float] = field(default_factory=dict)
    overridable: tuple[str, ...] = ()
    box: tuple[float, float] | None = None
    halton: bool = False

    @property
    def swarm_only(self) -> bool:
        """A swarm's answer, kept as it is (no LM after it)."""
        return self.swarm is not None and not self.least_squares


METHODS: dict[str, Method] = {m.name: m for m in (
    Method("lm", None, "sum_squares", least_squares=True),
    Method("pso", pso, "sum_norms", least_squares=False, settings=kou2022.PSO, overridable=("w", "c1", "c2"),
           box=kou2022.BOX),
    Method("ipso", ipso, "sum_squares", least_squares=False, settings=wen2019.IPSO, overridable=("c1", "c2"),
           box=wen2019.BOX, halton=True),
    Method("ldpso-bt", ldpso_bt, "sum_norms", least_squares=False, settings=kou2022.LDPSO_BT,
           overridable=("min_particles", "w1", "w2", "switch", "c1", "c2"), box=kou2022.BOX),
    Method("hybrid", ipso, "sum_squares", least_squares=True,
           settings={**wen2019.IPSO, "iterations": HYBRID_GENERATIONS}, overridable=("c1", "c2"), box=wen2019.BOX,
           halton=True),
)}
