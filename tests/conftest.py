import numpy as np
import pytest

from robocal.cli import main


@pytest.fixture
def rng():
    return np.random.default_rng(12345)


@pytest.fixture
def run_cli(capsys):
    """Run the command line in-process; returns (exit code, stdout, stderr)."""

    def run(*args):
        code = main([str(a) for a in args])
        out, err = capsys.readouterr()
        return code, out, err

    return run
