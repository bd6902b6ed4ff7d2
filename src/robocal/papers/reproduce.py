"""``robocal reproduce``: run one paper's experiment, or all three, into a folder."""

from __future__ import annotations

from pathlib import Path

from .. import options as opt
from ..exceptions import InputError
from . import SCENARIOS
from .common import Say, quiet


def reproduce(name: str, out: str | Path, *, quick: bool = False, runs: int = 10, seed: int = 0,
              say: Say = quiet, workers: int | None = None, scheduler: str | None = None) -> dict:
    """Run one scenario (or ``all``) into folder ``out`` (subfolders per scenario for ``all``).

    quick: shortened settings, a smoke test only.  runs: repeated runs per swarm (kou2022).
    workers / scheduler: where Kou's repeated runs go (see :func:`robocal.study.engine.map_runs`;
    default: this process, interleaved, the fairest timing).
    Each writes ``summary.md``, ``results.json`` and PNG figures.
    """
    names = SCENARIOS if name == "all" else (opt.choice(name, SCENARIOS + ("all",), "scenario", "scenario"),)
    opt.integer(runs, "runs", minimum=1)
    if workers is not None:
        opt.integer(workers, "workers", minimum=1)
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise InputError("exists and is not a folder", source=out)
    if not out.exists() and not out.parent.is_dir():
        raise InputError("its parent folder does not exist", source=out, option="out")
    from ..io.atomic import together

    with together():  # every summary and figure lands at the end, or none does
        return _run(names, name, out, quick, runs, seed, say, workers, scheduler)


def _run(names, name, out: Path, quick, runs, seed, say, workers, scheduler) -> dict:
    done = {}
    for n in names:
        folder = out / n if name == "all" else out
        folder.mkdir(parents=True, exist_ok=True)
        if n == "wen2019":
            from .wen2019.reproduce import wen2019

            done[n] = wen2019(folder, quick=quick, seed=seed, say=say)
        elif n == "kou2022":
            from .kou2022.reproduce import kou2022

            done[n] = kou2022(folder, quick=quick, runs=runs, seed=seed, say=say, workers=workers,
                              scheduler=scheduler)
        else:
            from .chen2023.reproduce import chen2023_study

            done[n] = chen2023_study(folder, quick=quick, seed=seed, say=say)
    return done
