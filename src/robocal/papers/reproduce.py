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


#: how a summary's verdict begins, and what it counts as
VERDICTS = (("beats", "beaten"), ("reproduces", "reproduced"), ("does not reproduce", "not reproduced"),
            ("cannot reproduce", "need data robocal does not have"))


def verdict_counts(summary: str) -> dict[str, int]:
    """How many of the published figures a ``summary.md`` (its text) beats, reproduces, does not
    reproduce, or cannot reproduce (the last column of its first table)."""
    counts = {label: 0 for _, label in VERDICTS}
    rows = summary.split("## Published against measured", 1)[-1].split("\n## ", 1)[0]
    for line in rows.splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if len(cells) < 2 or cells[-1] in ("verdict", "") or set(cells[-1]) <= set("-:"):
            continue
        label = next((label for start, label in VERDICTS if cells[-1].startswith(start)), None)
        if label is not None:
            counts[label] += 1
    return counts

