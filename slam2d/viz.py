"""Live view of a SLAM run in the rerun viewer (``slam2d run --viz`` or ``--viz-save FILE.rrd``).

Needs the ``[viz]`` extra (``rerun-sdk``); nothing here is imported unless a view is asked for.
Entities, in the map frame (m), on the timelines ``scan`` (scan index) and ``time`` (s since the
first scan):

- ``world/scan``: the latest scan's hits at the current estimate (Points2D), every scan;
- ``world/robot``: the current pose estimate, an arrow along the heading (Arrows2D), every scan;
- ``world/trajectory``: the keyframe estimates (LineStrips2D), with each map refresh, and at the
  end (scan index N for N scans) every scan's optimised pose;
- ``world/loops``: one segment per loop closure between its keyframe estimates (LineStrips2D),
  whenever the graph's loops change;
- ``world/map``: centres of the occupied cells of the grid at the current keyframe estimates
  (Points2D), every ``MAP_EVERY`` scans and once more after the final optimisation.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from slam2d import geometry
from slam2d.config import MappingConfig
from slam2d.errors import InputError
from slam2d.types import Scan

MAP_EVERY = 25
"""Scans between two refreshes of the map and the keyframe trajectory."""
ARROW_M = 0.5
"""Length of the robot's heading arrow, m."""
ENTITIES = ("world/scan", "world/robot", "world/trajectory", "world/loops", "world/map")


def open_view(target: str | Path, name: str, mapping: MappingConfig) -> LiveView:
    """A view streaming to a spawned (or already running) viewer when ``target`` is ``"viewer"``,
    else recording to the ``.rrd`` file ``target``."""
    try:
        import rerun as rr
    except ImportError:
        raise InputError("--viz", "rerun-sdk is not installed: pip install -e '.[viz]'") from None
    rec = rr.RecordingStream(f"slam2d {name}")
    if str(target) == "viewer":
        rec.spawn()
    else:
        path = Path(target)
        if path.suffix != ".rrd" or not path.parent.is_dir():
            raise InputError("--viz-save", f"expected FILE.rrd in an existing folder, got '{target}'")
        rec.save(path)
    return LiveView(rec, mapping)


class LiveView:
    """Logs a run scan by scan: ``step(scan, backend)`` after each back-end update, ``finish(poses)``
    with the optimised poses, ``close()`` to flush (an .rrd file is complete only then)."""

    def __init__(self, rec, mapping: MappingConfig):
        import rerun as rr

        from slam2d.slam.keyframe_grid import KeyframeGrid

        self.rr, self.rec, self.mapping = rr, rec, mapping
        self.grid = KeyframeGrid(mapping)
        self.count = 0
        self.loops = 0
        self.t0: float | None = None

    def step(self, scan: Scan, backend) -> None:
        """Log scan number ``self.count`` (just added to ``backend``) and the pose it was given."""
        rr, n = self.rr, self.count
        self.t0 = scan.stamp if self.t0 is None else self.t0
        self.rec.set_time("scan", sequence=n)
        self.rec.set_time("time", duration=scan.stamp - self.t0)
        pose = backend.current_pose()
        self.rec.log("world/scan", rr.Points2D(geometry.transform_points(pose, scan.points_in_base()),
                                               radii=0.02, colors=(230, 60, 40)))  # fmt: skip
        heading = ARROW_M * np.array([np.cos(pose[2]), np.sin(pose[2])])
        self.rec.log("world/robot", rr.Arrows2D(origins=[pose[:2]], vectors=[heading], colors=(30, 90, 220)))
        keys, offsets = backend.scan_anchors(n)
        if n % self.mapping.every_nth_scan == 0:
            self.grid.add_scan(int(keys[0]), offsets[0], scan)
        self._log_loops(backend)
        self.count += 1
        if self.count % MAP_EVERY == 0:
            keyframes = keyframe_poses(backend)
            self._log_map(keyframes, closed=len(keyframes) - 1)

    def finish(self, poses: np.ndarray, backend) -> None:
        """Log the optimised poses (N, 3) of every scan and the map at the optimised keyframes, one
        step after the last scan on the ``scan`` timeline."""
        self.rec.set_time("scan", sequence=self.count)
        keys, offsets = backend.scan_anchors()
        _, first = np.unique(keys, return_index=True)  # a keyframe's pose from any of its scans
        keyframes = geometry.compose(poses[first], geometry.inverse(offsets[first]))
        self._log_map(keyframes, closed=len(keyframes), trajectory=poses)
        self._log_loops(backend, keyframes)

    def close(self) -> None:
        self.rec.disconnect()

    def _log_map(self, keyframes: np.ndarray, closed: int, trajectory: np.ndarray | None = None) -> None:
        rr = self.rr
        self.grid.update(keyframes, closed=closed)  # the open keyframe drawn on top, as OnlineSlam.grid
        grid = self.grid.grid()
        cells = np.argwhere(grid.occupied_mask(self.mapping.occupied_thresh))
        self.rec.log("world/map", rr.Points2D(grid.cell_to_world(cells), radii=grid.resolution / 2,
                                              colors=(60, 60, 60)))  # fmt: skip
        line = keyframes if trajectory is None else trajectory
        self.rec.log("world/trajectory", rr.LineStrips2D([line[:, :2]], colors=(30, 90, 220)))

    def _log_loops(self, backend, keyframes: np.ndarray | None = None) -> None:
        """Log the loop closures when their number changed (or with ``keyframes``, at those poses)."""
        graph = backend.graph
        if graph is None or (graph.num_loops == self.loops and keyframes is None):
            return
        from slam2d.datasets.g2o import odometry_mask

        self.loops = graph.num_loops
        edges = graph.to_g2o()
        poses = edges.poses if keyframes is None else keyframes
        loop = ~odometry_mask(edges)
        segments = np.stack([poses[edges.i[loop], :2], poses[edges.j[loop], :2]], axis=1)
        self.rec.log("world/loops", self.rr.LineStrips2D(segments, colors=(40, 170, 60)))


def keyframe_poses(backend) -> np.ndarray:
    """Current keyframe estimates (K, 3): the pose graph's, or every scan's for the chain back end."""
    return backend.graph.estimate() if backend.graph is not None else np.array(backend.poses)
