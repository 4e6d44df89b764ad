"""How well an exploration run did, from the world's ground truth: the reachable free space, coverage of
it, map IoU, path repetition, and seeded starts."""

from __future__ import annotations

import numpy as np
from scipy import ndimage
from scipy.spatial import cKDTree

from slam2d.datasets.simulator import route_start
from slam2d.errors import InputError
from slam2d.exploration.gridops import cells_inside_polygon, visible_from
from slam2d.navigation.maps import world_grid

START_CLEARANCE = 0.5  # m from walls for a seeded start
VIEW_SPACING = 0.25  # m between the places the reachable area is seen from
REPEAT_RADIUS = 0.5  # m: path within this of earlier path is repeated
REPEAT_GAP = 2.0  # m of travel before a piece of path counts as "earlier"
SAMPLE_STEP = 0.1  # m between path samples for the repetition metric


def truth_map(world, resolution: float = 0.05):
    """The world's free mask (H, W) and its grid frame (a PlanningGrid)."""
    grid = world_grid(world, resolution)
    return grid.free, grid


def reachable_free(free: np.ndarray, frame, start_xy, radius: float = 0.25, max_range: float = 12.0,
                   unmapped: np.ndarray | None = None) -> np.ndarray:
    """The area an explorer can be asked to map: free cells that the laser (``max_range`` m) sees from
    some place the robot's centre can reach from the start (the free cells farther than ``radius`` m
    from walls, connected to the start's cell — the robot's radius plus the navigator's inflation
    margin in a run), sampled every VIEW_SPACING m; none of the ``unmapped`` cells (a PNG plan's
    unknown grey: wall interiors and the outside, seen through pinholes in its walls)."""
    res = frame.resolution
    room = ndimage.distance_transform_edt(np.pad(free, 1))[1:-1, 1:-1] * res > radius
    labels, _ = ndimage.label(room, np.ones((3, 3), int))
    cell = frame.world_to_cell(np.asarray(start_xy, float))
    if not frame.in_bounds(cell) or not free[cell[0], cell[1]]:
        raise InputError("exploration.start", "the start is not in the world's free space")
    if labels[cell[0], cell[1]] == 0:  # a start closer to a wall than that: the nearest place with room
        rows, cols = np.nonzero(labels)
        d = np.hypot(rows - cell[0], cols - cell[1])
        if len(d) == 0 or d.min() * res > 2 * radius:
            raise InputError("exploration.start", "the start is not in the world's free space")
        cell = np.array([rows[np.argmin(d)], cols[np.argmin(d)]])
    robot = labels == labels[cell[0], cell[1]]
    k = max(1, round(VIEW_SPACING / res))
    rows, cols = np.nonzero(robot[::k, ::k])
    origins = np.column_stack([cols * k + 0.5, rows * k + 0.5])
    area = visible_from(free, res, origins, max_range) | robot
    return area if unmapped is None else area & ~unmapped


def ignored_cells(unmapped: np.ndarray | None, frame, shape, bounds) -> np.ndarray | None:
    """The world's cells (H, W) bool that no coverage or IoU counts: the plan's ``unmapped`` ones and those
    outside the bounding polygon ``bounds`` (K, 2) m; None when there are none."""
    if bounds is None:
        return unmapped
    outside = ~cells_inside_polygon(shape, frame.cell_to_world, bounds)
    return outside if unmapped is None else outside | unmapped


def seeded_start(world, name: str, free: np.ndarray, frame, seed: int) -> np.ndarray:
    """A start pose: the office route's start for the office; else a seeded cell at least
    START_CLEARANCE from walls in the largest open component that does not touch the map's edge
    (the building, not the area around it), heading seeded too."""
    if name == "office":
        return route_start("office")
    clear = ndimage.distance_transform_edt(free) * frame.resolution > START_CLEARANCE
    labels, n = ndimage.label(clear)
    if n == 0:
        raise InputError("dataset.simulator.world", f"{name}: no free place {START_CLEARANCE} m from every wall")
    edge = np.unique(np.concatenate([labels[0], labels[-1], labels[:, 0], labels[:, -1]]))
    sizes = np.bincount(labels.ravel(), minlength=n + 1)
    sizes[0] = 0
    inner = sizes.copy()
    inner[edge] = 0
    pick = int(np.argmax(inner)) if inner.max() > 0 else int(np.argmax(sizes))
    rows, cols = np.nonzero(labels == pick)
    rng = np.random.default_rng(seed)
    k = int(rng.integers(len(rows)))
    xy = frame.cell_to_world(np.array([rows[k], cols[k]]))
    return np.array([xy[0], xy[1], rng.uniform(-np.pi, np.pi)])


