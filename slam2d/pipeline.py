"""SlamPipeline: scans -> frontend -> back end -> poses for every scan."""

from __future__ import annotations

import time
from collections import Counter
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from slam2d import geometry
from slam2d.config import ExperimentConfig
from slam2d.errors import InputError
from slam2d.frontends import create_frontend
from slam2d.frontends.base import FrontendResult
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
    cpu_s: float  # process CPU time of the run (reading, frontend, back end)
    skipped: Counter = field(default_factory=Counter)
    stats: dict[str, Any] = field(default_factory=dict)
    graph: Any = None  # the PoseGraph when the back end is 'pose_graph'

    @property
    def fallbacks(self) -> int:
        """Scans after the first answered with confidence 0 (the frontend returned odometry)."""
        return int(np.count_nonzero(self.confidences[1:] <= 0.0))


class ChainBackend:
    """Back end 'none': the frontend's deltas chained from the first odometry pose."""

    graph = None

    def __init__(self) -> None:
        self.poses: list[np.ndarray] = []

    def add(self, scan: Scan, result: FrontendResult) -> None:
        pose = scan.odom if not self.poses else geometry.compose(self.poses[-1], result.delta)
        self.poses.append(np.asarray(pose, float))

    def finish(self) -> np.ndarray:
        return np.array(self.poses)

    def summary(self) -> dict[str, int]:
        return {}


class SlamPipeline:
    """Runs the configured frontend and back end over a scan stream."""

    def __init__(self, cfg: ExperimentConfig):
        self.cfg = cfg
        self.frontend = create_frontend(cfg.frontend.name, cfg.frontend.options)
        if cfg.backend.name == "pose_graph":
            from slam2d.backend.slam import GraphSlamBackend

            self.backend = GraphSlamBackend(cfg.backend)
        else:
            self.backend = ChainBackend()

    def run(self, scans: Iterable[Scan], on_scan: Callable[[], None] | None = None) -> SlamResult:
        """Process every scan; ``on_scan`` is called after each one (progress)."""
        t0 = time.process_time()
        kept: list[Scan] = []
        confidences = []
        for scan in scans:
            odom_delta = np.zeros(3) if not kept else geometry.between(kept[-1].odom, scan.odom)
            result = self.frontend.process(scan, odom_delta)
            self.backend.add(scan, result)
            confidences.append(result.confidence)
            kept.append(scan)
            if on_scan:
                on_scan()
        if not kept:
            skipped = dict(getattr(scans, "skipped", {}))
            raise InputError(getattr(scans, "name", "dataset"), f"no usable scan (skipped: {skipped})")
        poses = self.backend.finish()
        gts = [s.ground_truth for s in kept]
        stats = dict(self.backend.summary())
        stats.update({f"frontend {k}": v for k, v in getattr(self.frontend, "events", {}).items()})
        return SlamResult(
            scans=kept,
            stamps=np.array([s.stamp for s in kept]),
            poses=poses,
            odometry=np.array([s.odom for s in kept]),
            ground_truth=None if any(g is None for g in gts) else np.array(gts),
            confidences=np.array(confidences),
            cpu_s=time.process_time() - t0,
            skipped=Counter(getattr(scans, "skipped", {})),
            stats=stats,
            graph=self.backend.graph,
        )
