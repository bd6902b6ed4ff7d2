"""Backend choice is explicit, honours ROBOCAL_NO_NUMBA, and nothing heavy loads at import."""

import json
import os
import subprocess
import sys
import time
import warnings

import pytest

from robocal.backend import numba_installed
from robocal.exceptions import InputError
from robocal.model.compiled import resolve


def _python(code: str, env_extra: dict | None = None) -> str:
    """stdout of ``code`` in a fresh interpreter, with ROBOCAL_NO_NUMBA only as given."""
    env = dict(os.environ)
    env.pop("ROBOCAL_NO_NUMBA", None)
    env.update(env_extra or {})
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, env=env).stdout


def test_explicit_choices_and_bad_values(monkeypatch):
    assert resolve("numpy") == "numpy"
    monkeypatch.setenv("ROBOCAL_NO_NUMBA", "1")
    assert resolve("auto") == "numpy"
    with pytest.raises(InputError, match="unknown backend"):
        resolve("cuda")


@pytest.mark.skipif(not numba_installed(), reason="numba (fast extra) not installed")
def test_environment_variable_is_read_at_call_time_not_import_time(monkeypatch):
    from robocal.model import compiled

    monkeypatch.setattr(compiled, "kernels_compiled", lambda: True)
    monkeypatch.delenv("ROBOCAL_NO_NUMBA", raising=False)
    assert resolve("auto") == "numba"
    monkeypatch.setenv("ROBOCAL_NO_NUMBA", "1")
    assert resolve("auto") == "numpy"
    assert resolve("numba") == "numba"  # an explicit request wins


def test_swarm_under_no_numba_runs_the_numpy_path_and_loads_no_numba():
    code = (
        "import sys, json, numpy as np\n"
        "from robocal.optimize.swarm import pso\n"
        "r = pso(lambda X: np.sum(X**2, -1), -np.ones(4), np.ones(4), particles=20, iterations=30, w=0.8, c1=1.49,"
        " c2=1.49, seed=2)\n"
        "print(json.dumps({'x': r.x.tolist(), 'numba': 'numba' in sys.modules}))\n"
    )
    out = json.loads(_python(code, {"ROBOCAL_NO_NUMBA": "1"}).splitlines()[-1])
    assert out["numba"] is False
    import numpy as np

    from robocal.optimize.swarm import pso

    ref = pso(lambda X: np.sum(X**2, -1), -np.ones(4), np.ones(4), particles=20, iterations=30, w=0.8, c1=1.49,
              c2=1.49, seed=2,
              backend="numpy")
    assert out["x"] == ref.x.tolist()


def test_import_and_help_load_nothing_heavy():
    code = (
        "import sys, json, robocal, robocal.cli\n"
        "from robocal.cli import main\n"
        "import io, contextlib\n"
        "with contextlib.redirect_stdout(io.StringIO()):\n"
        "    main(['--help'])\n"
        "print(json.dumps(sorted(m for m in ('numba', 'scipy', 'matplotlib', 'numpy') if m in sys.modules)))\n"
    )
    assert json.loads(_python(code).splitlines()[-1]) == []


def test_no_process_wide_state_changes():
    import numpy as np

    before = np.geterr()
    from robocal.cli import main

    main(["robots"])
    assert np.geterr() == before
    import matplotlib

    backend = matplotlib.get_backend()
    from robocal.report import figures

    figures.png_bytes(figures.convergence({"a": np.array([3.0, 2.0, 1.0])}, "t"))
    assert matplotlib.get_backend() == backend


def _pid_and_square(x):
    return os.getpid(), x * x


def _fails(x):
    raise ValueError(f"piece {x}")


def test_worker_pool_gives_the_serial_results_in_order(monkeypatch):
    """With two idle cores the pieces run in forked workers (other process ids), and the results
    come back as the serial map gives them; a piece's error reaches the caller."""
    import robocal.backend as backend

    monkeypatch.setattr(backend, "idle_cores", lambda now=False, looks=5: 2)
    with backend.worker_pool() as pool:
        out = pool.map(_pid_and_square, range(12))
        with pytest.raises(ValueError, match="piece"):
            pool.map(_fails, range(3))
    assert [v for _, v in out] == [x * x for x in range(12)]
    if sys.platform == "linux":
        assert {pid for pid, _ in out} - {os.getpid()}
    with backend.SERIAL as serial:  # one core: here, in order
        assert serial.map(_pid_and_square, range(3)) == [(os.getpid(), x * x) for x in range(3)]


