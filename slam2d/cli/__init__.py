"""The slam2d command line. The app and what every command shares are in :mod:`slam2d.cli.common`; the
commands register on it from :mod:`slam2d.cli.experiments` and :mod:`slam2d.cli.tools`."""

from __future__ import annotations

import logging

from slam2d.cli import experiments, tools  # noqa: F401 (importing them registers their commands)
from slam2d.cli.common import STOPPED_CODES, app

__all__ = ["app", "entry", "main"]


def main() -> None:
    """The ``slam2d`` command. A stopped command exits 130 (SIGINT) or 143 (SIGTERM) at once (its clean-up is
    done): letting the interpreter finish could end the process as by SIGINT instead, when the interrupt arrived
    in code CPython itself ran (it then re-raises the signal at exit)."""
    import os
    import sys

    try:
        app()
    except SystemExit as done:
        if done.code not in STOPPED_CODES:
            raise
        logging.shutdown()
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(done.code)


def entry() -> None:
    """``slam2d`` as a program (the console script, ``python -m slam2d``, ``python -m slam2d.cli``): ``main``,
    then, once the command has ended and no other thread runs, the process exits with the command's code at once:
    its exit functions run (the log's handlers flushed and closed) and its streams are flushed, but the
    interpreter's teardown of numpy's, scipy's and gtsam's modules, which took 0.7-0.8 s after ``slam2d
    optimize`` on M3500 on a loaded machine (0.02-0.03 s without it), is skipped. ``main`` alone, as tests and
    benchmarks call it, exits as usual."""
    import atexit
    import os
    import sys
    import threading

    try:
        main()
        code = 0
    except SystemExit as done:
        code = done.code
    if not (code is None or isinstance(code, int)) or threading.active_count() > 1:
        sys.exit(code)  # a message to print, or threads to wait for: the usual exit
    atexit._run_exitfuncs()
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):
            pass
    os._exit(code or 0)
