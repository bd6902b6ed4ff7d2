"""numba or numpy: which implementation runs the compiled paths of this process.

``auto`` means numba when it is installed (the ``fast`` extra), the environment variable
``ROBOCAL_NO_NUMBA`` is not set, and its kernels are compiled: numba's cache holds them when the
process first asks.  A process that finds the cache cold (the first run after install) runs
numpy throughout, one backend for the whole process, and starts ``python -m
robocal.calibration.precompile`` in the background, so that the runs after it load the kernels
in milliseconds: compiling them takes seconds of a core, longer than numpy takes for a paper's
whole swarm.  ``numba`` asked for explicitly compiles in the foreground where it must (a
calibration reports that time apart from its optimizer's).  Both paths give the same numbers
(the tests check it); numba is only imported the first time a kernel runs, so neither importing
robocal nor its command line pays for it.
"""

from __future__ import annotations

import functools
import os

from ..backend import BACKENDS, numba_installed
from ..exceptions import InputError


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
    if not numba_installed() or os.environ.get("ROBOCAL_NO_NUMBA"):
        return "numpy"
    if _PINNED:
        return _PINNED[-1]
    return "numba" if kernels_compiled() else "numpy"


#: what ``auto`` means in this process when a parent process said so (:func:`pin`)
_PINNED: list[str] = []


def pin(backend: str) -> None:
    """Make ``auto`` mean ``backend`` (``numba`` or ``numpy``) in this process from now on: a
    study's worker runs what its parent resolved, whatever it finds in numba's cache itself."""
    if backend not in ("numba", "numpy"):
        raise ValueError(f"pin numba or numpy, not {backend!r}")
    if backend == "numba" and not numba_installed():
        backend = "numpy"
    _PINNED[:] = [backend]


@functools.cache
def kernels_compiled() -> bool:
    """Whether numba's cache held every chain kernel when this process first asked (asked once:
    a process keeps one backend).  Where it did not, they are compiled in a background process
    (:func:`compile_in_background`) for the processes that follow."""
    try:
        from . import kernels

        # numba's own index of a kernel's compiled versions: empty where its source changed since
        ready = all(serial._cache._cache_file._load_index() for serial, _ in kernels.TWINS)
    except Exception:  # numba's cache laid out otherwise: compile in the foreground where needed
        return True
    if not ready:
        compile_in_background()
    return ready


#: a background compile that started less than this long ago (s) is taken as still running
COMPILE_LOCK_S = 600.0


def compile_in_background() -> bool:
    """Start ``python -m robocal.calibration.precompile`` detached (its own session, no output,
    at low priority), unless one started less than COMPILE_LOCK_S ago (a lock file in the
    temporary folder, holding the compile's process id); whether it started one."""
    import subprocess
    import sys
    import tempfile
    import time
    from pathlib import Path

    user = os.getuid() if hasattr(os, "getuid") else 0
    lock = Path(tempfile.gettempdir()) / f"robocal-compile-{user}.lock"
    try:
        if lock.exists() and time.time() - lock.stat().st_mtime < COMPILE_LOCK_S:
            return False
        lock.write_text(str(os.getpid()))
        command = [sys.executable, "-m", "robocal.calibration.precompile"]
        if sys.platform != "win32" and _has_nice():  # beside the run that started it, not in its way
            command = ["nice", "-n", "10", *command]
        child = subprocess.Popen(command, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                                 stderr=subprocess.DEVNULL, start_new_session=True)
        lock.write_text(str(child.pid))  # its session's id, for whoever must end it (a benchmark)
    except OSError:
        return False
    return True


def _has_nice() -> bool:
    import shutil

    return shutil.which("nice") is not None
