"""SlamPipeline: scans -> frontend -> (back end) -> poses for every scan."""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field

import numpy as np

from slam2d import geometry
from slam2d.config import ExperimentConfig
from slam2d.errors import InputError
from slam2d.frontends import create_frontend
from slam2d.types import Scan


@dataclass
class SlamResult:
    """Poses for every scan: ``stamps`` (N,), estimate/odometry/ground truth (N, 3)."""

    scans: list[Scan]
    stamps: np.ndarray
    poses: np.ndarray
    odometry: np.ndarray
    ground_truth: np.ndarray | None
    confidences: np.ndarray
    skipped: Counter = field(default_factory=Counter)


class SlamPipeline:
    """Runs the configured frontend over a scan stream and chains its deltas."""

    def __init__(self, cfg: ExperimentConfig):
        self.cfg = cfg
        self.frontend = create_frontend(cfg.frontend.name, cfg.frontend.options)

    def run(self, scans: Iterable[Scan], on_scan: Callable[[], None] | None = None) -> SlamResult:
        """Process every scan; ``on_scan`` is called after each one (progress)."""
        kept: list[Scan] = []
        poses, confidences = [], []
        prev: Scan | None = None
        for scan in scans:
            odom_delta = np.zeros(3) if prev is None else geometry.between(prev.odom, scan.odom)
            result = self.frontend.process(scan, odom_delta)
            pose = scan.odom if prev is None else geometry.compose(poses[-1], result.delta)
            poses.append(np.asarray(pose, float))
            confidences.append(result.confidence)
            kept.append(scan)
            prev = scan
            if on_scan:
                on_scan()
        if not kept:
            raise InputError(getattr(scans, "name", "dataset"), f"no usable scan (skipped: {dict(getattr(scans, 'skipped', {}))})")
        gts = [s.ground_truth for s in kept]
        return SlamResult(
            scans=kept,
            stamps=np.array([s.stamp for s in kept]),
            poses=np.array(poses),
            odometry=np.array([s.odom for s in kept]),
            ground_truth=None if any(g is None for g in gts) else np.array(gts),
            confidences=np.array(confidences),
            skipped=Counter(getattr(scans, "skipped", {})),
        )
