"""``python -m slam2d.cli``: the slam2d command."""

from slam2d.cli import entry

entry()
