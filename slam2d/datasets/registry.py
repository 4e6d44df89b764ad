"""Dataset config -> ScanSource (the reader ``dataset.kind`` names, :data:`slam2d.datasets.base.DATASETS`);
where data files are looked up."""

from __future__ import annotations

from pathlib import Path

from slam2d.config import DatasetConfig
from slam2d.datasets.base import DATASETS, ScanSource
from slam2d.errors import InputError
from slam2d.paths import resolve_data_path


def log_path(cfg: DatasetConfig) -> Path:
    """The existing log file ``dataset.path`` names (for the readers of files)."""
    if cfg.path is None:
        raise InputError("dataset.path", f"a '{cfg.kind}' dataset needs a path")
    return resolve_data_path(cfg.path)


def open_dataset(cfg: DatasetConfig, seed: int = 0) -> ScanSource:
    """The ScanSource a dataset config names, from scan ``cfg.first_scan`` on, allowed to skip
    ``cfg.max_skipped`` of its scans."""
    if cfg.first_scan and cfg.max_scans is not None:  # the readers stop after max_scans of the whole log
        cfg = cfg.model_copy(update={"max_scans": cfg.first_scan + cfg.max_scans})
    source = DATASETS.create(cfg.kind, None, cfg, seed)
    source.max_skipped = cfg.max_skipped
    source.first_scan = cfg.first_scan
    return source
