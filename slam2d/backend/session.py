"""What a SLAM session leaves to go on from: its graph, its keyframes' scans, every scan's place.

A :class:`Session` is the pose-graph back end's state after its final
optimisation, as arrays (the runs layer saves them as ``session.npz`` beside
``graph.g2o``): keyframe poses and the distance travelled at each, the graph's
odometry and loop edges with their information, the loops that pin their pair
in the loop closer's path lengths, the back end's motion since the last
keyframe, and for every scan its stamp, odometry, mounting pose, ground truth,
keyframe and pose in that keyframe's frame. The ranges are kept for the
keyframes' first scans (the map and the loop closer are made of them) and the
last scan (the frontend starts from it); the other scans keep their place only.

Poses are ``(x, y, theta)`` (m, m, rad); information matrices 3x3 inverse covariances.
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

from slam2d.errors import InputError
from slam2d.types import Scan

ODOMETRY, LOOP = 0, 1  # edge kinds
VERSION = 1  # of the arrays' layout


@dataclass(frozen=True, eq=False)
class Session:
    """A saved SLAM session (see the module docstring); K keyframes, E edges, N scans, B kept beams."""

    keyframe_poses: np.ndarray  # (K, 3)
    travelled: np.ndarray  # (K,) m travelled when each keyframe was taken
    edge_kind: np.ndarray  # (E,) ODOMETRY or LOOP
    edge_ij: np.ndarray  # (E, 2) keyframes: the measurement is j's pose in i's frame
    edge_delta: np.ndarray  # (E, 3)
    edge_information: np.ndarray  # (E, 3, 3)
    edge_pinned: np.ndarray  # (E,) bool: a loop that pins its pair (LoopCloser.pin)
    tail: np.ndarray  # (14,) motion since the last keyframe (3), its covariance (9), m travelled, loop searches
    stamp: np.ndarray  # (N,) s
    odom: np.ndarray  # (N, 3)
    sensor_pose: np.ndarray  # (N, 3)
    ground_truth: np.ndarray  # (N, 3), NaN where unknown
    range_limits: np.ndarray  # (N, 2) m: range_min, range_max
    keyframe: np.ndarray  # (N,) keyframe each scan hangs off
    offset: np.ndarray  # (N, 3) scan pose in its keyframe's frame
    beams: np.ndarray  # (N,) ranges kept per scan (0: none)
    ranges: np.ndarray  # (B,) m, the kept scans' ranges one after another
    angles: np.ndarray  # (B,) rad

    def __len__(self) -> int:
        """Scans of the session."""
        return len(self.stamp)

    @property
    def num_keyframes(self) -> int:
        return len(self.keyframe_poses)

    def scans(self) -> list[Scan]:
        """Every scan of the session; those whose ranges were not kept have none."""
        ends = np.cumsum(self.beams)
        starts = ends - self.beams
        truth = [None if np.isnan(g).any() else g for g in self.ground_truth]
        return [Scan(stamp=float(t), ranges=self.ranges[a:b], angles=self.angles[a:b], range_min=float(lim[0]),
                     range_max=float(lim[1]), sensor_pose=m, odom=o, ground_truth=g, index=n)
                for n, (t, a, b, lim, m, o, g) in enumerate(zip(self.stamp, starts, ends, self.range_limits,
                                                                 self.sensor_pose, self.odom, truth))]  # fmt: skip

    def keyframe_scans(self) -> np.ndarray:
        """Index (K,) of each keyframe's first scan (the scan that made it)."""
        first = np.full(self.num_keyframes, -1)
        first[self.keyframe[::-1]] = np.arange(len(self))[::-1]
        return first

    def arrays(self) -> dict[str, np.ndarray]:
        """The session as named arrays (``np.savez``), with the layout's version."""
        return {f.name: getattr(self, f.name) for f in fields(self)} | {"version": np.array(VERSION)}

    @classmethod
    def from_arrays(cls, arrays, where: str = "session") -> Session:
        """The session of :meth:`arrays`'s output; an InputError naming ``where`` if it does not fit."""
        names = [f.name for f in fields(cls)]
        missing = [n for n in [*names, "version"] if n not in arrays]
        if missing:
            raise InputError(where, f"not a slam2d session: no {missing[0]!r}")
        if int(arrays["version"]) != VERSION:
            raise InputError(where, f"session layout {int(arrays['version'])}, this slam2d reads {VERSION}")
        session = cls(**{n: np.asarray(arrays[n]) for n in names})
        session.check(where)
        return session

    def check(self, where: str = "session") -> None:
        """InputError naming ``where`` unless the arrays' shapes and references agree."""
        k, e, n = self.num_keyframes, len(self.edge_kind), len(self)
        shapes = {
            "keyframe_poses": (k, 3), "travelled": (k,), "edge_ij": (e, 2), "edge_delta": (e, 3),
            "edge_information": (e, 3, 3), "edge_pinned": (e,), "tail": (14,), "odom": (n, 3),
            "sensor_pose": (n, 3), "ground_truth": (n, 3), "range_limits": (n, 2), "keyframe": (n,),
            "offset": (n, 3), "beams": (n,), "angles": self.ranges.shape,
        }  # fmt: skip
        for name, shape in shapes.items():
            if getattr(self, name).shape != shape:
                raise InputError(where, f"{name} has shape {getattr(self, name).shape}, expected {shape}")
        if k == 0 or n == 0:
            raise InputError(where, "a session needs a keyframe and a scan")
        if self.edge_ij.size and (self.edge_ij.min() < 0 or self.edge_ij.max() >= k):
            raise InputError(where, "an edge names a keyframe the session does not hold")
        if self.keyframe.min() < 0 or self.keyframe.max() >= k or np.any(np.diff(self.keyframe) < 0):
            raise InputError(where, "scans' keyframes out of range or out of order")
        if int(self.beams.sum()) != len(self.ranges) or self.beams.min() < 0:
            raise InputError(where, "kept beams do not add up to the ranges")
        if np.any(self.beams[self.keyframe_scans()] == 0) or self.beams[-1] == 0:
            raise InputError(where, "a keyframe's scan or the last scan has no ranges")
        odometry_into = self.edge_ij[self.edge_kind == ODOMETRY, 1]
        if sorted(odometry_into.tolist()) != list(range(1, k)):
            raise InputError(where, "every keyframe after the first needs one odometry edge into it")
