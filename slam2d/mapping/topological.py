"""Topological map: a region graph (networkx) from a room segmentation.

A node per region (label > 0) with

- ``centre`` (x, y) m: the region's cell nearest its centroid, so it lies
  inside the room even when the room is not convex; ``centre_cell`` (row, col);
- ``area`` m², ``cells`` count;

an edge per pair of regions with 8-adjacent cells, with

- ``portal``: (row, col) cells of either region sharing a side with the other
  (a corner when they touch only diagonally), for the widest opening when they
  touch in several places (doors); ``openings``: how many separate openings
  (8-connected pieces of such cells) they share;
- ``portal_centre`` (x, y) m: the portal cell nearest the portal's mean;
- ``width`` m: the portal's extent along its main axis (the larger of the
  two sides' cells, plus one cell: a door 10 cells wide gives 10 res);
- ``cost`` m: centre -> portal centre -> centre.

Cell to world. Two layouts, chosen by ``row0_top``:

- ``row0_top=True`` (floor-plan images, PNG, labels as read from the file):
  row 0 is the top of the map, ``x = ox + (col + 0.5) res``,
  ``y = oy + (H - 1 - row + 0.5) res``;
- ``row0_top=False`` (:class:`slam2d.mapping.occupancy.OccupancyGrid`, whose
  row index is y going up): ``x = ox + (col + 0.5) res``,
  ``y = oy + (row + 0.5) res``.

Either way ``origin`` is the lower-left corner of the map (as map_server's
``origin``) and cells are (row, col) of the array given.
"""

from __future__ import annotations

import json
from pathlib import Path

import networkx as nx
import numpy as np
from scipy import ndimage

from slam2d.errors import InputError, not_a_file

__all__ = ["region_graph", "cell_to_world", "world_to_cell", "save_graph", "load_graph", "draw_graph"]

_OFFSETS = ((0, 1), (1, 0), (1, 1), (1, -1))
"""Half of the 8-neighbourhood (the first two: of the 4-neighbourhood): each adjacent pair once."""


def cell_to_world(cells, shape, resolution, origin=(0.0, 0.0), row0_top=True) -> np.ndarray:
    """Centres (..., 2) as (x, y) m of cells (..., 2) as (row, col) of an array of ``shape`` (H, W)."""
    rc = np.asarray(cells, dtype=np.float64)
    row = (shape[0] - 1 - rc[..., 0]) if row0_top else rc[..., 0]
    return np.stack([origin[0] + (rc[..., 1] + 0.5) * resolution, origin[1] + (row + 0.5) * resolution], -1)


def world_to_cell(xy, shape, resolution, origin=(0.0, 0.0), row0_top=True) -> np.ndarray:
    """Integer (row, col) (..., 2) of the cells containing points (..., 2) as (x, y) m (may lie outside)."""
    xy = np.asarray(xy, dtype=np.float64)
    col = np.floor((xy[..., 0] - origin[0]) / resolution)
    row = np.floor((xy[..., 1] - origin[1]) / resolution)
    row = (shape[0] - 1 - row) if row0_top else row
    return np.stack([row, col], -1).astype(np.int64)


def region_graph(labels, resolution, origin=(0.0, 0.0), row0_top=True) -> nx.Graph:
    """Region adjacency graph of ``labels`` (H, W) int (0 = no region); see the module docstring."""
    labels = np.asarray(labels)
    if labels.ndim != 2 or not np.issubdtype(labels.dtype, np.integer):
        raise InputError("labels", f"expected a 2-D integer label image, got {labels.dtype} {labels.shape}")
    res, origin = float(resolution), (float(origin[0]), float(origin[1]))
    g = nx.Graph(resolution=res, origin=list(origin), shape=list(labels.shape), row0_top=bool(row0_top))

    def to_world(cells):
        return cell_to_world(cells, labels.shape, res, origin, row0_top)

    for lab, cell, count in _region_centres(labels):
        x, y = to_world(cell)
        g.add_node(lab, centre=(float(x), float(y)), centre_cell=(int(cell[0]), int(cell[1])),
                   cells=int(count), area=float(count * res * res))  # fmt: skip
    faces = _boundary_cells(labels, _OFFSETS[:2])
    for (a, b), cells in _boundary_cells(labels).items():
        pieces = _pieces(faces.get((a, b), cells))
        portal = max(pieces, key=len)
        xy = to_world(portal)
        mid = portal[np.argmin(((xy - xy.mean(0)) ** 2).sum(1))]
        pc = to_world(mid)
        ca, cb = np.array(g.nodes[a]["centre"]), np.array(g.nodes[b]["centre"])
        g.add_edge(
            a, b,
            portal=[(int(r), int(c)) for r, c in portal],
            portal_centre=(float(pc[0]), float(pc[1])),
            width=max(_extent(xy[labels[portal[:, 0], portal[:, 1]] == lab]) for lab in (a, b)) + res,
            openings=len(pieces),
            cost=float(np.hypot(*(pc - ca)) + np.hypot(*(pc - cb))),
        )  # fmt: skip
    return g


