"""The dynamically simplified grid-topological map of Li et al. (§3): topological nodes with their
candidate goals over the occupancy grid, kept sparse by a cache.

A node ``T = {pose, P_c, parent, children}`` is made every ``step`` m (S_tep = 0.9 m) of
travel or at a goal. Nodes are *current* (the newest), *cache* (the one before),
*final* (in the graph) or *marked* (dropped, but remembered as explored space). When a
new (current) node arrives, the cache joins the graph iff (1) the current node is not
straight-line reachable from its nearest final node — three rays (the two long sides
and the midline of a box of width ``box_width``) cast on the grid — or (2) the cache
still holds an unexplored candidate; otherwise it becomes a marked node. Then the
current node becomes the cache. The first node is final; at the end the last cache is.
Backtracking to an old candidate follows the graph (networkx shortest path over the
final nodes, edges between a final node and its parent).
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from slam2d.exploration.candidates import Candidate
from slam2d.exploration.gridops import straight_reachable

CURRENT, CACHE, FINAL, MARKED = "current", "cache", "final", "marked"
LINK_RANGE = 4.0  # m: a new final node is linked to the final nodes this close it can reach in a straight line


@dataclass(eq=False)
class TopoNode:
    """``T = {pose, P_c, parent, children}`` with its ``id`` and ``role``."""

    id: int
    pose: np.ndarray
    candidates: list[Candidate] = field(default_factory=list)
    parent: int | None = None
    children: list[int] = field(default_factory=list)
    role: str = CURRENT
    links: list[int] = field(default_factory=list)  # final nodes straight-line reachable besides the parent

    def open_candidates(self) -> list[Candidate]:
        return [c for c in self.candidates if c.alive]


class HybridMap:
    """Topological nodes over the grid; ``add(pose, candidates, blocked, resolution, origin)`` makes a
    node and updates the cache; ``final_ids``, ``marked_ids``, ``cache``, ``current``."""

    def __init__(self, step: float = 0.9, box_width: float = 0.6):
        self.step, self.box_width = float(step), float(box_width)
        self.nodes: dict[int, TopoNode] = {}
        self.final_ids: list[int] = []
        self.marked_ids: list[int] = []
        self.cache: int | None = None
        self.current: int | None = None
        self._travel = 0.0
        self._last_xy: np.ndarray | None = None

    # -- node creation ---------------------------------------------------------------

    def due(self, pose) -> bool:
        """Whether the robot has travelled ``step`` m since the last node (path length, m)."""
        xy = np.asarray(pose, dtype=np.float64)[:2]
        if self._last_xy is None:
            return True
        self._travel += float(np.hypot(*(xy - self._last_xy)))
        self._last_xy = xy
        return self._travel >= self.step

    def add(self, pose, candidates: list[Candidate], blocked: np.ndarray, resolution: float, origin) -> TopoNode:
        """A new current node at ``pose`` holding ``candidates``; the cache rules applied on the grid
        whose ``blocked`` (H, W) cells stop the three rays."""
        node = TopoNode(len(self.nodes), np.asarray(pose, dtype=np.float64).copy(), list(candidates))
        for c in node.candidates:
            c.node = node.id
        self.nodes[node.id] = node
        self._travel, self._last_xy = 0.0, node.pose[:2].copy()
        if not self.final_ids:
            self._make_final(node)
            return node
        if self.cache is not None:
            self._settle_cache(node, blocked, resolution, origin)
        node.role = CACHE  # the current node becomes the cache
        self.cache = self.current = node.id
        return node

    def _settle_cache(self, new: TopoNode, blocked, resolution, origin) -> None:
        """Cache -> final iff the current node is not straight-line reachable from its nearest final
        node, or the cache holds an open candidate; else cache -> marked."""
        cache, current = self.nodes[self.cache], new
        nearest = self.nearest_final(current.pose[:2])
        reachable = straight_reachable(blocked, resolution, origin, nearest.pose, current.pose, self.box_width)
        if not reachable or cache.open_candidates():
            self._make_final(cache, blocked, resolution, origin)
        else:
            cache.role = MARKED
            self.marked_ids.append(cache.id)

    def _make_final(self, node: TopoNode, blocked=None, resolution=None, origin=None) -> None:
        """``node`` joins the graph: its parent is the nearest final node straight-line reachable from it
        (the latest final node if none is), and it is linked to every final node within
        ``LINK_RANGE`` m that is straight-line reachable."""
        if self.final_ids:
            finals = [self.nodes[i] for i in self.final_ids]
            d = np.array([np.hypot(*(n.pose[:2] - node.pose[:2])) for n in finals])
            links = []
            if blocked is not None:
                for k in np.argsort(d):
                    if d[k] > LINK_RANGE:
                        break
                    if straight_reachable(blocked, resolution, origin, node.pose, finals[k].pose, self.box_width):
                        links.append(finals[k].id)
            parent = self.nodes[links[0]] if links else finals[-1]
            node.parent = parent.id
            parent.children.append(node.id)
            node.links = [i for i in links if i != parent.id]
        node.role = FINAL
        self.final_ids.append(node.id)

    def finish(self) -> None:
        """End of exploration: the cache and the current node join the graph."""
        if self.cache is not None and self.nodes[self.cache].role != FINAL:
            self._make_final(self.nodes[self.cache])
        self.cache = self.current = None

    # -- queries ------------------------------------------------------------------------

    def nearest_final(self, xy) -> TopoNode:
        finals = [self.nodes[i] for i in self.final_ids]
        d = [float(np.hypot(*(n.pose[:2] - xy))) for n in finals]
        return finals[int(np.argmin(d))]

    def candidates(self) -> list[Candidate]:
        """Every open candidate of every node."""
        return [c for n in self.nodes.values() for c in n.candidates if c.alive]

    def positions(self) -> np.ndarray:
        """Positions (N, 2) m of every node made so far (final, marked, cache and current)."""
        return np.array([n.pose[:2] for n in self.nodes.values()]).reshape(-1, 2)

    def route(self, start_xy, node_id: int) -> list[np.ndarray]:
        """Waypoints (x, y) m over the graph from the final node nearest ``start_xy`` to final node
        ``node_id`` (the nodes on the way, both ends included)."""
        import networkx as nx

        graph = self.graph()
        source = self.nearest_final(np.asarray(start_xy, dtype=np.float64)[:2]).id
        if node_id not in graph or not nx.has_path(graph, source, node_id):
            return []
        path = nx.shortest_path(graph, source, node_id, weight="length")
        return [self.nodes[i].pose[:2].copy() for i in path]

    def graph(self):
        """networkx Graph of the final nodes, edges parent-child weighted by length (m)."""
        import networkx as nx

        g = nx.Graph()
        for i in self.final_ids:
            n = self.nodes[i]
            g.add_node(i, pos=tuple(n.pose[:2]))
            for j in ([n.parent] if n.parent is not None else []) + n.links:
                g.add_edge(i, j, length=float(np.hypot(*(n.pose[:2] - self.nodes[j].pose[:2]))))
        return g

    def counts(self) -> dict[str, int]:
        """Nodes made in all (every node added, the naive map) and kept (final)."""
        return {"nodes_all": len(self.nodes), "nodes_final": len(self.final_ids), "nodes_marked": len(self.marked_ids)}

    # -- output ---------------------------------------------------------------------------

    def to_json(self) -> dict:
        nodes = []
        for n in self.nodes.values():
            cands = [{"position": c.position.tolist(), "d": float(c.d), "idx": int(c.idx), "type": c.type,
                      "alive": bool(c.alive), "utility": None if not np.isfinite(c.utility) else float(c.utility)}
                     for c in n.candidates]  # fmt: skip
            nodes.append({"id": n.id, "pose": n.pose.tolist(), "role": n.role, "parent": n.parent,
                          "children": list(n.children), "links": list(n.links), "candidates": cands})  # fmt: skip
        return {"step": self.step, "box_width": self.box_width, **self.counts(), "nodes": nodes}

    def save(self, path: Path) -> None:
        Path(path).write_text(json.dumps(self.to_json(), indent=1))

    def draw(self, ax) -> None:
        """Final nodes and the graph's edges, marked nodes as small dots, open candidates linked to their node."""
        g = self.graph()
        for i, j in g.edges:
            a, b = self.nodes[i].pose, self.nodes[j].pose
            ax.plot([a[0], b[0]], [a[1], b[1]], color="tab:purple", lw=0.8)
        fin = np.array([self.nodes[i].pose[:2] for i in self.final_ids]).reshape(-1, 2)
        mk = np.array([self.nodes[i].pose[:2] for i in self.marked_ids]).reshape(-1, 2)
        ax.plot(*mk.T, ".", color="0.6", ms=3, label=f"marked ({len(mk)})")
        ax.plot(*fin.T, "o", color="tab:purple", ms=5, label=f"final ({len(fin)})")
        for c in self.candidates():
            p = self.nodes[c.node].pose
            ax.plot([p[0], c.position[0]], [p[1], c.position[1]], color="tab:olive", lw=0.5)
            ax.plot(*c.position, "x", color="tab:olive", ms=4)
