"""Fixtures shared by every test: a seeded generator, the in-process command line, quiet
warnings, and the compute backends."""

import os
import warnings

import numpy as np
import pytest
from hypothesis import settings

from robocal.backend import numba_installed

# 300 examples per property in the suite; HYPOTHESIS_PROFILE=deep for a longer hunt
settings.register_profile("suite", max_examples=300)
settings.register_profile("deep", max_examples=5000)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "suite"))

#: the backends this machine can run: numpy always, numba with the fast extra
BACKENDS = ["numpy"] + (["numba"] if numba_installed() else [])


def _compile_state():
    """This install's compile folder and whether its kernels are compiled (None, True without numba)."""
    if not numba_installed():
        return None, True
    from robocal.model.compiled import COMPILED, _read, fingerprint, state_folder

    folder = state_folder()
    return folder, folder is None or _read(folder / COMPILED) == fingerprint()


def pytest_configure(config):
    """Once, as pytest-xdist's controller starts (or a run without it): this install's numba kernels
    compiled if they are not, as the first process after an install starts them compiling in the
    background, but here at full speed while the workers start and collect, and waited for before
    the first test (:func:`_kernels_compiled`), so that the workers do not each compile again the
    kernels their numba tests call (a clean clone, as CI has, starts with none compiled).  The test
    of a cold cache keeps a cache of its own."""
    import subprocess
    import sys

    if os.environ.get("PYTEST_XDIST_WORKER"):
        return
    folder, compiled = _compile_state()
    if compiled:
        return
    from robocal.model.compiled import take_lock

    if take_lock(folder):
        compiling = subprocess.Popen([sys.executable, "-m", "robocal.calibration.precompile", str(folder)],
                                     stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        config.add_cleanup(compiling.wait)


@pytest.fixture(scope="session", autouse=True)
def _kernels_compiled():
    """Each worker's tests start once the compile :func:`pytest_configure` started has ended (its
    lock gone), at most 120 s."""
    import time

    folder, compiled = _compile_state()
    if compiled or folder is None:
        return
    from robocal.model.compiled import LOCK

    deadline = time.time() + 120.0
    while (folder / LOCK).exists() and time.time() < deadline:
        time.sleep(0.2)


@pytest.fixture
def rng():
    return np.random.default_rng(12345)


@pytest.fixture
def run_cli(capsys):
    """Run the command line in-process; returns (exit code, stdout, stderr)."""
    from robocal.cli import main

    def run(*args):
        code = main([str(a) for a in args])
        out, err = capsys.readouterr()
        return code, out, err

    return run


@pytest.fixture
def quiet():
    """Silence robocal's warnings where a test looks at results, not at what is said."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        yield


@pytest.fixture(params=BACKENDS)
def backend(request):
    """Each available backend in turn: the numpy fallback runs in every suite."""
    return request.param
