"""Dataset config -> ScanSource; where data files are looked up."""

from __future__ import annotations

import os
from pathlib import Path

from slam2d.config import DatasetConfig
from slam2d.datasets.base import ScanSource
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


def open_dataset(cfg: DatasetConfig, seed: int = 0) -> ScanSource:
    """The ScanSource a dataset config names, allowed to skip ``cfg.max_skipped`` of its scans."""
    source = _open(cfg, seed)
    source.max_skipped = cfg.max_skipped
    return source


def _open(cfg: DatasetConfig, seed: int) -> ScanSource:
    if cfg.kind == "simulator":
        from slam2d.datasets.simulator import SimulatorSource

        return SimulatorSource(cfg.simulator, seed=seed, max_scans=cfg.max_scans)
    if cfg.path is None:
        raise InputError("dataset.path", f"a '{cfg.kind}' dataset needs a path")
    path = resolve_data_path(cfg.path)
    if cfg.kind == "rosbag":
        from slam2d.datasets.rosbag import RosbagSource

        return RosbagSource(path, scan_topic=cfg.scan_topic, odom_topic=cfg.odom_topic, max_scans=cfg.max_scans)
    from slam2d.datasets.carmen import CarmenSource

    return CarmenSource(path, max_scans=cfg.max_scans)
