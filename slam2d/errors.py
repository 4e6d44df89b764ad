"""One error type for bad input, so the CLI can print it as one clear line."""

from __future__ import annotations

import os
import reprlib
import stat
from typing import Any


class InputError(ValueError):
    """Bad input: names what is wrong and where (file and line, or config key)."""

    def __init__(self, where: str, what: str):
        self.where = str(where)
        self.what = _one_line(str(what))
        super().__init__(f"{self.where}: {self.what}")

    def __reduce__(self):
        return type(self), (self.where, self.what)


MAX_MESSAGE = 400
"""Longest ``what`` of an InputError, characters (an echoed input is cut)."""


def _one_line(text: str) -> str:
    """``text`` on one line (whitespace runs with a line break collapsed), at most MAX_MESSAGE characters."""
    if "\n" in text or "\r" in text:
        text = " ".join(text.split())
    return text if len(text) <= MAX_MESSAGE else text[: MAX_MESSAGE - 3] + "..."


def short_repr(value: Any, limit: int = 80) -> str:
    """``repr(value)`` cut to ``limit`` characters, so that an error stays one short line.

    Nested and long containers are abbreviated before they are printed (a YAML alias bomb is not expanded).
    """
    shorter = reprlib.Repr()
    shorter.maxlevel, shorter.maxstring, shorter.maxother = 3, limit, limit
    text = shorter.repr(value)
    return text if len(text) <= limit else f"{text[:limit - 3]}..."


def check_inside(key: str, point, extent, what: str = "the map") -> None:
    """InputError naming ``key`` if the point ``(x, y, ...)`` m lies outside ``extent`` (x_min, x_max, y_min, y_max)."""
    x, y = float(point[0]), float(point[1])
    x0, x1, y0, y1 = map(float, extent)
    if not (x0 <= x <= x1 and y0 <= y <= y1):
        raise InputError(key, f"({x:g}, {y:g}) is outside {what}: x from {x0:g} to {x1:g} m, y from {y0:g} to "
                         f"{y1:g} m")


def not_a_file(path) -> str | None:
    """What ``path`` is when it exists but is not a regular file ("a folder, not a file", "a named pipe
    (FIFO), not a file", "a device, not a file"); None for a file or nothing at all."""
    try:
        mode = os.stat(path).st_mode
    except (OSError, ValueError):
        return None
    if stat.S_ISREG(mode):
        return None
    kind = ("a folder" if stat.S_ISDIR(mode) else "a named pipe (FIFO)" if stat.S_ISFIFO(mode)
            else "a device" if stat.S_ISCHR(mode) or stat.S_ISBLK(mode) else "a socket" if stat.S_ISSOCK(mode)
            else "not a regular file")  # fmt: skip
    return f"{kind}, not a file"


def read_text(path) -> str:
    """The UTF-8 text of ``path``; an InputError naming it if it cannot be read, is not a regular file
    (a pipe would block, a device read as empty) or is not text."""
    if (kind := not_a_file(path)) is not None:
        raise InputError(path, kind)
    try:
        return open(path, "rb").read().decode("utf-8")
    except UnicodeDecodeError as err:
        raise InputError(path, f"not a text file (byte {err.start} is not UTF-8)") from None
    except OSError as err:
        raise InputError(path, f"cannot read ({err.strerror})") from None