def _slow_square(x):
    import time

    time.sleep(1.0 if x == 0 else 0.0)  # long beside a worker's start, even on a loaded machine
    return os.getpid(), x * x, time.perf_counter()


def test_submitted_pieces_start_first_and_give_map_s_results(monkeypatch):
    """Pieces handed over with ``submit`` run on the workers ahead of a later ``map``, whose pieces
    fill the core the slow one leaves; ``result()`` gives map's results in order, and without
    workers (or with a worker dead) the same results, here."""
    import robocal.backend as backend
    from robocal.exceptions import RobocalWarning

    monkeypatch.setattr(backend, "idle_cores", lambda now=False, looks=5: 2)
    with backend.worker_pool() as pool:
        early = pool.submit(_slow_square, [0, 1])
        later = pool.map(_pid_and_square, range(6))
        mapped = time.perf_counter()  # the same monotonic clock as the workers' on Linux
        got = early.result()
        with pytest.raises(ValueError, match="piece"):
            pool.submit(_fails, range(2)).result()
    assert [v for _, v, _ in got] == [0, 1] and [v for _, v in later] == [x * x for x in range(6)]
    if sys.platform == "linux":
        # the slow piece was still running when map returned: map did not wait behind it
        assert got[0][2] > mapped and {pid for pid, _, _ in got} - {os.getpid()}
    with backend.SERIAL as serial:
        pending = serial.submit(_pid_and_square, range(3))
        assert pending.result() == [(os.getpid(), x * x) for x in range(3)]
    if sys.platform == "linux":
        with backend.worker_pool() as pool, pytest.warns(RobocalWarning, match="worker process ended abruptly"):
            assert pool.submit(_dies_in_a_worker, range(4)).result() == [1, 2, 3, 4]


def test_residual_tuning_on_workers_equals_tuning_here(monkeypatch):
    """The tunings from several starts give the same kernel on workers as in this process (to
    the rounding of BLAS on one thread there and on this process's threads here)."""
    import numpy as np

    import robocal.backend as backend
    from robocal.calibration.select.residual import fit_residual

    rng = np.random.default_rng(3)
    q = rng.uniform(-2, 2, (90, 6))
    e = np.column_stack([np.sin(2 * q[:, 0]), np.cos(q[:, 1]), q[:, 2] * 0.1]) + rng.normal(0, 0.05, (90, 3))
    here = fit_residual(q, e, seed=0)[1][0]
    monkeypatch.setattr(backend, "idle_cores", lambda now=False, looks=5: 2)
    with backend.worker_pool() as pool:
        there = fit_residual(q, e, seed=0, pool=pool)[1][0]
    np.testing.assert_allclose(here.theta, there.theta, rtol=1e-6)


_PARENT = os.getpid()


def _dies_in_a_worker(x):
    if os.getpid() != _PARENT:
        os._exit(1)
    return x + 1


def test_a_pool_whose_worker_dies_runs_the_pieces_here_and_says_so(monkeypatch):
    import robocal.backend as backend
    from robocal.exceptions import RobocalWarning

    if sys.platform != "linux":
        pytest.skip("workers are forked on Linux only")
    monkeypatch.setattr(backend, "idle_cores", lambda now=False, looks=5: 2)
    with backend.worker_pool() as pool, pytest.warns(RobocalWarning, match="worker process ended abruptly"):
        assert pool.map(_dies_in_a_worker, range(4)) == [1, 2, 3, 4]


@pytest.mark.skipif(not os.path.exists("/proc/loadavg"), reason="Linux's count of runnable tasks")
def test_idle_cores_now_sees_busy_processes_the_minute_average_has_not_yet():
    """One busy process per core, started a moment ago: no core is idle now (at least 1 is
    said, for this process), whatever the 1-minute load still says."""
    import time

    import robocal.backend as backend

    cores = len(os.sched_getaffinity(0))
    busy = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(cores)]
    try:
        time.sleep(0.5)
        assert backend.idle_cores(now=True) == 1
    finally:
        for p in busy:
            p.kill()
            p.wait()


