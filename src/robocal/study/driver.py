"""Running a study into a folder: the runs not done yet, runs.csv, summary.md and figures."""

from __future__ import annotations

import functools
import os
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from ..calibration.registry import METHODS
from ..exceptions import InputError, Interrupted
from .engine import map_runs
from .runs import RunsFile, key_of, key_text, read_runs, run
from .spec import Study, load_study
from .summary import summary_markdown


@dataclass
class StudyResult:
    """The rows of the study's runs (this study's cells only), how many ran now, and the time."""

    study: Study
    rows: list[dict]
    ran: int
    skipped: int
    elapsed_s: float
    executor: str


#: methods this process has already run once (imports done, kernels compiled or loaded)
_WARM: set = set()


def warm_up(study: Study) -> None:
    """Before a task's runs: one tiny calibration per method in this process, the first time,
    so that imports and kernel compilation stay out of the runs' own times."""
    import warnings

    from ..calibration import calibrate
    from ..simulation import simulate
    from .runs import cached_robot

    robot = cached_robot(study.robot)
    for method in study.methods:
        if (study.robot, method) in _WARM:
            continue
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            sim = simulate(robot, 12, measure=study.measure, seed=0)
            short = {} if METHODS[method].swarm is None else {"iterations": 2, "particles": 10}
            calibrate(robot, sim.measurements, method, frames="none", **{**study.calibration, **short})
        _WARM.add((study.robot, method))


def run_study(study: Study | str | Path, out: str | Path, *, workers: int | None = None, scheduler: str | None = None,
              batch: int | None = None, progress: Callable[[int, int], None] | None = None) -> StudyResult:
    """Run the study's runs that ``out``/runs.csv does not hold yet, then write runs.csv (in run
    order), summary.md and the figures.  workers: local worker processes (default: all cores);
    scheduler: a Dask scheduler's address instead (see :func:`robocal.study.engine.map_runs`)."""
    from .. import options as opt

    if not isinstance(study, Study):
        study = load_study(study)
    if workers is not None and scheduler is not None:
        raise InputError("give local workers or a scheduler, not both", option="scheduler")
    workers = opt.integer(workers, "workers", minimum=1) if workers is not None else None
    if scheduler is None and workers is None:
        workers = os.cpu_count() or 1
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise InputError("exists and is not a folder", source=out)
    if not out.exists() and not out.parent.is_dir():
        raise InputError("its parent folder does not exist", source=out, option="out")
    order = study.runs()
    wanted = {key_text(k) for k in order}
    existing = read_runs(out / "runs.csv")
    check_same_study(study, existing, out)
    have = {key_of(r) for r in existing if key_of(r) in wanted}
    todo = [k for k in order if key_text(k) not in have]
    runs_file = RunsFile(out / "runs.csv", existing)
    start = time.perf_counter()
    try:
        for _, r in map_runs(functools.partial(run, study), todo, workers=workers, scheduler=scheduler,
                             setup=functools.partial(warm_up, study), batch=batch, progress=progress):
            runs_file.add(r)
    except (Interrupted, KeyboardInterrupt):
        raise Interrupted(f"{out / 'runs.csv'} keeps the {len(runs_file.rows)} runs done; the same command "
                          "resumes") from None
    finally:
        runs_file.close()
    elapsed = time.perf_counter() - start
    rows = [r for r in runs_file.finish(order) if key_of(r) in wanted]
    executor = f"Dask scheduler {scheduler}" if scheduler else (
        f"{workers} local worker process{'es' if workers > 1 else ''}" if workers > 1 else "this process")
    result = StudyResult(study, rows, len(todo), len(order) - len(todo), elapsed, executor)
    write_outputs(result, out)
    return result


#: the study's identity beside its runs.csv, to name what differs when another study resumes there
IDENTITY_FILE = "study.json"


def check_same_study(study: Study, rows: list[dict], out: Path) -> None:
    """Refuse to resume into a folder whose runs another study made (another robot, errors,
    frames, options…): their figures would be summarised as this study's."""
    import json

    mine = study.fingerprint()
    theirs = sorted({r["spec"] for r in rows} - {mine})
    if not theirs:
        return
    recorded = out / IDENTITY_FILE
    differ = ""
    try:
        before = json.loads(recorded.read_text(encoding="utf-8"))["identity"]
        now = study.identity()
        keys = [k for k in sorted(set(before) | set(now)) if before.get(k) != now.get(k)]
        differ = ": " + "; ".join(f"{k} {before.get(k, '(unset)')!r} there, {now.get(k, '(unset)')!r} here"
                                  for k in keys)
    except (OSError, ValueError, KeyError, TypeError):
        pass
    raise InputError(f"was made by a different study{differ or ' (' + IDENTITY_FILE + ' is missing)'}; its runs "
                     "would mix with this one's: use another --out folder", source=out / "runs.csv")


def write_outputs(result: StudyResult, out: Path) -> None:
    import json

    from ..io.atomic import atomic_write
    from ..report import figures

    atomic_write(out / IDENTITY_FILE, json.dumps({"spec": result.study.fingerprint(),
                                                  "identity": result.study.identity()}, indent=1) + "\n")
    atomic_write(out / "summary.md", summary_markdown(result.study, result.rows,
                                                      elapsed_s=result.elapsed_s if result.ran else None,
                                                      executor=result.executor if result.ran else ""))
    for column, label, name in (("validation_rms", "validation RMS (mm)", "validation_rms.png"),
                                ("time_s", "time per run (s)", "time.png")):
        figures.save_png(figures.study_boxes(result.rows, result.study, column, label), out / name)
