"""Frontend protocol, result type and registry.

A frontend turns each scan, with the odometry delta since the previous scan,
into a :class:`FrontendResult`. It never touches GTSAM. A new frontend is one
class decorated with ``@register_frontend("name")``; other packages register
through the ``slam2d.frontends`` entry-point group.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from importlib import import_module
from importlib.metadata import entry_points
from importlib.util import find_spec
from typing import Any, Protocol, runtime_checkable

import numpy as np
from pydantic import BaseModel, ValidationError

from slam2d.errors import InputError
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


_REGISTRY: dict[str, Callable[..., Frontend]] = {}

# Built-in frontends, imported on first use so that importing slam2d stays light.
_BUILTIN = {
    "icp": "slam2d.frontends.icp.frontend",
    "lines": "slam2d.frontends.lines.frontend",
    "corners": "slam2d.frontends.corners.frontend",
    "fuzzy_vertex": "slam2d.frontends.fuzzy_vertex.frontend",
    "fused": "slam2d.frontends.fused",
}


def register_frontend(name: str):
    """Class decorator: make a frontend available under ``name`` in configs."""

    def decorate(cls):
        _REGISTRY[name] = cls
        return cls

    return decorate


def available_frontends() -> list[str]:
    """Names of all registered frontends, built-ins and entry points included."""
    _load_entry_points()
    return sorted(set(_REGISTRY) | {n for n, m in _BUILTIN.items() if find_spec(m) is not None})


def frontend_class(name: str):
    """The class registered as ``name`` (entry points included)."""
    if name not in _REGISTRY and name in _BUILTIN and find_spec(_BUILTIN[name]) is not None:
        import_module(_BUILTIN[name])
    if name not in _REGISTRY:
        _load_entry_points()
    if name not in _REGISTRY:
        raise InputError("frontend.name", f"unknown frontend '{name}' (available: {', '.join(available_frontends())})")
    return _REGISTRY[name]


def resolve_options(name: str, options: dict[str, Any] | None = None) -> BaseModel | None:
    """The frontend's ``Config`` model filled from ``options`` (None if it takes none)."""
    cls = frontend_class(name)
    model = getattr(cls, "Config", None)
    if model is None:
        if options:
            raise InputError("frontend.options", f"frontend '{name}' takes no options, got {sorted(options)}")
        return None
    try:
        return model.model_validate(options or {})
    except ValidationError as err:
        e = err.errors()[0]
        key = "frontend.options." + ".".join(str(p) for p in e["loc"])
        what = "unknown key" if e["type"] == "extra_forbidden" else e["msg"]
        raise InputError(key, what) from None


def create_frontend(name: str, options: dict[str, Any] | None = None) -> Frontend:
    """Instantiate the frontend registered as ``name`` with its checked options.

    A frontend with parameters declares them as a nested pydantic ``Config``
    class and takes an instance of it as its only constructor argument.
    """
    cls = frontend_class(name)
    params = resolve_options(name, options)
    return cls() if params is None else cls(params)


def _load_entry_points() -> None:
    for ep in entry_points(group="slam2d.frontends"):
        if ep.name not in _REGISTRY:
            _REGISTRY[ep.name] = ep.load()


# Odometry noise used as the pass-through frontend's information: 2 cm, 1 deg per step.
ODOMETRY_INFORMATION = np.diag([1 / 0.02**2, 1 / 0.02**2, 1 / np.deg2rad(1.0) ** 2])


@register_frontend("odometry")
class OdometryFrontend:
    """Pass-through: the wheel odometry delta is the estimate."""

    def process(self, scan: Scan, odom_delta: np.ndarray) -> FrontendResult:
        return FrontendResult(delta=np.asarray(odom_delta, float), information=ODOMETRY_INFORMATION, confidence=1.0)