@pytest.mark.skipif(not os.path.exists("/proc/self/task"), reason="Linux's threads of a process")
def test_this_process_s_own_spinning_threads_are_not_another_s_work():
    """A helper thread of this process that runs (as a kernel's OpenMP threads spin a moment after
    their work) is counted as this process's: the workers it is about to wait on take its core."""
    import threading

    import numpy as np

    import robocal.backend as backend

    stop = threading.Event()

    def spin():  # a large product releases the interpreter lock: the thread runs beside this one
        a = np.ones((300, 300))
        while not stop.is_set():
            a @ a

    thread = threading.Thread(target=spin)
    thread.start()
    try:
        seen = max(backend._own_running() for _ in range(50))
    finally:
        stop.set()
        thread.join()
    assert seen >= 2
    assert backend._own_running() >= 1


@pytest.mark.skipif(not numba_installed(), reason="numba (fast extra) not installed")
def test_a_cold_cache_runs_numpy_and_compiles_for_the_next_process(tmp_path):
    """The first process after install finds no compile recorded: it runs numpy (no compiling in its
    time) and starts the compile in the background, once; the next process, the compile recorded, runs
    the kernels.  Its own lock and record (the user cache folder moved); numba's cache the session's,
    which the compile before the tests filled, so the background compile loads it in seconds (a cold
    one is every clean clone's compile before its tests), unless NUMBA_CACHE_DIR holds both."""
    import time

    env = {"XDG_CACHE_HOME": str(tmp_path / "cache")}
    if os.environ.get("NUMBA_CACHE_DIR"):  # the record lives beside numba's cache: both of its own, cold
        env = {"NUMBA_CACHE_DIR": str(tmp_path / "cache")}
    ask = ("import json, time\nfrom robocal.model.compiled import resolve\nt = time.perf_counter()\n"
           "b = resolve('auto')\nprint(json.dumps({'backend': b, 's': time.perf_counter() - t}))")
    first = json.loads(_python(ask, env).splitlines()[-1])
    assert first["backend"] == "numpy" and first["s"] < 5.0  # asked, not compiled
    (folder,) = (tmp_path / "cache" / "robocal").glob("compile-*")
    assert (folder / "lock").exists() and oct((folder / "lock").stat().st_mode)[-3:] == "600"
    assert json.loads(_python(ask, env).splitlines()[-1])["backend"] == "numpy"  # still compiling: no second one
    deadline = time.time() + 55
    while time.time() < deadline and not (folder / "compiled").exists():
        time.sleep(0.5)
    assert not (folder / "lock").exists()
    assert json.loads(_python(ask, env).splitlines()[-1])["backend"] == "numba"


def test_a_study_worker_runs_what_its_parent_resolved(monkeypatch):
    """A worker process may find numba's cache warm where its parent found it cold (the compile
    finished in between): the engine hands each task the parent's backend, so a run gives the
    same numbers wherever it runs."""
    import inspect

    from robocal.model import compiled
    from robocal.study import engine

    monkeypatch.setattr(compiled, "_PINNED", [])
    monkeypatch.setattr(compiled, "kernels_compiled", lambda: True)
    monkeypatch.delenv("ROBOCAL_NO_NUMBA", raising=False)
    assert resolve("auto") == ("numba" if numba_installed() else "numpy")
    compiled.pin("numpy")
    assert resolve("auto") == "numpy" and resolve("numpy") == "numpy"
    assert "backend" in inspect.signature(engine.run_batch).parameters


def test_the_compile_lock_is_taken_once_by_simultaneous_starts_and_never_through_a_link(tmp_path):
    """Four processes started together, five times over: one takes the lock each time (O_EXCL); a
    planted link in the lock's place is removed, not followed, and its target left as it was; a lock
    left by a compile that died long ago is taken over."""
    from robocal.model.compiled import COMPILE_LOCK_S, take_lock

    code = ("import sys, time\nfrom robocal.model.compiled import take_lock\nstart = float(sys.argv[2])\n"
            "time.sleep(max(0.0, start - time.time()))\nprint(take_lock(sys.argv[1]))")
    for trial in range(5):
        folder = tmp_path / f"t{trial}"
        folder.mkdir()
        start = time.time() + 1.0  # each process started and waiting by then (a late one still finds the lock held)
        runs = [subprocess.Popen([sys.executable, "-c", code, str(folder), str(start)], stdout=subprocess.PIPE,
                                 text=True) for _ in range(4)]
        said = [r.communicate()[0].strip() for r in runs]
        assert said.count("True") == 1, said
    folder = tmp_path / "linked"
    folder.mkdir()
    victim = tmp_path / "victim.txt"
    victim.write_text("keep me")
    (folder / "lock").symlink_to(victim)
    assert take_lock(folder)
    assert victim.read_text() == "keep me" and not (folder / "lock").is_symlink()
    assert not take_lock(folder)  # held
    old = time.time() - 2 * COMPILE_LOCK_S
    os.utime(folder / "lock", (old, old))
    assert take_lock(folder)  # a dead compile's


