"""Accept a scan match or keep odometry: the frame-to-frame similarity gate.

The patrol-robot thesis (Tian 2016, section 2.3.3) trusts a laser correction
only when consecutive scans are similar (a nearest-neighbour similarity that
dips when the robot passes a doorway, enters new ground or sees heavy noise)
and the matcher's own confidence is high; otherwise it keeps odometry.

:class:`SimilarityGate` implements that decision for any frontend. The
similarity is a normalised form of the thesis's nearest-neighbour measure:
the current points are moved into the previous base frame by the match's
delta (or the odometry delta), and the similarity is the mean of the two
directed fractions of points that have a neighbour in the other scan within
``radius + range_factor * range`` metres (1 for identical scans, symmetric,
in [0, 1]). A scan is "not continuous" when its similarity is below
``min_similarity`` or below ``min_relative`` times the running typical value
(the dip at a doorway).
"""

from __future__ import annotations

import logging
from collections import Counter
from typing import Literal

import numpy as np
from pydantic import Field

from slam2d import geometry
from slam2d.config import Section
from slam2d.frontends.base import FrontendResult
from slam2d.frontends.common import OdomSigmaThetaDeg, OdomSigmaXY
from slam2d.frontends.odometry import odometry_information

log = logging.getLogger(__name__)

__all__ = ["SimilarityGate", "nn_similarity"]


def _tree(points: np.ndarray):
    from scipy.spatial import cKDTree

    return cKDTree(points, balanced_tree=False, compact_nodes=False)


def _shared_fraction(query: np.ndarray, limit: np.ndarray, tree) -> float:
    """Fraction of ``query`` points (M, 2) with a tree point within ``limit`` (M,) m."""
    dist, _ = tree.query(query, k=1, distance_upper_bound=float(limit.max()) + 1e-9)
    return float(np.mean(dist <= limit))


def nn_similarity(a: np.ndarray, b: np.ndarray, radius: float = 0.1, range_factor: float = 0.0) -> float:
    """Symmetric nearest-neighbour similarity in [0, 1] of point sets ``a`` (N, 2) and ``b`` (M, 2), metres.

    A point counts as shared when the other set has a point within
    ``radius + range_factor * |point|`` m (``|point|``: distance from the
    frame origin, which absorbs the wider beam spacing far away). The result is
    the mean of the shared fractions of ``a`` and of ``b``; 0 if either is empty.
    """
    a, b = np.asarray(a, float).reshape(-1, 2), np.asarray(b, float).reshape(-1, 2)
    if len(a) == 0 or len(b) == 0:
        return 0.0
    limit_a = radius + range_factor * np.hypot(a[:, 0], a[:, 1])
    limit_b = radius + range_factor * np.hypot(b[:, 0], b[:, 1])
    return 0.5 * (_shared_fraction(a, limit_a, _tree(b)) + _shared_fraction(b, limit_b, _tree(a)))


