"""Memory ceilings: a one-line refusal before a big allocation, instead of the out-of-memory killer."""

from __future__ import annotations

import os

from slam2d.errors import InputError

MAX_MEMORY_ENV = "SLAM2D_MAX_MEMORY_GB"
"""Environment variable: a ceiling (GB) below the memory the system has available."""


def available_bytes() -> tuple[float, str] | None:
    """(bytes a new allocation may take, where that figure comes from), or None if unknown: the
    system's available memory (Linux ``MemAvailable``) or :data:`MAX_MEMORY_ENV`, the smaller."""
    known = []
    try:
        with open("/proc/meminfo", "rb") as meminfo:
            for line in meminfo:
                if line.startswith(b"MemAvailable:"):
                    known.append((int(line.split()[1]) * 1024.0, "available memory"))
    except (OSError, ValueError, IndexError):
        pass
    ceiling = os.environ.get(MAX_MEMORY_ENV)
    if ceiling:
        try:
            known.append((float(ceiling) * 1e9, MAX_MEMORY_ENV))
        except ValueError:
            raise InputError(MAX_MEMORY_ENV, f"expected a number of GB, got {ceiling[:40]!r}") from None
    return min(known) if known else None


def check_memory(nbytes: float, key: str, what: str) -> None:
    """InputError naming ``key`` if ``what`` (e.g. "a 1000 x 1000 map grid") needing ``nbytes`` would not fit."""
    limit = available_bytes()
    if limit is not None and nbytes > limit[0]:
        raise InputError(key, f"{what} would need {_gb(nbytes)} of memory, more than the {_gb(limit[0])} of "
                         f"{limit[1]}")


def _gb(nbytes: float) -> str:
    return f"{nbytes / 1e9:.3g} GB"