def test_a_failed_compile_is_said_once_and_not_started_again(tmp_path, monkeypatch):
    """A compile that fails (an unwritable numba cache) records why; the processes after it run numpy,
    say so once, and start no compile until something it depends on changes."""
    from robocal.calibration import precompile
    from robocal.exceptions import RobocalWarning
    from robocal.model import compiled

    folder = tmp_path / "state"
    folder.mkdir()
    monkeypatch.setattr(compiled, "state_folder", lambda package=None: folder)
    monkeypatch.setattr(compiled, "fingerprint", lambda: "robocal x, numba y")

    def broken():
        raise PermissionError("cannot write numba's cache in /opt/site-packages/robocal/__pycache__")

    monkeypatch.setattr(precompile, "compile_kernels", broken)
    with pytest.raises(PermissionError):
        precompile.main(str(folder))
    assert not (folder / "lock").exists() and "PermissionError" in (folder / "failed").read_text()
    started = []
    monkeypatch.setattr(compiled, "compile_in_background", lambda f=None: started.append(f) or True)
    for expected in (1, 0):  # said the first time, not again
        compiled.kernels_compiled.cache_clear()
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            assert compiled.kernels_compiled() is False
        said = [str(w.message) for w in caught if issubclass(w.category, RobocalWarning)]
        assert len(said) == expected and (not said or "could not be compiled (PermissionError" in said[0])
    assert started == []
    monkeypatch.setattr(compiled, "fingerprint", lambda: "robocal x, numba z")  # numba changed: tried again
    compiled.kernels_compiled.cache_clear()
    assert compiled.kernels_compiled() is False and started == [folder]
    compiled.kernels_compiled.cache_clear()


def test_no_writable_cache_folder_means_numpy_and_each_install_has_its_own(tmp_path, monkeypatch):
    from robocal.exceptions import RobocalWarning
    from robocal.model import compiled

    blocker = tmp_path / "not-a-folder"
    blocker.write_text("")
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(blocker))
    assert compiled.state_folder() is None
    compiled.kernels_compiled.cache_clear()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        assert compiled.kernels_compiled() is False
    assert any("no writable cache folder" in str(w.message) for w in caught if issubclass(w.category, RobocalWarning))
    compiled.kernels_compiled.cache_clear()
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path / "cache"))
    one, two = compiled.state_folder(tmp_path / "a" / "robocal"), compiled.state_folder(tmp_path / "b" / "robocal")
    assert one != two and one.parent == two.parent == tmp_path / "cache" / "robocal"
    assert oct(one.stat().st_mode)[-3:] == "700"


def _threads_here(_):
    from robocal.backend import kernel_threads

    return kernel_threads(10 ** 9), kernel_threads(10 ** 9, now=True)


def test_a_child_process_runs_kernels_on_one_thread(monkeypatch):
    """A kernel large enough for every idle core gets them in this process, and one thread in a
    forked worker: its cores are shared out already, and numba's OpenMP layer aborts a forked
    child that starts it."""
    import robocal.backend as backend

    if not backend.numba_installed() or sys.platform != "linux":
        pytest.skip("numba's threads, forked workers")
    import numba

    monkeypatch.setattr(backend, "idle_cores", lambda now=False, looks=5: 2)
    monkeypatch.delenv("ROBOCAL_WORKERS", raising=False)
    here = _threads_here(None)
    assert here == (min(2, numba.config.NUMBA_NUM_THREADS),) * 2
    assert backend.kernel_threads(backend.PARALLEL_MIN_WORK - 1) == 1
    with backend.worker_pool() as pool:
        assert pool.map(_threads_here, range(2)) == [(1, 1), (1, 1)]
