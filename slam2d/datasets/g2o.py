"""2D pose graphs in g2o and TORO format: read and write.

g2o:  ``VERTEX_SE2 id x y theta`` and ``EDGE_SE2 i j dx dy dtheta I11 I12 I13 I22 I23 I33``
TORO: ``VERTEX2 id x y theta`` and ``EDGE2 i j dx dy dtheta I11 I12 I22 I33 I13 I23``

An edge's measurement is pose j seen from pose i (``geometry.between``) with
its 3x3 information matrix (inverse covariance, units 1/m^2 and 1/rad^2).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from slam2d import geometry
from slam2d.errors import InputError, not_a_file

log = logging.getLogger(__name__)

# Position of each file value in the row-major 3x3 information matrix.
_G2O_ORDER = [(0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2)]
_TORO_ORDER = [(0, 0), (0, 1), (1, 1), (2, 2), (0, 2), (1, 2)]
_VERTEX_TAGS = ("VERTEX_SE2", "VERTEX2")
_EDGE_TAGS = {"EDGE_SE2": _G2O_ORDER, "EDGE2": _TORO_ORDER}
_IGNORED_TAGS = ("FIX",)


@dataclass(eq=False)
class PoseGraphFile:
    """A 2D pose graph: vertices ``ids`` (N,) with ``poses`` (N, 3), and M edges
    ``i``, ``j`` (M,) with ``measurements`` (M, 3) and ``information`` (M, 3, 3)."""

    ids: np.ndarray
    poses: np.ndarray
    i: np.ndarray
    j: np.ndarray
    measurements: np.ndarray
    information: np.ndarray

    def __len__(self) -> int:
        return len(self.ids)


def _symmetric(values, order) -> np.ndarray:
    """3x3 symmetric matrix from 6 upper-triangle values in ``order``."""
    m = np.zeros((3, 3))
    for v, (r, c) in zip(values, order):
        m[r, c] = m[c, r] = v
    return m


def _parse_line(tokens, where: str):
    """One vertex or edge line -> ('v', id, pose) or ('e', i, j, measurement, information)."""
    tag = tokens[0]
    n = 5 if tag in _VERTEX_TAGS else 12
    if len(tokens) != n:
        raise InputError(where, f"{tag} needs {n - 1} values, got {len(tokens) - 1}")
    try:
        ids = [int(t) for t in tokens[1:2 if n == 5 else 3]]
        v = np.array(tokens[2 if n == 5 else 3:], dtype=np.float64)
    except ValueError:
        raise InputError(where, f"non-numeric field in {tag} line") from None
    if not np.all(np.isfinite(v)):
        raise InputError(where, f"non-finite value in {tag} line")
    if n == 5:
        return ("v", ids[0], v)
    return ("e", ids[0], ids[1], v[:3], _symmetric(v[3:], _EDGE_TAGS[tag]))


def read_g2o(path) -> PoseGraphFile:
    """Read a g2o or TORO 2D pose graph (FIX, blank and # lines ignored).

    A file with no vertex lines (e.g. CSAIL.g2o) gets vertices for every id
    in its edges, initialised by chaining measurements along a spanning tree.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(path, not_a_file(path) or "file not found")
    return _graph(path, *(_read_well_formed(path) or _read_lines(path)))


def _read_well_formed(path: Path):
    """The arrays of :func:`_graph` (vertex ids (N,), poses (N, 3), i, j (M,), measurements (M, 3), information
    (M, 3, 3), the edges' line numbers) of a file whose every line is well formed, parsed in numpy; None at the
    first doubt (the line-by-line reader then says where)."""
    with open(path, encoding="ascii", errors="replace") as f:
        rows = [line.split() for line in f]
    lineno = np.flatnonzero([bool(r) and not r[0].startswith("#") and r[0] not in _IGNORED_TAGS for r in rows])
    rows = [rows[k] for k in lineno.tolist()]
    tags = np.array([r[0] for r in rows])
    vertex, edge = np.isin(tags, _VERTEX_TAGS), np.isin(tags, list(_EDGE_TAGS))
    if not (vertex | edge).all() or any(len(r) != (5 if v else 12) for r, v in zip(rows, vertex.tolist())):
        return None
    try:
        v = np.array([r[1:] for r, k in zip(rows, vertex.tolist()) if k], dtype=np.float64).reshape(-1, 4)
        e = np.array([r[1:] for r, k in zip(rows, edge.tolist()) if k], dtype=np.float64).reshape(-1, 11)
    except ValueError:
        return None
    ids = v[:, 0].astype(np.int64)
    ends = e[:, :2].astype(np.int64)
    if (not np.isfinite(v).all() or not np.isfinite(e).all() or np.any(ids != v[:, 0]) or np.any(ends != e[:, :2])
            or len(set(ids.tolist())) != len(ids)):
        return None
    info = np.zeros((len(e), 3, 3))
    for tag, order in _EDGE_TAGS.items():
        rows_of_tag = tags[edge] == tag
        for k, (r, c) in enumerate(order):
            info[rows_of_tag, r, c] = info[rows_of_tag, c, r] = e[rows_of_tag, 5 + k]
    return (ids, v[:, 1:].copy(), ends[:, 0].copy(), ends[:, 1].copy(), e[:, 2:5].copy(), info,
            (lineno[edge] + 1).tolist())


def _read_lines(path: Path):
    """The arrays of :func:`_read_well_formed`, line by line: InputError at the first bad line."""
    vertices: dict[int, np.ndarray] = {}
    edges, lines = [], []
    with open(path, encoding="ascii", errors="replace") as f:
        for lineno, line in enumerate(f, 1):
            tokens = line.split()
            if not tokens or tokens[0].startswith("#") or tokens[0] in _IGNORED_TAGS:
                continue
            where = f"{path}:{lineno}"
            if tokens[0] not in _VERTEX_TAGS and tokens[0] not in _EDGE_TAGS:
                raise InputError(where, f"unsupported line type {tokens[0]!r}")
            rec = _parse_line(tokens, where)
            if rec[0] == "v":
                if rec[1] in vertices:
                    raise InputError(where, f"duplicate vertex {rec[1]}")
                vertices[rec[1]] = rec[2]
            else:
                edges.append(rec[1:])
                lines.append(lineno)
    ids = np.array(list(vertices), dtype=np.int64)
    poses = np.array(list(vertices.values())).reshape(-1, 3)
    i, j, meas, info = (np.array(a) for a in zip(*edges)) if edges else (
        np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros((0, 3)), np.zeros((0, 3, 3)))
    return ids, poses, i, j, meas, info, lines


def _graph(path: Path, ids, poses, i, j, meas, info, lines: list) -> PoseGraphFile:
    """The PoseGraphFile of the parsed arrays, vertices sorted by id; InputError for an empty file, an
    information matrix that is not positive definite, an edge to an unknown vertex."""
    if not len(ids) and not len(i):
        raise InputError(path, "no vertices or edges")
    not_pd = np.linalg.eigvalsh(info)[:, 0] <= 0 if len(i) else np.zeros(0, bool)  # eigenvalues ascend
    if not_pd.any():
        k = int(np.argmax(not_pd))
        raise InputError(f"{path}:{lines[k]}", "information matrix is not positive definite")
    if len(ids):
        unknown = ~np.isin(i, ids) | ~np.isin(j, ids)
        if unknown.any():
            k = int(np.argmax(unknown))
            raise InputError(f"{path}:{lines[k]}", f"edge {i[k]} -> {j[k]} to an unknown vertex")
        order = np.argsort(ids, kind="stable")
        ids, poses = ids[order], poses[order]
    else:
        ids = np.unique(np.r_[i, j])
        poses = _chain_poses(ids, i, j, meas)
        log.info("%s: no vertex lines; %d poses initialised from the edges", path, len(ids))
    return PoseGraphFile(ids, poses, i, j, meas, info)


def _chain_poses(ids, i, j, meas) -> np.ndarray:
    """Poses for ``ids`` composed along a breadth-first spanning tree of the edges.

    The first id sits at the origin; ids not connected to it stay at the origin.
    """
    a, b = np.searchsorted(ids, i), np.searchsorted(ids, j)
    order, pred = _breadth_first(len(ids), a, b)
    edge = {(x, y): k for k, (x, y) in enumerate(zip(a.tolist(), b.tolist()))}
    steps, pred = meas.tolist(), pred.tolist()
    poses = [[0.0, 0.0, 0.0] for _ in ids]
    for v in order[1:].tolist():  # in Python floats: the same numbers as geometry.compose, 20 x faster
        p = pred[v]
        step = steps[edge[p, v]] if (p, v) in edge else geometry.inverse_floats(steps[edge[v, p]])
        poses[v] = geometry.compose_floats(poses[p], step)
    if len(order) < len(ids):
        log.warning("%d poses not connected to pose %d; left at the origin", len(ids) - len(order), ids[0])
    return np.array(poses).reshape(-1, 3)


def _breadth_first(n: int, a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(order, predecessors) of a breadth-first search from vertex 0 over the undirected edges ``a`` - ``b`` of
    ``n`` vertices, as scipy's ``csgraph.breadth_first_order(..., directed=False)`` gives them (each vertex's
    successors ``b`` by rank, then its predecessors ``a``; -9999 for vertex 0 and those not reached): numpy
    and a loop over the vertices, no scipy import."""
    out = [_neighbours(n, a, b), _neighbours(n, b, a)]
    pred = [-9999] * n
    seen = [True] + [False] * (n - 1)
    order = [0]
    for p in order:
        for starts, ends in out:
            for c in ends[starts[p]:starts[p + 1]]:
                if not seen[c]:
                    seen[c] = True
                    pred[c] = p
                    order.append(c)
    return np.array(order, dtype=np.int32), np.array(pred, dtype=np.int32)


def _neighbours(n: int, a: np.ndarray, b: np.ndarray) -> tuple[list, list]:
    """The distinct ``b`` of each ``a``, ascending, as (row starts (n + 1,), ends) lists (a CSR pattern)."""
    pairs = np.unique(np.column_stack([a, b]).astype(np.int64), axis=0)
    return np.searchsorted(pairs[:, 0], np.arange(n + 1)).tolist(), pairs[:, 1].tolist()


def write_g2o(path, graph: PoseGraphFile) -> None:
    """Write ``graph`` in g2o format with full float64 precision (round-trips exactly)."""
    rows = [f"VERTEX_SE2 {k} {x!r} {y!r} {t!r}" for k, (x, y, t) in zip(graph.ids.tolist(), graph.poses.tolist())]
    upper = graph.information[:, [r for r, _ in _G2O_ORDER], [c for _, c in _G2O_ORDER]]
    for a, b, m, u in zip(graph.i.tolist(), graph.j.tolist(), graph.measurements.tolist(), upper.tolist()):
        rows.append(f"EDGE_SE2 {a} {b} " + " ".join(map(repr, m + u)))
    Path(path).write_text("\n".join(rows) + "\n")


# ------------------------------------------------------------ outlier loops

OUTLIER_KINDS = ("random", "local", "group")
OUTLIER_SPAN_M = 10.0  # m: a false loop's translation is uniform within +-this (heading within +-pi)
LOCAL_SPAN = 10  # local false loops join poses at most this many vertices apart
GROUP_SIZE = 10  # group false loops come in clusters of this many mutually consistent edges


def odometry_mask(graph: PoseGraphFile) -> np.ndarray:
    """(M,) bool: the first edge from each vertex to the next id (``j == i + 1``); the rest are loops."""
    mask = np.zeros(len(graph.i), bool)
    seen: set[int] = set()
    for k, (a, b) in enumerate(zip(graph.i.tolist(), graph.j.tolist())):
        if b == a + 1 and a not in seen:
            mask[k] = True
            seen.add(a)
    return mask


def _outlier_pairs(n: int, count: int, kind: str, rng) -> tuple[np.ndarray, np.ndarray]:
    """Vertex rows (a, b) of ``count`` false loops: uniform pairs, or pairs 2..LOCAL_SPAN apart."""
    if kind == "random":
        a = rng.integers(0, n, count)
        b = (a + rng.integers(1, n, count)) % n  # never a == b
        return a, b
    a = rng.integers(0, n - 2, count)
    b = np.minimum(a + rng.integers(2, LOCAL_SPAN + 1, count), n - 1)
    return a, b


def _group_outliers(graph: PoseGraphFile, count: int, rng):
    """Clusters of GROUP_SIZE false loops (a+k, b+k), consistent with one false offset and the graph's poses."""
    n, rows_a, rows_b, meas = len(graph.ids), [], [], []
    while len(rows_a) < count:
        size = min(GROUP_SIZE, count - len(rows_a))
        a, b = rng.integers(0, n - size, 2)
        if abs(int(a) - int(b)) < 2 * size:
            continue
        offset = _random_measurement(rng)
        for k in range(size):
            da = geometry.between(graph.poses[a], graph.poses[a + k])
            db = geometry.between(graph.poses[b], graph.poses[b + k])
            meas.append(geometry.compose(geometry.inverse(da), geometry.compose(offset, db)))
            rows_a.append(a + k)
            rows_b.append(b + k)
    return np.array(rows_a), np.array(rows_b), np.array(meas).reshape(-1, 3)


def _random_measurement(rng, count: int | None = None) -> np.ndarray:
    size = 3 if count is None else (count, 3)
    return rng.uniform(-1, 1, size) * np.array([OUTLIER_SPAN_M, OUTLIER_SPAN_M, np.pi])


def inject_outliers(graph: PoseGraphFile, count: int, kind: str = "random", seed: int = 0):
    """``graph`` with ``count`` false loop closures appended, the Vertigo way; returns
    ``(graph, injected)`` with ``injected`` (M',) True on the new edges.

    ``random``: uniform vertex pairs; ``local``: pairs 2..LOCAL_SPAN vertices apart;
    ``group``: clusters of GROUP_SIZE mutually consistent false loops. Measurements
    are uniform within +-OUTLIER_SPAN_M m and +-pi rad (one per group); each takes the
    information of a random true loop (of any edge if there is none)."""
    if kind not in OUTLIER_KINDS:
        raise InputError("outlier kind", f"unknown kind {kind!r} (choose from {', '.join(OUTLIER_KINDS)})")
    if count < 0 or len(graph.ids) < GROUP_SIZE + 2:
        raise InputError("outliers", f"need count >= 0 and at least {GROUP_SIZE + 2} vertices")
    rng = np.random.default_rng(seed)
    if kind == "group":
        a, b, meas = _group_outliers(graph, count, rng)
    else:
        a, b = _outlier_pairs(len(graph.ids), count, kind, rng)
        meas = _random_measurement(rng, count)
    loops = np.flatnonzero(~odometry_mask(graph))
    pool = loops if len(loops) else np.arange(len(graph.i))
    info = graph.information[rng.choice(pool, count)]
    out = PoseGraphFile(graph.ids, graph.poses, np.r_[graph.i, graph.ids[a]], np.r_[graph.j, graph.ids[b]],
                        np.r_[graph.measurements, meas].reshape(-1, 3),
                        np.r_[graph.information, info].reshape(-1, 3, 3))
    return out, np.r_[np.zeros(len(graph.i), bool), np.ones(count, bool)]
