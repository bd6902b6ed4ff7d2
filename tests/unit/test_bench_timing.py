"""The benchmarks' own measures: a workload's peak memory is its own process's."""

import sys

import numpy as np
import pytest


@pytest.mark.skipif(sys.platform != "linux", reason="the process image's own peak (VmHWM) is Linux's")
def test_a_workload_s_peak_memory_is_its_own_not_its_parent_s():
    """A fresh interpreter forked from a large one: its peak is what it allocates (80 MB here), not
    the parent's 300 MB, which ru_maxrss carries across the exec."""
    from robocal.bench.timing import run_measured

    parent = np.ones(300_000_000 // 8)  # resident: every page written
    script = "import json\nimport numpy as np\nx = np.ones(10_000_000)\nprint(json.dumps({'s': float(x.sum())}))"
    out, peak_gb = run_measured(script)
    assert out == {"s": 1e7} and parent[-1] == 1.0
    assert 0.08 <= peak_gb < 0.2, peak_gb
