"""The slam2d command line. The app and what every command shares are in :mod:`slam2d.cli.common`; the
commands register on it from :mod:`slam2d.cli.experiments` and :mod:`slam2d.cli.tools`."""

from __future__ import annotations

import logging

from slam2d.cli import experiments, tools  # noqa: F401 (importing them registers their commands)
from slam2d.cli.common import app

__all__ = ["app", "main"]


def main() -> None:
    """The ``slam2d`` command. A stopped command exits 130 (SIGINT) or 143 (SIGTERM) at once (its clean-up
    is done): letting the interpreter finish could end the process as by SIGINT instead, when the interrupt arrived
    in code CPython itself ran (it then re-raises the signal at exit)."""
    import os
    import sys

    try:
        app()
    except SystemExit as done:
        if done.code not in (130, 143):
            raise
        logging.shutdown()
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(done.code)
