"""Goal choice for exploration: frontiers (nearest, explore_lite's cost) or Li et al.'s candidates
(nearest, farthest, utility), with visited and inaccessible lists and the hybrid map.

The utility of a candidate p (eq. 6): F(p) = A(p) · exp(−(k1·L + k2·γ)), with A the hidden
unknown cells visible from p (information gain, rays cast on the grid), L how much later, on
average over the goals' hidden cells (each counted once: a cell several goals see is shared among
them), a tour through all open goals reaches them when p is first (``tour_regret``; or the grid
path length, or the Euclidean distance as the paper) and γ the
absolute angle between the robot's heading and the direction to p; the frontier regions' goals
are scored by the same F beside the candidates. explore_lite's cost of a frontier:
potential_scale · min_distance · resolution − gain_scale · size · resolution (the
lowest wins), goal at the reachable cell nearest the frontier's centroid.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from slam2d import geometry
from slam2d.exploration.base import EXPLORATION_STRATEGIES
from slam2d.exploration.candidates import Candidate, CandidateParams, scan_candidates
from slam2d.exploration.collection import paused, resume
from slam2d.exploration.config import ExplorationConfig
from slam2d.exploration.frontiers import (
    WALL_GAP,
    _goal_cell,
    depth_cells,
    find_frontiers,
    frontier_mask,
)
from slam2d.exploration.gains import RayRecords, _changed_tiles
from slam2d.exploration.gridops import (
    FREE,
    OCCUPIED,
    UNKNOWN,
    GridView,
    cells_inside_polygon,
    cells_of,
    entry_mask,
    information_gain,
    inside_polygon,
    straight_reachable,
)
from slam2d.exploration.hybrid import FINAL, HybridMap
from slam2d.exploration.paths import Paths, Scratch, path_lengths
from slam2d.exploration.pockets import (
    POCKET_RAYS,
    LocalRefresh,
    opaque_faces,
    pocket_goal,
    pocket_state,
    without_outside,
)
from slam2d.exploration.regret import tour_regret
from slam2d.segmentation.observations import raycast_grid

WALL_SPAN = 2.0  # m: a wall's unseen stretch (behind furniture) bridged when telling pockets from the outside
OPTIONS_KEPT = 10  # a utility decision's best options kept with its goal (goals.json)
OPTION_TERMS = "gain_m2", "share_m2", "path_m", "L_m", "gamma_rad", "F"


@dataclass(eq=False)
class Goal:
    """A chosen goal: ``position`` (x, y) m, ``kind`` ("frontier" / "candidate" / "pocket" / "viewpoint": a view
    of frontier cells, ``targets``), the candidate if any,
    ``waypoints`` (x, y) m to pass first (backtracking over the graph), ``score`` of the choice, and for the
    utility the decision's best ``options`` (the chosen goal first): why it went there; ``tight``: reached only
    on paths closer to obstacles than the safety margin (the robot's own disc is driven there)."""

    position: np.ndarray
    kind: str
    candidate: Candidate | None = None
    waypoints: list = field(default_factory=list)
    score: float = float("nan")
    targets: np.ndarray | None = None  # (K, 2) m: the hidden cells a pocket view (frontier cells a viewpoint) is to see
    options: list = field(default_factory=list)  # dicts: position, kind, gain_m2, share_m2, path_m, L_m, gamma_rad, F
    tight: bool = False


class Explorer:
    """Chooses goals with ``decide`` (by the strategy ``cfg.strategy`` names, then pockets); ``observe`` makes
    topological nodes (with their candidates) from the scans; ``spent`` says when the current goal is no
    longer worth reaching."""

    def __init__(self, cfg: ExplorationConfig, robot_radius: float, inflation: float, range_max: float):
        self.cfg, self.radius, self.inflation, self.range_max = cfg, robot_radius, inflation, range_max
        width = 2 * robot_radius
        safe = robot_radius + cfg.safe_margin
        self.params = CandidateParams(width=width, delta=cfg.delta, safe_d=safe, safe_dis=safe, d_tho=cfg.d_tho)
        self.min_frontier, self.width = cfg.min_frontier or width, width
        self.hybrid = HybridMap(cfg.node_step, cfg.box_width)
        self.visited: list[np.ndarray] = []
        self.inaccessible: list[np.ndarray] = []
        self.retired = np.zeros((0, 2))  # (K, 2) m: hidden cells a pocket view reached did not reveal
        self.viewed = np.zeros((0, 2))  # (K, 2) m: frontier cells a viewpoint reached was chosen to see
        self.decision_seconds: list[float] = []  # wall clock of each decision
        self.decision_cpu_seconds: list[float] = []  # the deciding thread's CPU time (little moved by other jobs)
        self.fallbacks = self.pocket_goals = self.tight_goals = 0
        self._hidden_of: tuple = (None, None, None)  # (view, its hidden-cell grid, its entry cells) counted on last
        self._maintained: tuple = (None, -1, [])  # (view, inaccessible goals, its open candidates) of the last upkeep
        self._hidden_grid = None  # the hidden-cell grid, kept between views
        self._frontier_grid: tuple = (None, None)  # (depth in cells, its frontier cells kept between views)
        self._scratch = Scratch()  # the buffers of the path search, one decision's level at a time
        self._rays = RayRecords()  # the gains' rays on the hidden-cell grid, kept where it did not change
        self._entries = LocalRefresh(entry_mask, 1)  # where the rays enter the hidden cells, kept likewise
        self._outside_of: tuple = (None, None)  # (grid frame, its cells outside the bounds)
        self._pockets_of: tuple = (None, -1, None)  # (view, retired targets, its pocket grid) counted on last
        self._gains_of: tuple = (None,) * 5  # (pocket grid, its places' gains, hidden cells, reach table, frame)
        self.strategy = EXPLORATION_STRATEGIES.create(cfg.strategy, cfg.strategy_options)
        _warm_up(self)

    # -- nodes and candidates --------------------------------------------------------------

    def observe(self, pose, scan, view: GridView, force: bool = False) -> bool:
        """Make a node at ``pose`` when ``node_step`` m have been travelled (or ``force``): its
        candidates from ``scan``, the older candidates it sees superseded; True if a node was made."""
        if not (self.hybrid.due(pose) or force):
            return False
        sensor = geometry.compose(np.asarray(pose, dtype=np.float64), scan.sensor_pose)
        found = scan_candidates(scan.ranges, scan.angles, scan.range_max, sensor, self.params)
        blocked = view.state == OCCUPIED
        self._supersede(sensor, view, blocked)
        here = np.asarray(pose, dtype=np.float64)[:2]
        found = [c for c in found if np.hypot(*(c.position - here)) >= self.cfg.node_step / 2 and self._open(c.position)]
        self.hybrid.add(pose, found, blocked, view.resolution, view.origin)
        return True

    def _supersede(self, sensor, view: GridView, blocked) -> None:
        """Older candidates the new node sees (line of sight on the grid, within range − delta) are
        closed: the new scan holds the frontier there now."""
        old = self.hybrid.candidates()
        if not old:
            return
        pts = np.array([c.position for c in old])
        d = np.hypot(*(pts - sensor[:2]).T)
        bearing = np.arctan2(pts[:, 1] - sensor[1], pts[:, 0] - sensor[0])
        t, _ = raycast_grid(~blocked, view.resolution, np.repeat(sensor[None, :2], len(old), 0), bearing[:, None],
                            self.range_max, view.origin)  # fmt: skip
        seen = (t[:, 0] >= d - view.resolution) & (d < self.range_max - self.cfg.delta)
        for c, s in zip(old, seen):
            c.alive = c.alive and not s

    def _open(self, xy) -> bool:
        """Not within half a node step of a node made so far, nor near an inaccessible goal, inside the bounds."""
        if len(self.hybrid.nodes) and np.hypot(*(self.hybrid.positions() - xy).T).min() < self.cfg.node_step / 2:
            return False
        if self.inaccessible and np.hypot(*(np.array(self.inaccessible) - xy).T).min() < self.cfg.avoid_radius:
            return False
        return self.cfg.bounds is None or bool(inside_polygon(xy[None], self.cfg.bounds)[0])

    def maintain(self, view: GridView) -> list[Candidate]:
        """Global dynamic maintenance: candidates whose gain fell below ``min_gain`` (explored space)
        are closed; the open ones returned with their gain (cells). Once a view (its clearance levels ask again):
        the same candidates are open then, with the same gains."""
        if self._maintained[:2] == (view, len(self.inaccessible)):
            return [c for c in self._maintained[2] if c.alive]
        live = self.hybrid.candidates()
        if not live:
            return []
        pts = np.array([c.position for c in live])
        gain = self._rays.gains(self._hidden(view), pts, self.cfg.gain_range, self.cfg.gain_rays,
                                self._hidden_entries(view))  # fmt: skip
        floor = self.cfg.min_gain / view.resolution**2
        out = []
        for c, g in zip(live, gain):
            c.gain = float(g)
            c.alive = g >= floor and self._open_goal(c.position)
            if c.alive:
                out.append(c)
        self._maintained = view, len(self.inaccessible), out
        return out

    def _open_goal(self, xy) -> bool:
        return not self.inaccessible or np.hypot(*(np.array(self.inaccessible) - xy).T).min() >= self.cfg.avoid_radius

    # -- decisions -------------------------------------------------------------------------------

    def decide(self, pose, view: GridView) -> Goal | None:
        """The next goal from ``pose`` on ``view``, or None when nothing is left to explore. Paths keep the
        robot's radius + the safety margin + the navigator's inflation margin from obstacles; when no goal is left
        so, the radius + the safety margin; then the radius alone, and the goal is ``tight`` (the navigator takes a
        gap that tight as a last resort: the robot may have come in through one, or the map draws a door narrower
        than it is)."""
        collecting = paused()  # no garbage collection in a decision: the one owed falls after it
        try:
            t0, c0 = time.perf_counter(), time.thread_time()
            pose = np.asarray(pose, dtype=np.float64)
            keep = self.radius + self.cfg.safety_margin
            goal = self._decide(pose, view, keep + self.inflation)
            if goal is None and self.inflation > 0:
                goal = self._decide(pose, view, keep)
            if goal is None and self.cfg.safety_margin > 0:
                goal = self._decide(pose, view, self.radius)
                if goal is not None:
                    goal.tight = True
            self.tight_goals += goal is not None and goal.tight
            self.decision_seconds.append(time.perf_counter() - t0)
            self.decision_cpu_seconds.append(time.thread_time() - c0)
        finally:
            resume(collecting)
        return goal

    def _decide(self, pose, view: GridView, clearance: float) -> Goal | None:
        """The next goal over paths keeping ``clearance`` m from obstacles."""
        roomy = view.traversable(self.radius + self.cfg.goal_clearance)  # goals only where the robot has room
        distance = Paths(view.traversable(clearance), view.to_cell(pose[:2]), view.resolution, allowed=roomy,
                         scratch=self._scratch)  # fmt: skip
        goal = self.strategy.choose(self, pose, view, distance)
        if goal is None and self.cfg.pockets:
            goal = pocket_goal(self, pose, view, distance)
            self.pocket_goals += goal is not None
        return goal

    def frontiers(self, pose, view, distance, nearest: bool = False) -> list:
        """The frontier regions the robot can reach (``find_frontiers``), away from visited and inaccessible goals;
        with ``nearest`` only the nearest one's ``path`` is exact (the others' a lower bound above it)."""
        avoid = self.visited + self.inaccessible
        return find_frontiers(view, pose[:2], distance, self.min_frontier, self.radius + 0.3, self.cfg.bounds, avoid,
                              self.cfg.avoid_radius, self.width, nearest, self._frontier_cells(view))  # fmt: skip

    def _frontier_cells(self, view: GridView) -> np.ndarray:
        """The view's ``frontier_mask`` (H, W) bool of the robot's width, kept, refreshed where the map changed (a copy)."""
        depth = depth_cells(self.width, view.resolution)
        if self._frontier_grid[0] != depth:
            refresh = LocalRefresh(lambda st: frontier_mask(st, depth=depth), max(depth + 1, WALL_GAP))
            self._frontier_grid = depth, refresh
        return self._frontier_grid[1](view.state)

    def keep_up(self, view: GridView) -> None:
        """The grids kept between decisions (frontier cells; once used, the hidden cells, their entry cells, the rays'
        records) brought up to ``view`` while the robot drives: the next decision refreshes only what changed since."""
        self._frontier_cells(view)
        if self._hidden_grid is not None:
            self._hidden_entries(view)

    def frontier_goal(self, pose, view, distance, cost=None) -> Goal | None:
        """The goal of the frontier region of lowest ``cost`` (a function of a region; default its path length, and
        then the path search stops at the nearest region)."""
        found = self.frontiers(pose, view, distance, nearest=cost is None)
        if not found:
            return None
        cost = [cost(f) for f in found] if cost is not None else [f.path for f in found]
        k = int(np.argmin(cost))
        return Goal(found[k].goal, "frontier", score=float(cost[k]))

    def utility_goal(self, pose, view, distance) -> Goal | None:
        """The candidate or frontier region's goal of highest utility, scored together: candidates are made
        only at nodes from one scan each, so a side opening the scans missed has a frontier but no candidate."""
        live, pts, path, target = self._candidate_options(view, distance)
        found = self.frontiers(pose, view, distance)
        if not live and not found:
            return None
        fronts = np.array([f.goal for f in found]).reshape(-1, 2)
        points = np.concatenate([pts, fronts])
        goals = np.concatenate([target, fronts])
        own, shares = self._rays.shared(self._hidden(view), points, self.cfg.gain_range, self.cfg.gain_rays,
                                        self._hidden_entries(view))  # fmt: skip
        gain = np.concatenate([[c.gain for c in live], own[len(live) :]])
        path = np.concatenate([path, [f.path for f in found]])
        score, length, gamma = self.utility_terms(pose, points, gain, path, goals, shares)
        for c, sc in zip(live, score):
            c.utility = float(sc)
        best = np.argsort(-score, kind="stable")[:OPTIONS_KEPT]  # best first; ties keep the first, as argmax
        k = int(best[0])
        terms = np.column_stack([gain * view.resolution**2, shares * view.resolution**2, path, length, gamma, score])
        options = [_option(goals[i], i < len(live), terms[i]) for i in best]
        if k >= len(live):
            return Goal(fronts[k - len(live)].copy(), "frontier", score=float(score[k]), options=options)
        way = self._route(pose, view, live[k], target[k], path[k])
        return Goal(target[k].copy(), "candidate", live[k], way, float(score[k]), options=options)

    def _hidden(self, view: GridView) -> GridView:
        """The grid the information gain is counted on: ``pocket_state`` (the hidden cells, what the coverage
        counts as unexplored; rays stopped by gaps between occupied cells narrower than the robot's radius,
        so that the unknown inside furniture or behind a wall seen at a grazing angle keeps no goal open)."""
        if self._hidden_of[0] is not view:
            wall = int(self.radius / view.resolution)
            if self._hidden_grid is None or self._hidden_grid.wall != wall:  # refreshed where the map changed
                self._hidden_grid = LocalRefresh(lambda st, *out: pocket_state(st, wall, *out), 2 * wall + 4)
                self._hidden_grid.wall = wall
            outside = self._outside(view)
            state = self._hidden_grid(view.state, *(() if outside is None else (outside,)))
            self._hidden_of = view, GridView(state, view.resolution, view.origin), None
            self._rays.update(self._hidden_of[1])
        return self._hidden_of[1]

    def _hidden_entries(self, view: GridView) -> np.ndarray:
        """The ``unknown_cells`` (K, 2) of :meth:`_hidden`'s grid, listed once a view (kept between views, refreshed
        where the grid changed)."""
        hidden = self._hidden(view)
        if self._hidden_of[2] is None:
            self._hidden_of = view, hidden, cells_of(self._entries(hidden.state))
        return self._hidden_of[2]

    def _outside(self, view: GridView) -> np.ndarray | None:
        """The view's cells (H, W) bool outside the bounding polygon, which no goal is chosen to see; None
        without bounds."""
        if self.cfg.bounds is None:
            return None
        frame = view.shape, tuple(np.asarray(view.origin, dtype=float)), view.resolution
        if self._outside_of[0] != frame:
            self._outside_of = frame, ~cells_inside_polygon(view.shape, view.to_world, self.cfg.bounds)
        return self._outside_of[1]

    def _pocket_state(self, view: GridView) -> np.ndarray:
        """The grid views of pockets are scored on: ``pocket_state`` without the retired targets and the
        cells outside the bounds, then ``opaque_faces`` and ``without_outside``. Stricter than the
        information gain's grid, so that once the frontiers are done the robot neither peels blocks of walls
        a column at a time nor looks for slivers of the outside. Kept for the same view (the levels of one
        decision) until more targets are retired."""
        if self._pockets_of[0] is not view or self._pockets_of[1] != len(self.retired):
            self._pockets_of = view, len(self.retired), self._pocket_grid(view)
        return self._pockets_of[2]

    def _pocket_grid(self, view: GridView) -> np.ndarray:
        retired = self._outside(view)
        retired = np.zeros(view.shape, dtype=bool) if retired is None else retired.copy()
        if len(self.retired):
            cells = view.to_cell(self.retired)
            cells = cells[view.inside(cells)]
            retired[cells[:, 0], cells[:, 1]] = True
        scored = pocket_state(view.state, int(self.radius / view.resolution), retired)
        scored = opaque_faces(scored, view.state, depth_cells(self.width, view.resolution))
        return without_outside(scored, int(WALL_SPAN / view.resolution))

    def _candidate_options(self, view, distance) -> tuple[list[Candidate], np.ndarray, np.ndarray, np.ndarray]:
        """The open candidates the robot can reach: candidates, positions (P, 2) m, grid path lengths (P,) m
        and where to drive (P, 2) m."""
        none = [], np.zeros((0, 2)), np.zeros(0), np.zeros((0, 2))
        live = self.maintain(view)
        if not live:
            return none
        pts = np.array([c.position for c in live])
        path, target = path_lengths(view, distance, pts, self.radius + 0.3)
        ok = np.isfinite(path)
        if self.visited and ok.any():  # a candidate whose goal is where the robot has been is explored
            near = np.hypot(*(target[:, None, :] - np.array(self.visited)[None]).transpose(2, 0, 1)).min(axis=1)
            for c in np.array(live, dtype=object)[near < self.cfg.avoid_radius]:
                c.alive = False
            ok &= near >= self.cfg.avoid_radius
        if not ok.any():
            return none
        return [c for c, k in zip(live, ok) if k], pts[ok], path[ok], target[ok]

    def candidate_goal(self, pose, view, distance, nearest: bool = True) -> Goal | None:
        """The nearest (or farthest) open candidate by grid path."""
        live, _, path, target = self._candidate_options(view, distance)
        if not live:
            return None
        score = -path if nearest else path
        for c, s in zip(live, score):
            c.utility = float(s)
        k = int(np.argmax(score))
        way = self._route(pose, view, live[k], target[k], path[k])
        return Goal(target[k].copy(), "candidate", live[k], way, float(score[k]))

    def utility(self, pose, points, gain, path, goals=None, shares=None) -> np.ndarray:
        """F(p) = A(p)·exp(−(k1·L + k2·γ)) for points (P, 2) m with gains (P,) cells and grid path lengths
        (P,) m; for ``distance: tour``, ``goals`` (P, 2) m where the robot drives for each (default ``points``) and
        ``shares`` (P,) cells each goal's share of the hidden cells (``shared_gain``; default ``gain``)."""
        return self.utility_terms(pose, points, gain, path, goals, shares)[0]

    def utility_terms(self, pose, points, gain, path, goals=None, shares=None) -> tuple[np.ndarray, ...]:
        """:meth:`utility` F (P,) with its terms: L (P,) m and γ (P,) rad."""
        if self.cfg.distance == "euclidean":
            length = np.hypot(*(points - pose[:2]).T)
        elif self.cfg.distance == "tour":
            length = tour_regret(points if goals is None else goals, path, gain if shares is None else shares)
        else:
            length = path
        gamma = np.abs(geometry.wrap_angle(np.arctan2(points[:, 1] - pose[1], points[:, 0] - pose[0]) - pose[2]))
        return gain * np.exp(-(self.cfg.k1 * length + self.cfg.k2 * gamma)), length, gamma

    def _route(self, pose, view, chosen: Candidate, target, path: float) -> list:
        """Waypoints over the topological graph to a candidate of an old final node (``backtrack: graph``), driving
        to ``target`` (x, y) m; none when their straight legs are longer than the grid path (``path`` m) by more
        than a node step: the graph is a tree of the ways the robot came, and the grid knows a shortcut."""
        node = self.hybrid.nodes.get(chosen.node)
        if self.cfg.backtrack != "graph" or node is None or node.role != FINAL:
            return []
        blocked = view.state == OCCUPIED
        width = self.cfg.box_width

        def clear(a, b):
            return straight_reachable(blocked, view.resolution, view.origin, a, b, width)

        way = self.hybrid.route(pose[:2], node.id)
        while way and clear(pose[:2], way[0]) and (len(way) == 1 or clear(pose[:2], way[1])):
            way.pop(0)
        while way and clear(way[-1] if len(way) == 1 else way[-2], chosen.position):
            way.pop()
        legs = np.diff(np.array([pose[:2], *way, target]), axis=0)
        return way if np.hypot(*legs.T).sum() <= path + self.cfg.node_step else []

    # -- goal bookkeeping ---------------------------------------------------------------------

    def spent(self, goal: Goal, view: GridView) -> bool:
        """Whether the goal is no longer worth reaching: a frontier goal with no frontier cell left
        within the goal reach; a candidate whose gain fell below ``min_gain``."""
        if goal.kind == "pocket":
            state = GridView(self._pocket_state(view), view.resolution, view.origin)
            g = information_gain(state, goal.position[None], self.cfg.gain_range, POCKET_RAYS)[0]
            if g < self.cfg.pocket_gain / view.resolution**2:
                self._retire(goal)
                return True
            return False
        if goal.kind == "candidate":
            g = information_gain(self._hidden(view), goal.candidate.position[None], self.cfg.gain_range,
                                 self.cfg.gain_rays)[0]  # fmt: skip
            if g < self.cfg.min_gain / view.resolution**2:
                goal.candidate.alive = False
                return True
            return False
        if goal.kind == "viewpoint":  # spent when none of the frontier cells it was chosen to see is one still
            cells = view.to_cell(goal.targets)
            cells = cells[view.inside(cells)]
            if len(cells) == 0:
                return True
            r0, c0 = cells.min(axis=0)
            r1, c1 = cells.max(axis=0) + 1
            mask = self._frontier_window(view, r0, r1, c0, c1)
            return not mask[cells[:, 0] - r0, cells[:, 1] - c0].any()
        cell = view.to_cell(goal.position)
        k = int(np.ceil((self.radius + 0.3) / view.resolution)) + 1
        h, w = view.shape
        r0, r1 = max(cell[0] - k, 0), min(cell[0] + k + 1, h)
        c0, c1 = max(cell[1] - k, 0), min(cell[1] + k + 1, w)
        if r0 >= r1 or c0 >= c1:
            return False
        return not self._frontier_window(view, r0, r1, c0, c1).any()

    def _frontier_window(self, view: GridView, r0, r1, c0, c1) -> np.ndarray:
        """The frontier cells (``frontier_mask``) of the window rows r0:r1, cols c0:c1 of ``view``."""
        depth = depth_cells(self.width, view.resolution)
        m = max(depth + 1, WALL_GAP)  # the cells a frontier test looks at around the window
        lo = np.array([max(r0 - m, 0), max(c0 - m, 0)])
        mask = frontier_mask(view.state[lo[0] : r1 + m, lo[1] : c1 + m], depth=depth)
        return mask[r0 - lo[0] : r1 - lo[0], c0 - lo[1] : c1 - lo[1]]

    def reached(self, goal: Goal) -> None:
        self.visited.append(goal.position.copy())
        if goal.kind == "viewpoint" and goal.targets is not None:
            self.viewed = np.concatenate([self.viewed, goal.targets])
        self._retire(goal)
        if goal.candidate is not None:
            goal.candidate.alive = False

    def _retire(self, goal: Goal) -> None:
        """A pocket view reached (or no longer worth it): the hidden cells it was chosen to see are no
        target any more, seen or not (some are furniture, or need a view the robot cannot take)."""
        if goal.kind == "pocket" and goal.targets is not None and len(goal.targets):
            self.retired = np.concatenate([self.retired, goal.targets])

    def give_up(self, goal: Goal) -> None:
        self.inaccessible.append(goal.position.copy())
        if goal.candidate is not None:
            goal.candidate.alive = False


_WARM: set = set()  # the strategies whose first decision this process has made


def _warm_up(explorer: Explorer) -> None:
    """Decisions of a throwaway explorer of the same strategy, the first time a strategy is made in this process: on
    a small room with an opening (a frontier; again once the map changed; the goal checked), then with a pocket
    behind a wall's gap only; then a straight way checked (a candidate's route) and a frontier's goal off its own
    cells: numba's compiled kernels and the strategy's libraries are loaded then, not in the first decisions' time."""
    if explorer.cfg.strategy in _WARM:
        return
    _WARM.add(explorer.cfg.strategy)
    import networkx  # noqa: F401  (the hybrid map's routes: 0.7 s to import)

    state = np.full((60, 60), UNKNOWN, dtype=np.int8)
    state[10:50, 10:50] = FREE
    state[9, 9:51] = state[50, 9:51] = state[9:51, 9] = state[9:51, 50] = OCCUPIED
    state[50, 20:40] = FREE  # the opening
    throwaway = Explorer(explorer.cfg, explorer.radius, explorer.inflation, explorer.range_max)
    pose = np.array([1.5, 1.5, 0.0])
    for _ in range(2):
        goal = throwaway.decide(pose, GridView(state.copy(), 0.05, (0.0, 0.0)))
        if goal is not None:
            throwaway.spent(goal, GridView(state.copy(), 0.05, (0.0, 0.0)))
        state[51:54, 20:40] = FREE
    state[50, 20:40] = OCCUPIED
    state[51:59, 12:48] = OCCUPIED
    state[52:58, 14:46] = UNKNOWN  # a pocket seen through a gap only
    state[51, 28:32] = UNKNOWN
    throwaway.decide(pose, GridView(state, 0.05, (0.0, 0.0)))
    straight_reachable(state == OCCUPIED, 0.05, (0.0, 0.0), pose, pose + 1.0, 0.4)  # a way back over the graph
    _goal_cell(np.array([[0, 0]]), ~np.eye(3, dtype=bool), 1.5)  # a frontier's goal off its own cells
    _changed_tiles(state, state, 8)  # the rays' records checked against a changed grid


def _option(goal, candidate: bool, terms) -> dict:
    """One option of a utility decision as goals.json keeps it: where (x, y) m, the kind, and ``OPTION_TERMS``."""
    return {"position": np.round(goal, 3).tolist(), "kind": "candidate" if candidate else "frontier",
            **{key: float(f"{v:.4g}") for key, v in zip(OPTION_TERMS, terms)}}