class SimilarityGate:
    """Accept a match when frame-to-frame similarity is normal and confidence high; else odometry.

    ``check(previous, current, result, odom_delta)`` returns ``result`` or an
    odometry fallback (odometry delta and information, confidence 0). Each
    fallback is counted in ``events`` under ``gate: <reason>``.

    The two scans are aligned by the match's own delta (``align = "match"``:
    a doorway, new ground or a wrong match all lower the overlap) or by the
    odometry delta (``"odometry"``, closer to the thesis, which then also
    rejects matches exactly where odometry slipped).
    """

    class Config(Section):
        """Gate thresholds; the thesis gives none, these suit 1-degree scans at 5-10 Hz."""

        enabled: bool = Field(True, description="False: every result passes")
        align: Literal["match", "odometry"] = Field("match", description="delta that aligns the two scans")
        radius: float = Field(0.1, gt=0, description="m; a point within this of the other scan is shared")
        range_factor: float = Field(0.02, ge=0, description="m per m of range added to radius (beam spacing)")
        min_similarity: float = Field(0.5, ge=0, le=1, description="below this the scans are not continuous")
        min_relative: float = Field(
            0.7, ge=0, le=1, description="below this fraction of the recent typical similarity is a dip"
        )
        history: int = Field(20, gt=0, description="scans in the running typical similarity (EMA span)")
        min_confidence: float = Field(0.3, ge=0, le=1, description="matches with a lower confidence are dropped")
        odom_sigma_xy: OdomSigmaXY = 0.05  # of the fallback delta
        odom_sigma_theta_deg: OdomSigmaThetaDeg = 2.0

    def __init__(self, config: Config | None = None):
        self.config = config or self.Config()
        self.events: Counter[str] = Counter()
        self.odometry_information = odometry_information(self.config.odom_sigma_xy, self.config.odom_sigma_theta_deg)
        self.typical: dict[str, float] = {}  # per source: EMA of recent similarities
        self.last_similarity: float | None = None
        self._trees: list[tuple[np.ndarray, object]] = []  # KD-trees of the last two scans

    def _tree_of(self, points: np.ndarray):
        """KD-tree of ``points`` (built once per array; the last two are kept)."""
        for pts, tree in self._trees:
            if pts is points:
                return tree
        tree = _tree(points)
        self._trees = [*self._trees[-1:], (points, tree)]
        return tree

    def similarity(self, previous: np.ndarray | None, current: np.ndarray, delta) -> float | None:
        """:func:`nn_similarity` of ``current`` and ``previous`` (each in its own base frame), aligned by ``delta``.

        ``delta`` (3,) is the current base pose in the previous base frame. None
        without a previous scan, 0 if either scan is empty.
        """
        if previous is None:
            return None
        if len(previous) == 0 or len(current) == 0:
            return 0.0
        cfg, delta = self.config, geometry.as_pose(delta)
        limit_cur = cfg.radius + cfg.range_factor * np.hypot(current[:, 0], current[:, 1])
        limit_prev = cfg.radius + cfg.range_factor * np.hypot(previous[:, 0], previous[:, 1])
        forward = _shared_fraction(geometry.transform_points(delta, current), limit_cur, self._tree_of(previous))
        backward = _shared_fraction(geometry.transform_points(geometry.inverse(delta), previous), limit_prev,
                                    self._tree_of(current))
        return 0.5 * (forward + backward)

    def continuity(self, similarity: float | None, source: str = "") -> str | None:
        """Why scans with this ``similarity`` are not continuous (too low, or a dip), else None.

        Call once per scan and ``source``: it also updates that source's running
        typical similarity (``None``, no previous scan, is continuous and changes nothing).
        """
        if similarity is None:
            return None
        cfg = self.config
        typical = self.typical.get(source)
        alpha = 2.0 / (cfg.history + 1.0)
        self.typical[source] = similarity if typical is None else (1 - alpha) * typical + alpha * similarity
        self.last_similarity = similarity
        if similarity < cfg.min_similarity:
            return "similarity below min_similarity"
        if typical is not None and similarity < cfg.min_relative * typical:
            return "similarity dip"
        return None

    def decide(self, discontinuity: str | None, result: FrontendResult, odom_delta,
               min_confidence: float | None = None, source: str = "") -> FrontendResult:
        """``result``, or the odometry fallback (counted) if the scans are discontinuous or confidence low.

        ``discontinuity`` is what :meth:`continuity` returned for this scan.
        """
        if not self.config.enabled:
            return result
        threshold = self.config.min_confidence if min_confidence is None else min_confidence
        reason = discontinuity
        if reason is None and result.confidence < threshold:
            reason = "confidence below min_confidence"
        return result if reason is None else self.fallback(reason, odom_delta, source)

    def check(self, previous: np.ndarray | None, current: np.ndarray, result: FrontendResult, odom_delta,
              min_confidence: float | None = None, source: str = "") -> FrontendResult:
        """Gate ``result`` of the scan ``current`` (base frame, (M, 2)) after ``previous`` (or None)."""
        if not self.config.enabled:
            return result
        align = result.delta if self.config.align == "match" else odom_delta
        discontinuity = self.continuity(self.similarity(previous, current, align), source)
        return self.decide(discontinuity, result, odom_delta, min_confidence, source)

    def fallback(self, reason: str, odom_delta, source: str = "") -> FrontendResult:
        """Odometry delta with the odometry information and confidence 0, counted under ``reason``."""
        key = f"gate{' ' + source if source else ''}: {reason}"
        self.events[key] += 1
        log.debug("%s", key)
        return FrontendResult(
            delta=geometry.as_pose(odom_delta).copy(), information=self.odometry_information.copy(), confidence=0.0
        )
