"""SlamPipeline: scans -> frontend -> back end -> poses for every scan."""

from __future__ import annotations

import queue
import threading
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
    skipped: Counter = field(default_factory=Counter)
    stats: dict[str, Any] = field(default_factory=dict)
    graph: Any = None  # the PoseGraph when the back end is 'pose_graph'


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


class _BackendThread:
    """Feeds a back end from a worker thread, in order, so that the frontend and
    the back end (loop closing) overlap on two cores; the compiled kernels, the
    k-d trees and the bag decompression release the GIL. Leaving the ``with``
    block waits for the queue to drain and re-raises the worker's error."""

    QUEUE = 256  # scans buffered ahead of the back end

    def __init__(self, backend) -> None:
        self.backend = backend
        self._queue: queue.Queue = queue.Queue(maxsize=self.QUEUE)
        self._error: BaseException | None = None
        self._thread = threading.Thread(target=self._work, name="slam2d-backend", daemon=True)

    def __enter__(self) -> _BackendThread:
        self._thread.start()
        return self

    def add(self, scan: Scan, result: FrontendResult) -> None:
        if self._error is not None:
            raise self._error
        self._queue.put((scan, result))

    def _work(self) -> None:
        while (item := self._queue.get()) is not None:
            if self._error is None:
                try:
                    self.backend.add(*item)
                except BaseException as err:  # re-raised in the caller's thread
                    self._error = err

    def __exit__(self, *exc) -> None:
        self._queue.put(None)
        self._thread.join()
        if self._error is not None and exc[0] is None:
            raise self._error


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
        kept: list[Scan] = []
        confidences = []
        with _BackendThread(self.backend) as backend:
            for scan in scans:
                odom_delta = np.zeros(3) if not kept else geometry.between(kept[-1].odom, scan.odom)
                result = self.frontend.process(scan, odom_delta)
                backend.add(scan, result)
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
        stats.update({f"frontend {k}": v for k, v in getattr(self.frontend, "fallbacks", {}).items()})
        if getattr(self.frontend, "still", 0):
            stats["frontend scans not registered (no motion)"] = self.frontend.still
        return SlamResult(
            scans=kept,
            stamps=np.array([s.stamp for s in kept]),
            poses=poses,
            odometry=np.array([s.odom for s in kept]),
            ground_truth=None if any(g is None for g in gts) else np.array(gts),
            confidences=np.array(confidences),
            skipped=Counter(getattr(scans, "skipped", {})),
            stats=stats,
            graph=self.backend.graph,
        )
