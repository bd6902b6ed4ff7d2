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


def pytest_configure(config):
    """Once, before pytest-xdist starts its workers (in its controller, or a run without it): this
    install's numba kernels compiled if they are not, as the first process after an install starts
    them compiling in the background, but waited for here, so that the workers do not each compile
    again the kernels their numba tests call (a clean clone, as CI has, starts with none compiled).
    The test of a cold cache keeps a cache of its own."""
    import subprocess
    import sys

    if os.environ.get("PYTEST_XDIST_WORKER") or not numba_installed():
        return
    from robocal.model.compiled import COMPILED, _read, fingerprint, state_folder, take_lock

    folder = state_folder()
    if folder is None or _read(folder / COMPILED) == fingerprint() or not take_lock(folder):
        return
    subprocess.run([sys.executable, "-m", "robocal.calibration.precompile", str(folder)], check=False,
                   stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)


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
