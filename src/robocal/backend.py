"""Which implementation runs the hot loops: compiled numba kernels or plain numpy.

The choice is explicit: functions that have a compiled path take ``backend=`` (``auto``,
``numba``, ``numpy``) and resolve it here, at call time.  ``auto`` means numba when it is
installed (the ``fast`` extra) and the environment variable ``ROBOCAL_NO_NUMBA`` is not
set.  Both paths give the same numbers (the tests check it); numba is only imported the
first time a kernel runs, so neither importing robocal nor its command line pays for it.
"""

from __future__ import annotations

import functools
import importlib.util
import os

from .exceptions import InputError

BACKENDS = ("auto", "numba", "numpy")


@functools.cache
def numba_installed() -> bool:
    return importlib.util.find_spec("numba") is not None


def resolve(backend: str = "auto") -> str:
    """``numba`` or ``numpy`` for a requested backend (see the module docstring)."""
    if backend not in BACKENDS:
        raise InputError(f"unknown backend {backend!r} (expected {' | '.join(BACKENDS)})", option="backend")
    if backend == "numpy":
        return "numpy"
    if backend == "numba":
        if not numba_installed():
            raise InputError("numba is not installed (pip install 'robocal[fast]')", option="backend")
        return "numba"
    return "numba" if numba_installed() and not os.environ.get("ROBOCAL_NO_NUMBA") else "numpy"
