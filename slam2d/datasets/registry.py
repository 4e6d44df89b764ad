"""Dataset config -> ScanSource (the reader ``dataset.kind`` names, :data:`slam2d.datasets.base.DATASETS`);
where data files are looked up."""

from __future__ import annotations

import os
from pathlib import Path

from slam2d.config import DatasetConfig
from slam2d.datasets.base import DATASETS, ScanSource
from slam2d.errors import InputError

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


def log_path(cfg: DatasetConfig) -> Path:
    """The existing log file ``dataset.path`` names (for the readers of files)."""
    if cfg.path is None:
        raise InputError("dataset.path", f"a '{cfg.kind}' dataset needs a path")
    return resolve_data_path(cfg.path)


def open_dataset(cfg: DatasetConfig, seed: int = 0) -> ScanSource:
    """The ScanSource a dataset config names, allowed to skip ``cfg.max_skipped`` of its scans."""
    source = DATASETS.create(cfg.kind, None, cfg, seed)
    source.max_skipped = cfg.max_skipped
    return source
