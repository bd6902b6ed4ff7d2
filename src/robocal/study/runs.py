"""One run of a study, and runs.csv.

A run is one seed of one cell: the robot with deviations planted by that seed is measured at
``poses`` + ``validate`` joint sets (noise drawn with the same seed), calibrated on the first
``poses`` and validated on the rest.  Everything it draws comes from its seed, so its numbers
are the same wherever it runs; they are written with 10 significant digits, so that the last
bits of a machine's arithmetic do not show.
"""

from __future__ import annotations

import csv
import functools
import io
import math
import time
import warnings
from pathlib import Path

import numpy as np

from ..exceptions import InputError
from .spec import RunKey, Study, number_key

COLUMNS = ("method", "poses", "noise", "seed", "status", "before_rms", "after_rms", "validation_rms", "iterations",
           "evaluations", "time_s", "spec")
#: columns that depend on where and when a run ran
TIME_COLUMNS = ("time_s",)
#: statuses of a run that ended by its own criterion
SUCCESS = ("converged", "completed")


@functools.lru_cache(maxsize=8)
def cached_robot(spec: str):
    """A robot argument, loaded once per process (a worker runs many runs of one robot)."""
    from ..io.robotfile import load_robot

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return load_robot(spec)


def run(study: Study, key: RunKey) -> dict:
    """Simulate, calibrate and validate one run; a row of runs.csv (a failed run has status
    ``error: …`` and empty figures, and does not stop the study)."""
    from ..calibration import calibrate
    from ..simulation import simulate

    robot = cached_robot(study.robot)
    spec = study.fingerprint()
    start = time.perf_counter()
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            sim = simulate(robot, key.poses + study.validate, deviations=study.errors, noise=key.noise,
                           angle_noise=math.radians(study.angle_noise), joint_noise=math.radians(study.joint_noise),
                           measure=study.measure, seed=key.seed)
            meas = sim.measurements
            cal, val = meas.subset(np.arange(key.poses)), meas.subset(np.arange(key.poses, meas.n_poses))
            res = calibrate(robot, cal, key.method, frames=study.frames, seed=key.seed, validate=val,
                            **study.calibration)
    except (ArithmeticError, ValueError, np.linalg.LinAlgError) as exc:  # a run's failure is a result
        return row(key, spec, f"error: {exc.__class__.__name__}", time_s=time.perf_counter() - start)
    m = res.metrics
    return row(key, spec, res.optimization.status, m["before"].position["rms"], m["after"].position["rms"],
               m["validation_after"].position["rms"], res.optimization.nit, res.optimization.nfev, res.time_s)


def row(key: RunKey, spec: str, status: str, before=math.nan, after=math.nan, validation=math.nan, iterations=0,
        evaluations=0, time_s=math.nan) -> dict:
    return {"method": key.method, "poses": str(key.poses), "noise": number_key(key.noise), "seed": str(key.seed),
            "status": status, "before_rms": number_key(before), "after_rms": number_key(after),
            "validation_rms": number_key(validation), "iterations": str(iterations), "evaluations": str(evaluations),
            "time_s": format(time_s, ".4g"), "spec": spec}


def key_of(r: dict) -> tuple[str, str, str, str]:
    """The identity of a row: method, poses, noise and seed as written."""
    return r["method"], r["poses"], r["noise"], r["seed"]


def key_text(key: RunKey) -> tuple[str, str, str, str]:
    return key.method, str(key.poses), number_key(key.noise), str(key.seed)


def read_runs(path: Path) -> list[dict]:
    """The complete rows of an existing runs.csv (a row cut short by a crash is left out)."""
    if not path.is_file():
        return []
    text = path.read_text(encoding="utf-8")
    reader = csv.DictReader(io.StringIO(text))
    rows = list(reader)
    header = list(reader.fieldnames or [])
    if header and header == list(COLUMNS[:-1]):
        raise InputError("was written by an earlier robocal that did not record the study it belongs to: resume "
                         "into a new --out folder", source=path)
    if header and header != list(COLUMNS):
        raise InputError(f"not a runs.csv of robocal study (columns {', '.join(header)})", source=path)
    return [r for r in rows if all(r.get(c) not in (None, "") for c in COLUMNS)]


def csv_text(rows: list[dict], header: bool = True) -> str:
    out = io.StringIO()
    w = csv.DictWriter(out, COLUMNS, lineterminator="\n")
    if header:
        w.writeheader()
    w.writerows(rows)
    return out.getvalue()


class RunsFile:
    """runs.csv while a study runs: each finished run is appended and flushed, so that an
    interrupted study resumes where it stopped; :meth:`finish` rewrites it in run order.  The
    file (and its folder) is only touched once the first run is done: a start that fails
    leaves nothing behind."""

    def __init__(self, path: Path, rows: list[dict]):
        self.path = path
        self.rows = list(rows)
        self._fh = None

    def _open(self):
        from ..io.atomic import atomic_write

        self.path.parent.mkdir(parents=True, exist_ok=True)
        atomic_write(self.path, csv_text(self.rows))  # drops a row a crash cut short
        return self.path.open("a", encoding="utf-8", newline="")

    def add(self, r: dict) -> None:
        if self._fh is None:
            self._fh = self._open()
        self.rows.append(r)
        self._fh.write(csv_text([r], header=False))
        self._fh.flush()

    def finish(self, order: list[RunKey]) -> list[dict]:
        from ..io.atomic import atomic_write

        self.close()
        self.path.parent.mkdir(parents=True, exist_ok=True)
        rank = {key_text(k): i for i, k in enumerate(order)}
        self.rows.sort(key=lambda r: (rank.get(key_of(r), len(rank)), key_of(r)))
        atomic_write(self.path, csv_text(self.rows))
        return self.rows

    def close(self) -> None:
        if self._fh is not None and not self._fh.closed:
            self._fh.close()