class Coverage:
    """Explored fraction of the reachable free area: a reachable true-free cell counts as explored
    when the SLAM grid knows (free or occupied) a cell within one cell of it. ``unmapped`` (H, W): the
    cells the plan leaves unknown and those outside the bounds (None: none), about which the map's IoU
    says nothing."""

    def __init__(self, reachable: np.ndarray, frame, mapping, unmapped: np.ndarray | None = None):
        rows, cols = np.nonzero(reachable)
        self.points = frame.cell_to_world(np.column_stack([rows, cols]))
        self.reachable, self.frame, self.mapping, self.unmapped = reachable, frame, mapping, unmapped

    def __call__(self, grid) -> float:
        known = grid.free_mask(self.mapping.free_thresh) | grid.occupied_mask(self.mapping.occupied_thresh)
        known = ndimage.binary_dilation(known, np.ones((3, 3), bool))
        return float(_lookup(grid, known, self.points).mean()) if len(self.points) else 1.0

    def iou(self, grid) -> float:
        """IoU of SLAM's free cells and the reachable true free space, on the world's cells the plan knows
        (SLAM's free cells where the plan is unknown grey, e.g. the outside seen through a door, are neither)."""
        h, w = self.reachable.shape
        rows, cols = np.indices((h, w))
        centres = self.frame.cell_to_world(np.column_stack([rows.ravel(), cols.ravel()]))
        free = _lookup(grid, grid.free_mask(self.mapping.free_thresh), centres).reshape(h, w)
        if self.unmapped is not None:
            free &= ~self.unmapped
        union = (free | self.reachable).sum()
        return float((free & self.reachable).sum() / union) if union else 1.0


def _lookup(grid, mask: np.ndarray, points) -> np.ndarray:
    cells = grid.world_to_cell(points)
    ok = grid.in_bounds(cells)
    out = np.zeros(len(points), dtype=bool)
    out[ok] = mask[cells[ok, 0], cells[ok, 1]]
    return out


def path_repetition(xy: np.ndarray) -> float:
    """Fraction of the path (resampled every SAMPLE_STEP m) within REPEAT_RADIUS of path driven more than
    REPEAT_GAP m earlier."""
    at, repeated = repeated_path(xy)
    return float(np.mean(repeated)) if len(at) else 0.0


def repeated_path(xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The path ``xy`` (N, 2) m resampled every SAMPLE_STEP m: each sample's distance along it (K,) m and whether it is
    driven again (K,) bool (within REPEAT_RADIUS of path driven more than REPEAT_GAP m earlier); none for a path
    shorter than REPEAT_GAP."""
    seg = np.hypot(*np.diff(xy, axis=0).T)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    if s[-1] < REPEAT_GAP:
        return np.zeros(0), np.zeros(0, dtype=bool)
    at = np.arange(0.0, s[-1], SAMPLE_STEP)
    pts = np.column_stack([np.interp(at, s, xy[:, 0]), np.interp(at, s, xy[:, 1])])
    near = cKDTree(pts).query_ball_point(pts, REPEAT_RADIUS)
    gap = round(REPEAT_GAP / SAMPLE_STEP)
    return at, np.array([bool(js) and min(js) < i - gap for i, js in enumerate(near)], dtype=bool)


def at_coverage(curve: np.ndarray, level: float) -> tuple[float, float]:
    """(time s, distance m) when coverage first reached ``level``; nan if never."""
    k = np.nonzero(curve[:, 2] >= level)[0]
    return (float(curve[k[0], 0]), float(curve[k[0], 1])) if len(k) else (float("nan"), float("nan"))
