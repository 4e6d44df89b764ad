"""Live view of a run in the rerun viewer (``--viz`` or ``--viz-save FILE.rrd`` of ``slam2d run``,
``localize`` and ``explore``).

Needs the ``[viz]`` extra (``rerun-sdk``); nothing here is imported unless a view is asked for.
Entities of a SLAM run (:class:`LiveView`), in the map frame (m), on the timelines ``scan`` (scan
index) and ``time`` (s since the first scan):

- ``world/scan``: the latest scan's hits at the current estimate (Points2D), every scan;
- ``world/robot``: the current pose estimate, an arrow along the heading (Arrows2D), every scan;
- ``world/trajectory``: the keyframe estimates (LineStrips2D), with each map refresh, and at the
  end (scan index N for N scans) every scan's optimised pose;
- ``world/loops``: one segment per loop closure between its keyframe estimates (LineStrips2D),
  whenever the graph's loops change;
- ``world/map``: centres of the occupied cells of the grid at the current keyframe estimates
  (Points2D), every ``MAP_EVERY`` scans and once more after the final optimisation.

A localisation run (:class:`ParticleView`, same timelines): ``world/map`` (the known map's
occupied cells, once), ``world/robot`` (the estimate, every scan), ``world/truth`` (the true or
reference position, every scan that has one) and ``world/particles`` (at most ``VIEW_PARTICLES``
of the particles, coloured from blue to red by weight, at each filter update).

An exploration run (:class:`ExploreView`, timeline ``time``): ``world/robot`` (the SLAM estimate,
every control step), ``world/goal`` (the current goal, whenever it changes; empty between goals),
and every ``MAP_PERIOD`` s and at the end ``world/map`` (the grid's occupied cells) and
``world/frontiers`` (its frontier cells: free cells next to unknown ones).
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
VIEW_PARTICLES = 2000
"""Particles logged per filter update at most (an even subset)."""
PARTICLE_ENTITIES = ("world/map", "world/robot", "world/truth", "world/particles")
MAP_PERIOD = 2.0
"""s of an exploration between two logs of its map and frontiers."""
EXPLORE_ENTITIES = ("world/robot", "world/goal", "world/map", "world/frontiers")
MAP_COLOUR = (60, 60, 60)
ROBOT_COLOUR = (30, 90, 220)


def open_view(target: str | Path, name: str, kind: str = "run", *args):
    """The view of a ``kind`` of run (run: :class:`LiveView`, localize: :class:`ParticleView`, explore:
    :class:`ExploreView`, made with ``args``) streaming to a spawned (or already running) viewer when
    ``target`` is ``"viewer"``, else recording to the ``.rrd`` file ``target``."""
    views = {"run": LiveView, "localize": ParticleView, "explore": ExploreView}
    return views[kind](_recording(target, name), *args)


def _recording(target: str | Path, name: str):
    """A rerun RecordingStream to the viewer or the ``.rrd`` file ``target``."""
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
    return rec


class _View:
    """A recording with the robot's pose and ``close()`` to flush it (an .rrd file is complete only then)."""

    def __init__(self, rec):
        import rerun as rr

        self.rr, self.rec = rr, rec

    def close(self) -> None:
        self.rec.disconnect()

    def _clock(self, index: int, seconds: float) -> None:
        self.rec.set_time("scan", sequence=index)
        self.rec.set_time("time", duration=seconds)

    def _robot(self, pose: np.ndarray) -> None:
        """The pose (x, y, theta) as an arrow ARROW_M long along the heading."""
        heading = ARROW_M * np.array([np.cos(pose[2]), np.sin(pose[2])])
        self.rec.log("world/robot", self.rr.Arrows2D(origins=[pose[:2]], vectors=[heading], colors=ROBOT_COLOUR))

    def _cells(self, entity: str, xy: np.ndarray, resolution: float, colour, static: bool = False) -> None:
        """Cell centres (N, 2) m as discs filling their cells."""
        self.rec.log(entity, self.rr.Points2D(xy, radii=resolution / 2, colors=colour), static=static)