def _region_centres(labels: np.ndarray):
    """(label, (row, col) of the region's cell nearest its centroid, cell count) for every label > 0;
    among cells equally near, the first in raster order."""
    rows, cols = np.nonzero(labels > 0)
    lab = labels[rows, cols]
    count = np.bincount(lab)
    ids = np.flatnonzero(count)
    ids = ids[ids > 0]
    mr = np.bincount(lab, rows) / np.maximum(count, 1)
    mc = np.bincount(lab, cols) / np.maximum(count, 1)
    d2 = (rows - mr[lab]) ** 2 + (cols - mc[lab]) ** 2
    least = np.full(len(count), np.inf)
    np.minimum.at(least, lab, d2)
    nearest = d2 == least[lab]
    _, first = np.unique(lab[nearest], return_index=True)
    first = np.flatnonzero(nearest)[first]
    return [(int(i), (int(rows[j]), int(cols[j])), int(count[i])) for i, j in zip(ids, first)]


def _boundary_cells(labels: np.ndarray, offsets=_OFFSETS) -> dict:
    """{(a, b): (P, 2) (row, col) cells of a or b adjacent to the other region}, a < b.

    ``offsets``: half of the neighbourhood, (dr, dc) pairs (8-adjacency by default).
    """
    h, w = labels.shape
    flat = labels.ravel()
    idx = np.arange(h * w).reshape(h, w)
    keys, cells = [], []
    for dr, dc in offsets:
        r0, r1 = slice(0, h - dr), slice(dr, h)
        c0, c1 = (slice(0, w - dc), slice(dc, w)) if dc >= 0 else (slice(-dc, w), slice(0, w + dc))
        p, q = idx[r0, c0].ravel(), idx[r1, c1].ravel()
        m = (flat[p] != flat[q]) & (flat[p] > 0) & (flat[q] > 0)
        p, q = p[m], q[m]
        key = np.minimum(flat[p], flat[q]).astype(np.int64) << 32 | np.maximum(flat[p], flat[q]).astype(np.int64)
        keys += [key, key]
        cells += [p, q]
    key, cell = np.concatenate(keys), np.concatenate(cells)
    if len(key) == 0:
        return {}
    pairs, pair = np.unique(key, return_inverse=True)
    combined = np.unique(pair.astype(np.int64) * (h * w) + cell)
    pair, cell = np.divmod(combined, h * w)
    start = np.searchsorted(pair, np.arange(len(pairs)))
    return {
        (int(k >> 32), int(k & 0xFFFFFFFF)): np.column_stack(np.unravel_index(c, (h, w)))
        for k, c in zip(pairs, np.split(cell, start[1:]))
    }


def _pieces(cells: np.ndarray) -> list[np.ndarray]:
    """Split (P, 2) cells into 8-connected pieces."""
    lo = cells.min(0)
    local = cells - lo
    mask = np.zeros(local.max(0) + 1, bool)
    mask[local[:, 0], local[:, 1]] = True
    lab, n = ndimage.label(mask, structure=np.ones((3, 3), bool))
    which = lab[local[:, 0], local[:, 1]]
    return [cells[which == i] for i in range(1, n + 1)]


def _extent(xy: np.ndarray) -> float:
    """Length (m) of points (P, 2) along their principal axis."""
    if len(xy) < 2:
        return 0.0  # one cell (or none): the caller adds the cell size
    centred = xy - xy.mean(0)
    _, _, vt = np.linalg.svd(centred, full_matrices=False)
    proj = centred @ vt[0]
    return float(proj.max() - proj.min())


_TUPLE_NODE = ("centre", "centre_cell")
_TUPLE_EDGE = ("portal_centre",)


def save_graph(g: nx.Graph, path) -> Path:
    """Write ``g`` as JSON (networkx node-link data); :func:`load_graph` restores it exactly."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    data = nx.node_link_data(g, edges="edges")
    path.write_text(json.dumps(data, indent=1))
    return path


def load_graph(path) -> nx.Graph:
    """Read a graph written by :func:`save_graph` (tuples restored: centres, portal cells)."""
    path = Path(path)
    if not path.is_file():
        raise InputError(path, not_a_file(path) or "graph file not found")
    try:
        data = json.loads(path.read_text())
        g = nx.node_link_graph(data, edges="edges")
    except (json.JSONDecodeError, KeyError, TypeError) as exc:
        raise InputError(path, f"not a node-link graph JSON ({exc})") from None
    for _, d in g.nodes(data=True):
        for k in _TUPLE_NODE:
            if k in d:
                d[k] = tuple(d[k])
    for _, _, d in g.edges(data=True):
        for k in _TUPLE_EDGE:
            if k in d:
                d[k] = tuple(d[k])
        if "portal" in d:
            d["portal"] = [tuple(c) for c in d["portal"]]
    return g


def draw_graph(ax, g: nx.Graph, node_color="k", edge_color="k", node_size=30.0, linewidth=1.2, labels=True):
    """Draw ``g`` on a matplotlib axes in world coordinates (m): nodes at their centres,
    each edge as centre -> portal centre -> centre, portal centres as small squares."""
    for a, b, d in g.edges(data=True):
        pts = np.array([g.nodes[a]["centre"], d["portal_centre"], g.nodes[b]["centre"]])
        ax.plot(pts[:, 0], pts[:, 1], color=edge_color, linewidth=linewidth, zorder=3)
        ax.plot(*d["portal_centre"], marker="s", markersize=3, color=edge_color, zorder=4)
    if g.number_of_nodes():
        xy = np.array([d["centre"] for _, d in g.nodes(data=True)])
        ax.scatter(xy[:, 0], xy[:, 1], s=node_size, c=node_color, edgecolors="w", linewidths=0.8, zorder=5)
    if labels:
        for n, d in g.nodes(data=True):
            ax.annotate(str(n), d["centre"], xytext=(3, 3), textcoords="offset points", fontsize=6, zorder=6)
    return ax
