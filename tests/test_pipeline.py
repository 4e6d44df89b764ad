"""The pipeline's frontend worker process: same results as one process, errors, logs and counts."""

from __future__ import annotations

import logging
from collections import Counter

import numpy as np
import pytest

from slam2d import config
from slam2d.datasets.base import ScanSource
from slam2d.datasets.registry import open_dataset
from slam2d.errors import InputError
from slam2d.frontends import FrontendResult, register_frontend
from slam2d.pipeline import SlamPipeline, can_fork
from slam2d.types import Scan

pytestmark = pytest.mark.skipif(not can_fork(), reason="no fork start method on this platform")


def run(*overrides, source=None):
    cfg = config.load(None, list(overrides))
    return SlamPipeline(cfg).run(source if source is not None else open_dataset(cfg.dataset, seed=cfg.seed))


def test_worker_gives_the_single_process_result():
    args = ("dataset.max_scans=400", "backend.name=pose_graph")
    parallel, single = run(*args, "parallel=true"), run(*args, "parallel=false")
    assert np.array_equal(parallel.poses, single.poses)
    assert parallel.stats == single.stats
    assert parallel.stats["loop closures added"] > 0
    assert parallel.cpu_s > 0


@register_frontend("fails_at_scan_5")
class FailsAtScan5:
    """Odometry that logs a warning on scan 3 and raises an InputError on scan 5."""

    def __init__(self, config=None):
        self.events: Counter[str] = Counter()

    def process(self, scan, odom_delta):
        self.events["calls"] += 1
        if scan.index == 3:
            logging.getLogger("slam2d.test").warning("scan 3 looked odd")
        if scan.index == 5:
            raise InputError(f"scan {scan.index}", "unreadable")
        return FrontendResult(delta=np.asarray(odom_delta, float), information=np.eye(3), confidence=1.0)


def test_worker_error_is_raised_with_its_type_and_logs_reach_the_parent():
    records = []
    handler = logging.Handler(logging.WARNING)
    handler.emit = records.append
    logger = logging.getLogger("slam2d")
    propagate, logger.propagate = logger.propagate, False  # as the command line sets it
    logger.addHandler(handler)
    try:
        with pytest.raises(InputError, match="scan 5: unreadable"):
            run("dataset.max_scans=20", "frontend.name=fails_at_scan_5", "parallel=true")
    finally:
        logger.removeHandler(handler)
        logger.propagate = propagate
    assert [r.getMessage() for r in records if r.name == "slam2d.test"] == ["scan 3 looked odd"]


class WithEmptyScans(ScanSource):
    """Ten scans of a flat wall; every third has no valid beam (skipped by the checks)."""

    name = "with-empty"

    def __len__(self) -> int:
        return 10

    def _raw_scans(self):
        angles = np.linspace(-1.0, 1.0, 50)
        for k in range(10):
            ranges = np.full(50, np.nan) if k % 3 == 2 else 2.0 / np.cos(angles)
            yield Scan(stamp=float(k), ranges=ranges, angles=angles, range_min=0.1, range_max=10.0,
                       odom=np.array([0.1 * k, 0.0, 0.0]))


def test_reader_counts_come_back_from_the_worker():
    source = WithEmptyScans()
    source.max_skipped = 0.5  # three of ten are skipped on purpose
    result = run("frontend.name=odometry", "backend.name=none", "parallel=true", source=source)
    assert len(result.poses) == 7
    assert result.skipped["empty scans (no valid beam)"] == 3
    assert source.skipped == result.skipped
    assert source.invalid_beams == 150
