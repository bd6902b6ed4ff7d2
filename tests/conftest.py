import os

import numpy as np
import pytest
from hypothesis import settings

from robocal.cli import main

# 300 examples per property in the suite; HYPOTHESIS_PROFILE=deep for a longer hunt
settings.register_profile("suite", max_examples=300)
settings.register_profile("deep", max_examples=5000)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "suite"))


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
