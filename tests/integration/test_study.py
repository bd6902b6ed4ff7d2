"""Studies: the same runs.csv (apart from times) in this process, on local worker processes and
on a Dask scheduler; resuming after an interruption; the outputs; one-line errors."""

import csv
import io

import pytest

from robocal.study.driver import run_study
from robocal.study.runs import TIME_COLUMNS
from robocal.study.spec import parse_study

STUDY = """
robot = "kr5-arc"
errors = "uniform:0.25,0.05"
measure = "position"
frames = "none"
poses = [30]
noise = [0.0, 0.02]
methods = ["lm", "ldpso-bt"]
seeds = 6
validate = 200
iterations = 100   # the swarm's generations, kept short for the suite
"""


def _without_times(path) -> list[dict]:
    rows = list(csv.DictReader(io.StringIO(path.read_text())))
    return [{k: v for k, v in r.items() if k not in TIME_COLUMNS} for r in rows]


@pytest.fixture(scope="module")
def in_process(tmp_path_factory):
    out = tmp_path_factory.mktemp("one")
    result = run_study(parse_study(STUDY, source="study.toml"), out, workers=1)
    return out, result


def test_a_study_runs_every_seed_of_every_cell(in_process):
    out, result = in_process
    assert result.ran == 24 and result.skipped == 0
    rows = _without_times(out / "runs.csv")
    assert len(rows) == 24
    assert list(rows[0]) == ["method", "poses", "noise", "seed", "status", "before_rms", "after_rms", "validation_rms",
                             "iterations", "evaluations", "spec"]
    assert {r["spec"] for r in rows} == {parse_study(STUDY, source="study.toml").fingerprint()}
    assert {(r["method"], r["noise"]) for r in rows} == {("lm", "0"), ("lm", "0.02"), ("ldpso-bt", "0"),
                                                          ("ldpso-bt", "0.02")}
    summary = (out / "summary.md").read_text()
    assert "| lm | ldpso-bt | 30 | 0.02 | 6 |" in summary
    assert (out / "validation_rms.png").stat().st_size > 1000 and (out / "time.png").stat().st_size > 1000


@pytest.mark.slow
def test_local_workers_and_a_dask_scheduler_give_the_same_runs(in_process, tmp_path):
    from dask.distributed import LocalCluster

    out, _ = in_process
    local = run_study(parse_study(STUDY, source="study.toml"), tmp_path / "local", workers=2)
    assert local.ran == 24 and "2 local worker processes" in local.executor
    assert _without_times(tmp_path / "local" / "runs.csv") == _without_times(out / "runs.csv")
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
                      dashboard_address=None) as cluster:
        remote = run_study(parse_study(STUDY, source="study.toml"), tmp_path / "dask",
                           scheduler=cluster.scheduler_address)
        # the scheduler's own count of the study's tasks that reached memory (were computed)
        computed = cluster.scheduler.task_prefixes["robocal-runs"].state_counts["memory"]
    assert remote.ran == 24 and computed >= 2
    assert _without_times(tmp_path / "dask" / "runs.csv") == _without_times(out / "runs.csv")


def test_an_interrupted_study_resumes_where_it_stopped(in_process, tmp_path):
    out, _ = in_process
    lines = (out / "runs.csv").read_text().splitlines()
    # a study that stopped after 10 runs, the last row cut short by the crash
    (tmp_path / "runs.csv").write_text("\n".join(lines[:11]) + "\n" + lines[11][:15])
    again = run_study(parse_study(STUDY, source="study.toml"), tmp_path, workers=1)
    assert again.skipped == 10 and again.ran == 14
    assert _without_times(tmp_path / "runs.csv") == _without_times(out / "runs.csv")
    done = run_study(parse_study(STUDY, source="study.toml"), tmp_path, workers=1)
    assert done.ran == 0 and done.skipped == 24


BAD = [
    ("seeds = 3\nmethods = ['lm']\nposes = [30]\n", "missing key 'robot'"),
    ("robot = 'kr5-arc'\nseeds = 3\nmethods = ['sgd']\nposes = [30]\n", "key 'methods': unknown method 'sgd'"),
    ("robot = 'kr5-arc'\nseeds = 3\nmethods = ['lm']\nposes = [30]\nnoise = [-1]\n", "key 'noise'"),
    ("robot = 'kr5-arc'\nseeds = 0\nmethods = ['lm']\nposes = [30]\n", "key 'seeds'"),
    ("robot = 'kr5-arc'\nseeds = 3\nmethods = ['lm']\nposes = [30]\nerrors = 'gauss'\n", "key 'errors'"),
    ("robot = 'kr5-arc'\nseeds = 3\nmethods = ['lm']\nposes = [30]\nloss = 'hubber'\n", "key 'loss'"),
    ("robot = 'kr5-arc'\nseeds = 3\nmethods = ['lm']\nposes = [30]\nworkers = 2\n", "unknown key 'workers'"),
    ("robot = 'kr6-arc'\nseeds = 3\nmethods = ['lm']\nposes = [30]\n", "key 'robot'"),
]


@pytest.mark.parametrize("text,message", BAD)
def test_bad_study_files_give_one_line_and_exit_2(text, message, tmp_path, run_cli):
    path = tmp_path / "bad.toml"
    path.write_text(text)
    code, out, err = run_cli("study", path, "--out", tmp_path / "out")
    assert code == 2 and err.count("\n") == 1 and message in err and str(path) in err
    assert not (tmp_path / "out").exists()


def test_the_command_line_and_an_unreachable_scheduler(tmp_path, run_cli):
    path = tmp_path / "s.toml"
    path.write_text("robot = 'kr5-arc'\nseeds = 2\nmethods = ['lm']\nposes = [20]\nvalidate = 20\n")
    code, out, err = run_cli("study", path, "--out", tmp_path / "o", "--workers", "1")
    assert code == 0 and "2 runs done" in " ".join(out.split())
    code, out, err = run_cli("study", path, "--out", tmp_path / "p", "--scheduler", "tcp://127.0.0.1:9")
    assert code == 2 and "cannot reach the Dask scheduler" in err


@pytest.mark.slow
def test_kou_repeated_runs_on_workers_give_the_runs_of_this_process(tmp_path):
    from robocal.papers.kou2022.reproduce import kou2022

    (tmp_path / "here").mkdir()
    (tmp_path / "there").mkdir()
    here = kou2022(tmp_path / "here", quick=True, runs=2)
    there = kou2022(tmp_path / "there", quick=True, runs=2, workers=2)
    for method in ("pso", "ldpso-bt"):
        assert there["swarms"][method]["fitness_all"] == here["swarms"][method]["fitness_all"]
    assert there["executor"] == "2 local worker processes"
    assert "run on 2 local worker processes" in (tmp_path / "there" / "summary.md").read_text()
