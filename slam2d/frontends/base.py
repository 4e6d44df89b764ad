"""Frontend protocol, result type and registry.

A frontend turns each scan, with the odometry delta since the previous scan,
into a :class:`FrontendResult`. It never touches GTSAM. A new frontend is one
class decorated with ``@register_frontend("name")``; other packages register
through the ``slam2d.frontends`` entry-point group.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Protocol, runtime_checkable

import numpy as np
from pydantic import BaseModel

from slam2d.registry import Registry
from slam2d.types import LandmarkObservation, Scan


@dataclass(frozen=True, eq=False)
class FrontendResult:
    """Relative base motion from the previous scan to this one.

    delta: (3,) pose of this scan's base in the previous scan's base frame.
    information: (3, 3) inverse covariance of ``delta`` (x, y, theta order).
    confidence: in [0, 1]; how much the frontend trusts ``delta``.
    landmarks: landmark observations made in this scan.
    """

    delta: np.ndarray
    information: np.ndarray
    confidence: float = 1.0
    landmarks: tuple[LandmarkObservation, ...] = field(default_factory=tuple)


@runtime_checkable
class Frontend(Protocol):
    """Optionally also an ``events`` Counter (reason -> count: fallbacks, skipped scans), reported by the run."""

    def process(self, scan: Scan, odom_delta: np.ndarray) -> FrontendResult:
        """Estimate the motion since the previous scan (``odom_delta`` for the first: zeros)."""
        ...


FRONTENDS = Registry("frontends", "frontend", key="frontend.name", options_key="frontend.options", builtins={
    "odometry": "slam2d.frontends.base",
    "icp": "slam2d.frontends.icp.frontend",
    "lines": "slam2d.frontends.lines.frontend",
    "corners": "slam2d.frontends.corners.frontend",
    "fuzzy_vertex": "slam2d.frontends.fuzzy_vertex.frontend",
    "fused": "slam2d.frontends.fused",
})
"""The frontends by name (``frontend.name``); their options are ``frontend.options``."""


def register_frontend(name: str):
    """Class decorator: make a frontend available under ``name`` in configs."""
    return FRONTENDS.register(name)


def available_frontends() -> list[str]:
    """Names of all registered frontends, built-ins and entry points included."""
    return sorted(FRONTENDS.names())


def frontend_class(name: str):
    """The class registered as ``name`` (entry points included)."""
    return FRONTENDS.get(name)


def resolve_options(name: str, options: dict[str, Any] | None = None) -> BaseModel | None:
    """The frontend's ``Config`` model filled from ``options`` (None if it takes none)."""
    return FRONTENDS.resolve_options(name, options)


def create_frontend(name: str, options: dict[str, Any] | None = None) -> Frontend:
    """Instantiate the frontend registered as ``name`` with its checked options.

    A frontend with parameters declares them as a nested pydantic ``Config``
    class and takes an instance of it as its only constructor argument.
    """
    return FRONTENDS.create(name, options)


# Odometry noise used as the pass-through frontend's information: 2 cm, 1 deg per step.
ODOMETRY_INFORMATION = np.diag([1 / 0.02**2, 1 / 0.02**2, 1 / np.deg2rad(1.0) ** 2])


@register_frontend("odometry")
class OdometryFrontend:
    """Pass-through: the wheel odometry delta is the estimate."""

    def process(self, scan: Scan, odom_delta: np.ndarray) -> FrontendResult:
        return FrontendResult(delta=np.asarray(odom_delta, float), information=ODOMETRY_INFORMATION, confidence=1.0)
