"""What a back end is (the Protocol) and the back ends by name (``backend.name``)."""

from __future__ import annotations

from typing import Any, Protocol

import numpy as np

from slam2d.registry import Registry


class Backend(Protocol):
    """Turns the frontend's results, scan by scan, into a pose for every scan. Built from the
    ``backend`` config section; ``graph``: its pose graph (written as ``graph.g2o``), or None."""

    graph: Any

    def add(self, scan, result) -> None:
        """Take one scan and its :class:`slam2d.frontends.base.FrontendResult`."""
        ...

    def finish(self) -> np.ndarray:
        """Poses (N, 3) of every scan added, after any final optimisation."""
        ...

    def current_pose(self) -> np.ndarray:
        """Pose (3,) of the latest scan."""
        ...

    def scan_anchors(self, start: int = 0) -> tuple[np.ndarray, np.ndarray]:
        """Keyframe key (M,) and pose in that keyframe's frame (M, 3) of scans ``start`` onwards."""
        ...

    def summary(self) -> dict[str, int]:
        """Counts reported by the run (keyframes, loop closures)."""
        ...


BACKENDS = Registry("backends", "back end", key="backend.name", builtins={
    "none": "slam2d.backend.chain",
    "pose_graph": "slam2d.backend.slam",
})
"""The back ends by name (``backend.name``); each is built from the ``backend`` section."""


def register_backend(name: str, **kw):
    """Decorator of a :class:`Backend` class taking the ``backend`` config section: ``backend.name: name``."""
    return BACKENDS.register(name, **kw)
