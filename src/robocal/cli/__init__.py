"""The ``robocal`` command line: a thin layer over the Python API.

Each command parses its options, builds the API's configuration (which validates every
value, once), calls the API and prints.  Bad input never produces a traceback: an
:class:`~robocal.exceptions.InputError` or a command-line misuse becomes one line on
stderr and exit code 2.  Heavy modules are imported inside the commands, so ``robocal
--help`` starts fast.
"""

from .app import app, main, run

__all__ = ["app", "main", "run"]
