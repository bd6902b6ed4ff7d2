"""numba or numpy: which implementation runs the compiled paths of this process.

``auto`` means numba when it is installed (the ``fast`` extra), the environment variable
``ROBOCAL_NO_NUMBA`` is not set, and its kernels are compiled: a background compile of this install
recorded that it finished, for this robocal, numba, Python and kernels' source (a per-user, per-install
folder holds its lock and record: :func:`state_folder`).  A process that finds them not compiled (the
first run after install) runs numpy throughout, one backend for the whole process, and starts ``python -m
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
    """Whether this install's kernels are compiled (asked once: a process keeps one backend): the
    record a finished background compile left (:func:`record`) for this robocal, numba and Python and
    these kernels' source, and the kernels import.  Where they are not, a compile starts in the
    background (:func:`compile_in_background`) for the processes that follow; where one failed, it is
    said once and not tried again until something it depends on changes."""
    folder = state_folder()
    if folder is None:  # nowhere of this user's to keep the lock and the record: numpy, said once
        _say_once(None, "no writable cache folder for the numba kernels' compile (set NUMBA_CACHE_DIR or "
                        "XDG_CACHE_HOME): running numpy")
        return False
    key = fingerprint()
    if _read(folder / COMPILED) == key:
        try:
            from . import kernels  # noqa: F401  (numba, and every kernel's module, import)
        except Exception as exc:  # an install whose numba breaks now: numpy, said
            _say_once(folder, f"the numba kernels cannot be imported ({type(exc).__name__}: {exc}): running numpy")
            return False
        return True
    failed = _read(folder / FAILED)
    if failed is not None and failed.split("\n", 1)[0] == key:
        _say_once(folder, f"the numba kernels could not be compiled ({failed.split(chr(10), 1)[-1].strip()}): "
                          "running numpy")
        return False
    compile_in_background(folder)
    return False


#: a background compile that started less than this long ago (s) is taken as still running
COMPILE_LOCK_S = 600.0
#: the files of a compile's state folder: its lock, its success record, its failure record (and when it was said)
LOCK, COMPILED, FAILED, SAID = "lock", "compiled", "failed", "said"


def state_folder(package=None):
    """This user's folder for this install's compile (its lock and records), created private, or None
    where none can be: under NUMBA_CACHE_DIR where set, else the user cache folder (XDG_CACHE_HOME,
    ~/.cache; LOCALAPPDATA on Windows), one per install (its package folder's path hashed): another
    install's compile never stands in this one's way."""
    import hashlib
    import sys
    from pathlib import Path

    if os.environ.get("NUMBA_CACHE_DIR"):
        base = Path(os.environ["NUMBA_CACHE_DIR"]) / "robocal"
    elif sys.platform == "win32" and os.environ.get("LOCALAPPDATA"):
        base = Path(os.environ["LOCALAPPDATA"]) / "robocal" / "cache"
    else:
        base = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "robocal"
    package = Path(__file__).resolve().parents[1] if package is None else Path(package)  # this install's robocal/
    install = hashlib.sha256(str(package).encode()).hexdigest()[:16]
    folder = base / f"compile-{install}"
    try:
        folder.mkdir(parents=True, exist_ok=True, mode=0o700)
        if folder.is_symlink() or not os.access(folder, os.W_OK):
            return None
    except OSError:
        return None
    return folder


@functools.cache
def fingerprint() -> str:
    """What a compile depends on: robocal's, numba's and Python's versions and the kernels' source."""
    import hashlib
    import platform
    from importlib.metadata import PackageNotFoundError, version
    from pathlib import Path

    from .. import __version__

    try:
        numba = version("numba")
    except PackageNotFoundError:
        numba = "none"
    here = Path(__file__).resolve().parents[1]
    parts = ("model/kernels.py", "optimize/kernels.py", "calibration/select/boost_kernels.py")
    source = b"".join((here / part).read_bytes() for part in parts if (here / part).is_file())
    return f"robocal {__version__}, numba {numba}, python {platform.python_version()}, " \
        f"kernels {hashlib.sha256(source).hexdigest()[:16]}"


def _read(path) -> str | None:
    """A record's text, never through a link; None where there is none."""
    try:
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NOFOLLOW", 0))
    except OSError:
        return None
    with os.fdopen(fd, encoding="utf-8") as f:
        return f.read().strip()


def record(folder, name: str, text: str) -> None:
    """Write a record of the compile's state folder atomically (a new file moved over the old one)."""
    import tempfile

    with tempfile.NamedTemporaryFile("w", dir=folder, delete=False, encoding="utf-8", prefix=f".{name}-") as f:
        f.write(text + "\n")
    os.replace(f.name, os.path.join(folder, name))


def _say_once(folder, message: str) -> None:
    """A compile's trouble, as a warning: once per failure record (and once per process without a folder)."""
    import warnings

    from ..exceptions import RobocalWarning

    if folder is not None:
        key = message.split(":", 1)[0]
        if _read(folder / SAID) == key:
            return
        try:
            record(folder, SAID, key)
        except OSError:
            pass
    warnings.warn(message, RobocalWarning, stacklevel=4)


def take_lock(folder) -> bool:
    """Create the compile's lock atomically (never through a link: a planted one is removed, not
    followed); a lock older than COMPILE_LOCK_S is a compile that died, and is taken over.  Whether
    this process holds it now."""
    import stat
    import time

    lock = os.path.join(folder, LOCK)
    flags = os.O_CREAT | os.O_EXCL | os.O_WRONLY | getattr(os, "O_NOFOLLOW", 0)
    for _ in range(2):
        try:
            fd = os.open(lock, flags, 0o600)
        except FileExistsError:
            try:
                st = os.lstat(lock)
                if not stat.S_ISLNK(st.st_mode) and time.time() - st.st_mtime < COMPILE_LOCK_S:
                    return False  # a compile running (or started less than COMPILE_LOCK_S ago)
                os.unlink(lock)  # a link, or a dead compile's: removed, never followed
            except FileNotFoundError:
                pass
            continue
        except OSError:
            return False
        with os.fdopen(fd, "w") as f:
            f.write(str(os.getpid()))
        return True
    return False


def compile_in_background(folder=None) -> bool:
    """Start ``python -m robocal.calibration.precompile FOLDER`` detached (its own session, no output,
    at low priority) where this process takes the compile's lock (:func:`take_lock`); whether it
    started one.  The compile records its success or its failure in ``folder`` and drops the lock."""
    import subprocess
    import sys

    folder = folder or state_folder()
    if folder is None or not take_lock(folder):
        return False
    command = [sys.executable, "-m", "robocal.calibration.precompile", str(folder)]
    if sys.platform != "win32" and _has_nice():  # beside the run that started it, not in its way
        command = ["nice", "-n", "10", *command]
    try:
        child = subprocess.Popen(command, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                                 stderr=subprocess.DEVNULL, start_new_session=True)
    except OSError as exc:
        record(folder, FAILED, f"{fingerprint()}\ncould not start it: {exc}")
        os.unlink(os.path.join(folder, LOCK))
        return False
    record(folder, "pid", str(child.pid))  # its session's id, for whoever must end it (a benchmark)
    return True


def _has_nice() -> bool:
    import shutil

    return shutil.which("nice") is not None
