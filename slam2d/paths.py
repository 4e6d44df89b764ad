"""Where data files are found: as given, else under ``SLAM2D_DATA`` (default ``../shared/datasets``)."""

from __future__ import annotations

import os
from pathlib import Path

from slam2d.errors import InputError

__all__ = ["DEFAULT_DATA_ROOT", "data_root", "resolve_data_path", "find_data_path"]

DEFAULT_DATA_ROOT = Path("../shared/datasets")


def data_root() -> Path:
    """Folder that relative dataset paths resolve against: $SLAM2D_DATA or ../shared/datasets."""
    return Path(os.environ.get("SLAM2D_DATA", DEFAULT_DATA_ROOT))


def resolve_data_path(path: str | Path, key: str = "dataset.path") -> Path:
    """An existing file: ``path`` as given, else under :func:`data_root`."""
    p = Path(path).expanduser()
    for candidate in (p, data_root() / p):
        if candidate.exists():
            return candidate
    raise InputError(key, f"file not found: {path} (looked here and under SLAM2D_DATA={data_root()})")


def find_data_path(path: str | Path) -> Path:
    """``path`` as given if it exists, else under :func:`data_root` if it exists there, else as given."""
    p = Path(path).expanduser()
    return p if p.exists() or not (data_root() / p).exists() else data_root() / p
