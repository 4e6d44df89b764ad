"""``python -m slam2d``: the slam2d command (as ``python -m slam2d.cli``)."""

from slam2d.cli import entry

entry()
