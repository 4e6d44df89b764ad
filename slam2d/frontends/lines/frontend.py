"""The line frontend: scan segments matched to the global segment map; odometry where lines say nothing."""

from __future__ import annotations

import logging
from collections import Counter, deque

import numpy as np
from pydantic import Field

from slam2d import geometry
from slam2d.config import Resolution, Section
from slam2d.frontends.base import FrontendResult, register_frontend
from slam2d.frontends.common import (
    MaxSigmaThetaDeg,
    MaxSigmaXY,
    MinSigmaThetaDeg,
    MinSigmaXY,
    OdomSigmaThetaDeg,
    OdomSigmaXY,
    beyond_correction,
    bound_information,
    sigma_bounds,
)
from slam2d.frontends.gate import SimilarityGate
from slam2d.frontends.lines.extraction import (
    LineExtractionConfig,
    extract_lines,
    lines_from_grid,
)
from slam2d.frontends.lines.map import SegmentMap
from slam2d.frontends.lines.matching import LineMatchConfig, associate, match_lines
from slam2d.frontends.lines.segments import Segments
from slam2d.frontends.odometry import HeadingCalibration, odometry_information
from slam2d.types import Scan

log = logging.getLogger(__name__)

__all__ = ["LineFrontend"]


class LineFrontend:
    """Scan segments matched to the global segment map; odometry where lines say nothing."""

    class Config(Section):
        """Line frontend options: extraction, matching, map, information, gate."""

        extraction: LineExtractionConfig = LineExtractionConfig()
        matching: LineMatchConfig = LineMatchConfig()
        map_max_count: float = Field(5000.0, gt=0, description="points of evidence a map line keeps at most")
        min_seen: int = Field(2, ge=1, description="scans a map line must appear in before it is matched")
        tentative_scans: int = Field(30, ge=1, description="scans a line seen fewer than min_seen times is kept")
        map_radius: float = Field(25.0, gt=0, description="m; map lines considered around the robot")
        match_window: int = Field(0, ge=0, description="match only lines seen in the last n scans (0: all)")
        # a tight odometry prior: with a few short segments (ACES) a loose one let the match jitter by
        # centimetres and degrees from scan to scan, also while the robot stood still
        odom_sigma_xy: OdomSigmaXY = 0.02  # the prior and the fallback
        odom_sigma_theta_deg: OdomSigmaThetaDeg = 0.5
        min_sigma_xy: MinSigmaXY = 0.005
        min_sigma_theta_deg: MinSigmaThetaDeg = 0.1
        max_sigma_xy: MaxSigmaXY = 1.0
        max_sigma_theta_deg: MaxSigmaThetaDeg = 20.0
        reanchor_every: int = Field(0, ge=0, description="rebuild the map lines from a grid of recent scans every n "
                                    "scans (0: off)")
        reanchor_window: int = Field(300, gt=0, description="recent scans in that grid")
        reanchor_resolution: Resolution = Field(0.05, description="m per cell of that grid")
        gate: SimilarityGate.Config = SimilarityGate.Config(min_confidence=0.3)
        # lines correct the heading on nearly every scan; on Intel calibrating it too lowered the heading
        # error but raised the translational one
        calibration: HeadingCalibration.Config = HeadingCalibration.Config(enabled=False)

    def __init__(self, config: Config | None = None):
        self.config = cfg = config or self.Config()
        self.calibration = HeadingCalibration(cfg.calibration)
        self.map = SegmentMap(cfg.map_max_count)
        self.pose = np.zeros(3)
        self.events: Counter[str] = Counter()
        self.gate = SimilarityGate(cfg.gate)
        self.gate.events = self.events
        self.odometry_information = odometry_information(cfg.odom_sigma_xy, cfg.odom_sigma_theta_deg)
        self._min_sigma, self._max_sigma = sigma_bounds(cfg)
        self._previous: np.ndarray | None = None
        self._index = 0
        self._recent: deque = deque(maxlen=cfg.reanchor_window)

    def process(self, scan: Scan, odom_delta) -> FrontendResult:
        """Match the scan's segments to the line map, starting from the odometry guess."""
        odom_delta = self.calibration.correct(odom_delta)
        guess = geometry.compose(self.pose, odom_delta)
        segs = self.extract(scan)
        points = scan.points_in_base()
        if self._index == 0:
            result, pose = self._odometry(odom_delta), guess
        else:
            result, pose = self._match(segs, guess, odom_delta)
            if result.confidence > 0:  # a match, not already a fallback
                gated = self.gate.check(self._previous, points, result, odom_delta)
                if gated is not result:
                    result, pose = gated, guess
                else:
                    self.calibration.observe(pose, guess)
        self._commit(pose, segs, scan)
        self._previous = points
        return result

    def extract(self, scan: Scan) -> Segments:
        """Segments of ``scan`` in the base frame."""
        m = scan.hit_mask()
        return extract_lines(scan.ranges[m], scan.angles[m], self.config.extraction).segments.transformed(
            scan.sensor_pose)

    def reanchor(self, occupancy, resolution: float, origin=(0.0, 0.0), **hough) -> int:
        """Replace the map lines by those of an occupancy grid (map frame); returns their number."""
        segs = lines_from_grid(occupancy, resolution, origin, **hough)
        self.map = SegmentMap(self.config.map_max_count)
        self.map.add(segs, self._index, seen=self.config.min_seen)
        return len(segs)

    # ------------------------------------------------------------------ steps

    def _match(self, segs: Segments, guess, odom_delta) -> tuple[FrontendResult, np.ndarray]:
        cfg = self.config
        if not len(segs):
            return self._fallback("no line segments", odom_delta), guess
        near = self.map.near(guess, cfg.map_radius)
        near = near[self.map.seen[near] >= cfg.min_seen]
        if cfg.match_window:
            near = near[self._index - self.map.last_seen[near] <= cfg.match_window]
        if not len(near):
            return self._fallback("no map lines nearby", odom_delta), guess
        match = match_lines(segs, self.map.lines.subset(near), guess, self.odometry_information, cfg.matching)
        if not (match.matched >= 0).any():
            return self._fallback("no matched lines", odom_delta), guess
        if beyond_correction(guess, match.pose, cfg.matching.max_correction_xy, cfg.matching.max_correction_theta_deg):
            return self._fallback("correction beyond max_correction", odom_delta), guess
        info = bound_information(match.information + self.odometry_information, self._min_sigma, self._max_sigma)
        delta = geometry.between(self.pose, match.pose)
        return FrontendResult(delta=delta, information=info, confidence=match.confidence), match.pose

    def _commit(self, pose, segs: Segments, scan: Scan) -> None:
        """Move to ``pose``; merge the scan's segments into their map lines, add the others."""
        cfg = self.config
        self.pose = pose
        world = segs.transformed(pose)
        near = self.map.near(pose, cfg.map_radius)
        idx = associate(world, self.map.lines.subset(near), cfg.matching) if len(near) else np.full(len(world), -1)
        hit = idx >= 0
        if hit.any():
            self.map.merge(near[idx[hit]], world.subset(hit), self._index)
        self.map.add(world.subset(~hit), self._index)
        if self._index % 25 == 0:
            self.map.prune(self._index, cfg.min_seen, cfg.tentative_scans)
        self._index += 1
        if cfg.reanchor_every:
            self._recent.append((pose, scan))
            if self._index % cfg.reanchor_every == 0:
                self._reanchor_from_recent()

    def _reanchor_from_recent(self) -> None:
        from slam2d.config import MappingConfig
        from slam2d.mapping.occupancy import build_grid

        poses = np.array([p for p, _ in self._recent])
        scans = [s for _, s in self._recent]
        grid = build_grid(poses, scans, MappingConfig(resolution=self.config.reanchor_resolution))
        n = self.reanchor(grid.probability(), grid.resolution, grid.origin)
        log.debug("re-anchored the line map on %d grid lines", n)

    def _odometry(self, odom_delta) -> FrontendResult:
        return FrontendResult(delta=odom_delta.copy(), information=self.odometry_information.copy(), confidence=0.0)

    def _fallback(self, reason: str, odom_delta) -> FrontendResult:
        self.events[reason] += 1
        log.debug("lines fallback to odometry: %s", reason)
        return self._odometry(odom_delta)


register_frontend("lines")(LineFrontend)
