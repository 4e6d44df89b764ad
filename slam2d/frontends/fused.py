"""Fused frontend: lines, corners and ICP on every scan, combined by information.

The patrol-robot thesis (Tian 2016, section 2.1, class ``Matching``) averages
the pose components of its matchers and suggests covariance-weighted fusion
instead. Here every source's delta passes the similarity gate (with its own
confidence threshold) and the accepted ones are combined by their
information matrices on the SE(2) tangent space at the odometry guess:

    xi_i = Log(odom^-1 delta_i),  xi = (sum W_i)^-1 sum W_i xi_i,  delta = odom Exp(xi)

Each W_i is the source's information in its own delta's frame, used as is at
the odometry guess (the corrections are small, so the frames differ by
centimetres and a fraction of a degree). Each source keeps its own map and
pose and runs without its own gate; the fusion only shapes the returned
delta. When no source is accepted the odometry delta is returned (counted).

The sum of the informations would be the information of the fused delta if
the sources were independent. They are not: they see the same scan and
lines and corners also include the same odometry prior. So the reported
information is the sum divided by the number of accepted sources (their mean),
which never claims more than the most confident source alone would in the
worst case of fully correlated sources (``information_scale = "sources"``);
``"none"`` keeps the independent sum.
"""

from __future__ import annotations

import logging
from collections import Counter
from typing import Any, Literal

import numpy as np
from pydantic import Field

from slam2d import geometry
from slam2d.config import Section
from slam2d.errors import InputError
from slam2d.frontends.base import FrontendResult, create_frontend, register_frontend
from slam2d.frontends.gate import SimilarityGate
from slam2d.types import Scan

log = logging.getLogger(__name__)

__all__ = ["FusedFrontend", "fuse_deltas", "se2_log", "se2_exp"]

Source = Literal["lines", "corners", "icp"]


def _v_matrix(theta: float) -> np.ndarray:
    """The 2x2 V of SE(2) Exp: t = V(theta) v (series near theta = 0)."""
    if abs(theta) < 1e-6:
        return np.array([[1.0, -theta / 2], [theta / 2, 1.0]])
    a, b = np.sin(theta) / theta, (1 - np.cos(theta)) / theta
    return np.array([[a, -b], [b, a]])


def se2_exp(xi) -> np.ndarray:
    """Pose (x, y, theta) of the tangent vector ``xi`` = (v_x, v_y, omega) (m, m, rad)."""
    xi = np.asarray(xi, float)
    return np.r_[_v_matrix(xi[2]) @ xi[:2], geometry.wrap_angle(xi[2])]


def se2_log(pose) -> np.ndarray:
    """Tangent vector (v_x, v_y, omega) of ``pose`` (x, y, theta), inverse of :func:`se2_exp`."""
    pose = geometry.as_pose(pose)
    return np.r_[np.linalg.solve(_v_matrix(pose[2]), pose[:2]), pose[2]]


