"""One error type for bad input, so the CLI can print it as one clear line."""

from __future__ import annotations


class InputError(ValueError):
    """Bad input: names what is wrong and where (file and line, or config key)."""

    def __init__(self, where: str, what: str):
        self.where = str(where)
        self.what = what
        super().__init__(f"{self.where}: {what}")

    def __reduce__(self):
        return type(self), (self.where, self.what)