class LiveView(_View):
    """Logs a SLAM run scan by scan: ``step(scan, backend)`` after each back-end update,
    ``finish(poses)`` with the optimised poses, ``close()`` to flush."""

    def __init__(self, rec, mapping: MappingConfig):
        from slam2d.slam.keyframe_grid import KeyframeGrid

        super().__init__(rec)
        self.mapping = mapping
        self.grid = KeyframeGrid(mapping)
        self.count = 0
        self.loops = 0
        self.t0: float | None = None

    def step(self, scan: Scan, backend) -> None:
        """Log scan number ``self.count`` (just added to ``backend``) and the pose it was given."""
        n = self.count
        self.t0 = scan.stamp if self.t0 is None else self.t0
        self._clock(n, scan.stamp - self.t0)
        pose = backend.current_pose()
        self.rec.log("world/scan", self.rr.Points2D(geometry.transform_points(pose, scan.points_in_base()),
                                                    radii=0.02, colors=(230, 60, 40)))  # fmt: skip
        self._robot(pose)
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

    def _log_map(self, keyframes: np.ndarray, closed: int, trajectory: np.ndarray | None = None) -> None:
        self.grid.update(keyframes, closed=closed)  # the open keyframe drawn on top, as OnlineSlam.grid
        grid = self.grid.grid()
        self._cells("world/map", occupied_points(grid, self.mapping.occupied_thresh), grid.resolution, MAP_COLOUR)
        line = keyframes if trajectory is None else trajectory
        self.rec.log("world/trajectory", self.rr.LineStrips2D([line[:, :2]], colors=ROBOT_COLOUR))

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


def occupied_points(grid, occupied_thresh: float) -> np.ndarray:
    """Centres (N, 2) m of the cells of an OccupancyGrid whose probability exceeds ``occupied_thresh``."""
    return grid.cell_to_world(np.argwhere(grid.occupied_mask(occupied_thresh)))


class ParticleView(_View):
    """Logs a localisation run on a known map: ``step(...)`` after each scan's filter step."""

    def __init__(self, rec, known):
        super().__init__(rec)
        self._cells("world/map", known.cell_to_world(np.argwhere(known.occupied)), known.resolution, MAP_COLOUR,
                    static=True)

    def step(self, index: int, seconds: float, pf, estimate: np.ndarray, truth: np.ndarray, updated: bool) -> None:
        """Scan ``index`` at ``seconds`` s: the ``estimate`` and ``truth`` poses (3,), and the
        particles of the ParticleFilter ``pf`` when the scan ``updated`` it."""
        self._clock(index, seconds)
        self._robot(estimate)
        if np.isfinite(truth).all():
            self.rec.log("world/truth", self.rr.Points2D([truth[:2]], radii=0.08, colors=(40, 170, 60)))
        if updated:
            keep = np.linspace(0, len(pf.particles) - 1, min(VIEW_PARTICLES, len(pf.particles))).astype(int)
            w = np.exp(pf.log_w[keep] - pf.log_w[keep].max())  # 1 for the heaviest
            colours = np.column_stack([255 * w, np.full_like(w, 60), 255 * (1 - w)]).astype(np.uint8)
            self.rec.log("world/particles", self.rr.Points2D(pf.particles[keep, :2], radii=0.03, colors=colours))


class ExploreView(_View):
    """Logs an exploration run: ``step(...)`` every control step (``force`` at the end)."""

    def __init__(self, rec, mapping: MappingConfig):
        super().__init__(rec)
        self.mapping = mapping
        self.goal = ()  # no goal logged yet (None is "no goal")
        self.next_map = 0.0

    def step(self, seconds: float, pose: np.ndarray, grid, goal, force: bool = False) -> None:
        """At ``seconds`` s of the run: the estimate ``pose`` (3,), the ``goal`` (an exploration
        Goal or None) when it changed, and the OccupancyGrid ``grid`` with its frontier cells when due."""
        self.rec.set_time("time", duration=seconds)
        self._robot(pose)
        if goal is not self.goal:
            self.goal = goal
            xy = np.zeros((0, 2)) if goal is None else np.asarray(goal.position, float)[None, :2]
            self.rec.log("world/goal", self.rr.Points2D(xy, radii=0.15, colors=(240, 160, 0)))
        if force or seconds >= self.next_map:
            self.next_map = seconds + MAP_PERIOD
            self._cells("world/map", occupied_points(grid, self.mapping.occupied_thresh), grid.resolution,
                        MAP_COLOUR)  # fmt: skip
            self._cells("world/frontiers", frontier_points(grid, self.mapping), grid.resolution, (0, 190, 190))


def frontier_points(grid, mapping: MappingConfig) -> np.ndarray:
    """Centres (N, 2) m of the frontier cells of an OccupancyGrid, as the explorer of the simulated robot
    finds them (free cells next to unknown that runs deeper than the robot's width)."""
    from slam2d.exploration.frontiers import depth_cells, frontier_mask
    from slam2d.exploration.gridops import GridView
    from slam2d.sim.robot import ROBOT_RADIUS

    view = GridView.of(grid, mapping.free_thresh, mapping.occupied_thresh)
    depth = depth_cells(2 * ROBOT_RADIUS, view.resolution)
    return view.to_world(np.argwhere(frontier_mask(view.state, depth=depth)))
