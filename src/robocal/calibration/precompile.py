"""Compile every numba kernel into numba's cache, with the types robocal's runs call them with.

``python -m robocal.calibration.precompile`` is what :func:`robocal.model.compiled.resolve` starts in the
background the first time a process finds the cache cold: that process runs the numpy path
(the same numbers), and the processes after it load the compiled kernels in milliseconds.
The kernels are compiled by running robocal's own calls on a dozen simulated poses (full pose
and position only, with and without frames, a swarm and Levenberg–Marquardt), so their
signatures are the ones real runs use; each parallel twin is compiled for its serial kernel's
signatures.
"""

from __future__ import annotations

import warnings

import numpy as np


def compile_kernels() -> None:
    """Compile (or load) every kernel, serial and parallel, on the calls robocal makes."""
    from ..io.robotfile import load_robot
    from ..model import kernels
    from ..optimize import kernels as swarm_kernels
    from ..simulation import simulate
    from . import calibrate
    from .select.boosting import compile_boosting

    robot = load_robot("er10l-c10")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for measure in ("pose", "position"):
            sim = simulate(robot, 12, deviations="paper", seed=0, measure=measure)
            for frames in ("none", "base+tool"):
                calibrate(robot, sim.measurements, "ipso", frames=frames, iterations=2, particles=4, backend="numba")
            calibrate(robot, sim.measurements, "lm", frames="none", backend="numba")
    swarm_kernels.warm_up()
    # a tree correction's walk, on arrays typed as an ensemble holds them (int64 nodes, float64 joints)
    two = np.array([1, -1, -1, 0, -1, -1], dtype=np.int64)
    kernels.tree_walk(two, np.zeros(6), np.array([1, -1, -1, 4, -1, -1], dtype=np.int64),
                      np.array([2, -1, -1, 5, -1, -1], dtype=np.int64), np.array([0, 3], dtype=np.int64),
                      np.arange(6.0), np.zeros((2, 2)))
    compile_boosting()
    for serial, parallel in kernels.TWINS:
        for signature in serial.signatures:
            parallel.compile(signature)


def main(folder: str | None = None) -> None:
    """Compile, and record the outcome in the compile's state folder (``folder``; see
    :func:`robocal.model.compiled.state_folder`): success, or the failure with its one-line reason,
    which later processes say once instead of starting the compile again; then drop the lock."""
    import os

    from ..model.compiled import COMPILED, FAILED, LOCK, fingerprint, record

    try:
        compile_kernels()
    except BaseException as exc:  # an unwritable numba cache, a numba that cannot compile: said once, later
        if folder is not None:
            record(folder, FAILED, f"{fingerprint()}\n{type(exc).__name__}: {' '.join(str(exc).split())[:300]}")
        raise
    else:
        if folder is not None:
            record(folder, COMPILED, fingerprint())
    finally:
        if folder is not None:
            try:
                os.unlink(os.path.join(folder, LOCK))
            except OSError:
                pass


if __name__ == "__main__":
    import sys

    main(sys.argv[1] if len(sys.argv) > 1 else None)
