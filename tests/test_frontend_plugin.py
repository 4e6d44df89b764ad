"""A frontend written in one class, registered by name and run through the pipeline."""

import numpy as np
import pytest
from pydantic import Field

from slam2d import config
from slam2d.config import Section
from slam2d.datasets.registry import open_dataset
from slam2d.errors import InputError
from slam2d.frontends import FrontendResult, available_frontends, register_frontend
from slam2d.pipeline import SlamPipeline


@register_frontend("scaled_odometry")
class ScaledOdometry:
    """Odometry with a calibrated translation scale (the example of docs/frontends.md)."""

    class Config(Section):
        scale: float = Field(1.0, gt=0)
        sigma_xy: float = Field(0.05, gt=0)

    def __init__(self, config: Config):
        self.config = config

    def process(self, scan, odom_delta):
        delta = np.array([odom_delta[0] * self.config.scale, odom_delta[1] * self.config.scale, odom_delta[2]])
        info = np.diag([self.config.sigma_xy**-2, self.config.sigma_xy**-2, 1 / np.deg2rad(2) ** 2])
        return FrontendResult(delta=delta, information=info, confidence=1.0)


def run(options):
    cfg = config.load(None, ["dataset.max_scans=50", "frontend.name=scaled_odometry", "backend.name=none"])
    cfg.frontend.options = options
    pipeline = SlamPipeline(cfg)
    return pipeline, pipeline.run(open_dataset(cfg.dataset, seed=cfg.seed))


def test_registered_frontend_runs_by_name():
    assert "scaled_odometry" in available_frontends()
    _, result = run({"scale": 2.0})
    assert len(result.poses) == 50
    odo_len = np.linalg.norm(np.diff(result.odometry[:, :2], axis=0), axis=1).sum()
    est_len = np.linalg.norm(np.diff(result.poses[:, :2], axis=0), axis=1).sum()
    assert est_len == pytest.approx(2.0 * odo_len, rel=1e-9)


def test_unknown_frontend_option_named():
    with pytest.raises(InputError, match="frontend.options.scael: unknown key"):
        run({"scael": 2.0})


def test_unknown_frontend_name_lists_available():
    cfg = config.load(None, ["frontend.name=nope"])
    with pytest.raises(InputError, match="unknown frontend 'nope'.*odometry"):
        SlamPipeline(cfg)


@register_frontend("every_third_fails")
class EveryThirdFails:
    """Odometry, but every third scan is answered with confidence 0 and counted as an event."""

    def __init__(self, config=None):
        from collections import Counter

        self.events, self.calls = Counter(), 0

    def process(self, scan, odom_delta):
        self.calls += 1
        failed = self.calls % 3 == 0
        if failed:
            self.events["stub failure"] += 1
        return FrontendResult(delta=np.asarray(odom_delta, float), information=np.eye(3), confidence=0.0 if failed else 1.0)


def test_frontend_events_and_fallbacks_reported():
    cfg = config.load(None, ["dataset.max_scans=30", "frontend.name=every_third_fails", "backend.name=none"])
    result = SlamPipeline(cfg).run(open_dataset(cfg.dataset, seed=cfg.seed))
    assert result.stats["frontend stub failure"] == 10
    assert result.fallbacks == 10  # scans 3, 6, ..., 30
    assert result.cpu_s > 0