def fuse_deltas(odom_delta, deltas, informations, scale: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """Information-weighted mean of ``deltas`` (K, 3) on the tangent at ``odom_delta``; and its information.

    ``informations`` (K, 3, 3). The information returned is their sum, divided
    by K when ``scale`` (see the module note on independence).
    """
    odom_delta = geometry.as_pose(odom_delta)
    deltas = np.asarray(deltas, float).reshape(-1, 3)
    infos = np.asarray(informations, float).reshape(-1, 3, 3)
    xi = np.array([se2_log(geometry.between(odom_delta, d)) for d in deltas])  # K is 3 at most
    total = infos.sum(axis=0)
    mean = np.linalg.solve(total, np.einsum("kij,kj->i", infos, xi))
    info = total / len(deltas) if scale else total
    return geometry.compose(odom_delta, se2_exp(mean)), 0.5 * (info + info.T)


class FusedFrontend:
    """Runs lines, corners and ICP on each scan; gates each; fuses the accepted deltas by information."""

    class Config(Section):
        """Sources, their options, the gate and the information scaling."""

        sources: list[Source] = Field(["lines", "corners", "icp"], min_length=1, description="frontends to fuse")
        lines: dict[str, Any] = Field(default_factory=dict, description="options of the lines frontend")
        corners: dict[str, Any] = Field(default_factory=dict, description="options of the corners frontend")
        icp: dict[str, Any] = Field(default_factory=dict, description="options of the icp frontend")
        gate: SimilarityGate.Config = SimilarityGate.Config()
        min_confidence: dict[Source, float] = Field(
            {"lines": 0.3, "corners": 0.66, "icp": 0.3}, description="per source: lower confidence is not accepted"
        )
        information_scale: Literal["sources", "none"] = Field(
            "sources", description="divide the summed information by the number of accepted sources, or not"
        )
        weights: dict[Source, float] = Field(
            {"lines": 1.0, "corners": 1.0, "icp": 1.0},
            description="per source: its information is multiplied by this before fusing (calibration)",
        )

    def __init__(self, config: Config | None = None):
        self.config = cfg = config or self.Config()
        bad = {k: v for k, v in cfg.weights.items() if not v > 0}
        if bad:
            raise InputError("frontend.options.weights", f"weights must be > 0, got {bad}")
        if "icp" in cfg.sources:
            import slam2d.frontends.icp  # noqa: F401  (registers "icp")
        from slam2d.frontends import corners, lines  # noqa: F401  (register "lines", "corners")

        self.sources = {name: create_frontend(name, self._options(name)) for name in dict.fromkeys(cfg.sources)}
        self.gate = SimilarityGate(cfg.gate)
        self._own: Counter[str] = Counter()
        self.gate.events = self._own
        self._previous: np.ndarray | None = None

    def _options(self, name: str) -> dict[str, Any]:
        """The source's options; lines and corners run ungated (this frontend gates every source)."""
        options = dict(getattr(self.config, name))
        if name in ("lines", "corners"):
            options.setdefault("gate", {"enabled": False})
        return options

    @property
    def events(self) -> Counter:
        """Scans each source was fused on ("fused lines"), gate rejections, fallbacks, and each source's own
        events prefixed by its name."""
        out = Counter(self._own)
        for name, fe in self.sources.items():
            out.update({f"{name}: {k}": v for k, v in getattr(fe, "events", {}).items()})
        return out

    def process(self, scan: Scan, odom_delta) -> FrontendResult:
        """Every source on ``scan``; the accepted deltas fused around the odometry delta."""
        odom_delta = geometry.as_pose(odom_delta)
        results = {name: fe.process(scan, odom_delta) for name, fe in self.sources.items()}
        points, previous = scan.points_in_base(), self._previous
        self._previous = points
        if previous is None:
            return next(iter(results.values()))
        accepted = {}
        for name, res in results.items():
            if res.confidence <= 0:  # the source fell back to odometry itself
                continue
            if self.gate.check(previous, points, res, odom_delta, self.config.min_confidence.get(name), name) is res:
                accepted[name] = res
        if not accepted:
            return self._fallback("no source accepted", odom_delta)
        self._own.update(f"fused {name}" for name in accepted)
        weights = [self.config.weights.get(name, 1.0) for name in accepted]
        delta, info = fuse_deltas(odom_delta, [r.delta for r in accepted.values()],
                                  [w * r.information for w, r in zip(weights, accepted.values())],
                                  scale=self.config.information_scale == "sources")
        landmarks = tuple(obs for r in accepted.values() for obs in r.landmarks)
        confidence = float(np.mean([r.confidence for r in accepted.values()]))
        return FrontendResult(delta=delta, information=info, confidence=confidence, landmarks=landmarks)

    def _fallback(self, reason: str, odom_delta) -> FrontendResult:
        self._own[reason] += 1
        return FrontendResult(delta=odom_delta.copy(), information=self.gate.odometry_information.copy(),
                              confidence=0.0)


register_frontend("fused")(FusedFrontend)
