"""Similarity of observations for spectral map segmentation (thesis ch. 4.3).

Every measure returns a symmetric (N, N) matrix with unit diagonal and values
in [0, 1]: a dense ``np.ndarray`` (visibility) or a ``scipy.sparse.csr_array``
(the point-set measures, which only compare observations closer than
``radius`` metres; farther pairs are 0). The normalisation of each measure is
stated in its docstring.
"""

from __future__ import annotations

import logging

import numpy as np
from numba import njit
from scipy import sparse
from scipy.sparse import csgraph
from scipy.spatial import cKDTree

from slam2d.errors import InputError
from slam2d.segmentation.base import SIMILARITY_MEASURES, register_similarity
from slam2d.segmentation.observations import Observations, cell_centres

__all__ = [
    "hausdorff_similarity",
    "nearest_neighbour_similarity",
    "feature_point_similarity",
    "visibility_similarity",
    "extract_corners",
    "associate_corners",
    "directed_distances",
    "local_scale",
    "similarity_matrix",
    "SIMILARITIES",
]

log = logging.getLogger(__name__)


# --------------------------------------------------------------------------- helpers


def _candidate_pairs(obs: Observations, radius: float) -> np.ndarray:
    """Pairs (P, 2), i < j, of observations whose positions are within ``radius`` m."""
    tree = cKDTree(obs.poses[:, :2])
    return tree.query_pairs(radius, output_type="ndarray").astype(np.int64).reshape(-1, 2)


def _symmetric_sparse(n: int, pairs: np.ndarray, values: np.ndarray) -> sparse.csr_array:
    """Symmetric csr (n, n) from upper pairs and values, unit diagonal; zero values dropped."""
    keep = values > 0
    i, j, v = pairs[keep, 0], pairs[keep, 1], values[keep]
    rows = np.concatenate([i, j, np.arange(n)])
    cols = np.concatenate([j, i, np.arange(n)])
    vals = np.concatenate([v, v, np.ones(n)])
    return sparse.csr_array((vals, (rows, cols)), shape=(n, n))


def _subsample(obs: Observations, max_points: int | None) -> tuple[np.ndarray, np.ndarray]:
    """Hit points and offsets with at most ``max_points`` per observation (evenly by scan index)."""
    counts = np.diff(obs.offsets)
    if max_points is None or counts.size == 0 or counts.max() <= max_points:
        return obs.points, obs.offsets
    owner = obs.owner()
    rank = np.arange(len(obs.points)) - obs.offsets[owner]
    stride = np.maximum(1, np.ceil(counts / max_points)).astype(np.int64)
    keep = rank % stride[owner] == 0
    new_counts = np.bincount(owner[keep], minlength=len(obs))
    return obs.points[keep], np.concatenate([[0], np.cumsum(new_counts)]).astype(np.int64)


@njit(cache=True, nogil=True)
def _directed(points, offsets, pairs, threshold, out):
    """Per pair (i, j) and direction: max of nearest distances, residual sum, point count.

    out[p] = [h(i->j), h(j->i), res(i->j), res(j->i), n_i, n_j], where res sums
    the nearest distances that are >= threshold.
    """
    for p in range(pairs.shape[0]):
        for side in range(2):
            a = pairs[p, side]
            b = pairs[p, 1 - side]
            a0, a1 = offsets[a], offsets[a + 1]
            b0, b1 = offsets[b], offsets[b + 1]
            hmax = 0.0
            res = 0.0
            if b1 == b0:
                hmax = np.inf if a1 > a0 else 0.0
            else:
                for u in range(a0, a1):
                    best = np.inf
                    for v in range(b0, b1):
                        dx = points[u, 0] - points[v, 0]
                        dy = points[u, 1] - points[v, 1]
                        d = dx * dx + dy * dy
                        if d < best:
                            best = d
                    best = np.sqrt(best)
                    if best > hmax:
                        hmax = best
                    if best >= threshold:
                        res += best
            out[p, side] = hmax
            out[p, 2 + side] = res
            out[p, 4 + side] = a1 - a0


def directed_distances(points, offsets, pairs, threshold: float = 0.0) -> np.ndarray:
    """Nearest-point statistics (P, 6) for pairs (P, 2) of ragged point sets (numba, exact).

    Columns: h(A, B), h(B, A) (directed Hausdorff, m); residual sums over A and
    over B of nearest distances ``>= threshold`` (m); |A|, |B|.
    """
    pairs = np.ascontiguousarray(np.asarray(pairs, dtype=np.int64).reshape(-1, 2))
    out = np.zeros((len(pairs), 6))
    _directed(np.ascontiguousarray(points, dtype=np.float64), np.asarray(offsets, dtype=np.int64),
              pairs, float(threshold), out)
    return out


# --------------------------------------------------------------------------- (1) Hausdorff


def local_scale(n: int, pairs: np.ndarray, dist: np.ndarray, knn: int = 7) -> np.ndarray:
    """Per-observation scale (n,): its ``knn``-th smallest distance over its candidate pairs
    (Zelnik-Manor & Perona 2004, self-tuning); observations with fewer pairs take their
    largest, those with none the median scale."""
    i = np.concatenate([pairs[:, 0], pairs[:, 1]])
    d = np.concatenate([dist, dist])
    ok = np.isfinite(d)
    i, d = i[ok], d[ok]
    order = np.lexsort((d, i))
    i, d = i[order], d[order]
    start = np.searchsorted(i, np.arange(n))
    count = np.bincount(i, minlength=n)
    pick = start + np.clip(np.minimum(count, knn) - 1, 0, None)
    sc = np.where(count > 0, d[np.minimum(pick, max(len(d) - 1, 0))] if len(d) else 0.0, np.nan)
    med = np.nanmedian(sc) if np.isfinite(sc).any() else 1.0
    return np.maximum(np.where(np.isfinite(sc), sc, med), 1e-6)


@register_similarity("hausdorff")
def hausdorff_similarity(obs: Observations, sigma: float | None = None, radius: float = 4.0,
                         max_points: int | None = 60, knn: int = 15) -> sparse.csr_array:
    """Hausdorff similarity of the observations' hit points: exp(-H / sigma), or with
    ``sigma=None`` the self-tuning exp(-H^2 / (sigma_i sigma_j)).

    H(A, B) = max(h(A, B), h(B, A)), h(A, B) = max_a min_b |a - b| (m), exact
    on at most ``max_points`` points per scan (evenly subsampled). sigma_i is
    observation i's ``knn``-th smallest H (:func:`local_scale`), so the measure
    adapts to how far apart the viewpoints are. Pairs of observations farther
    apart than ``radius`` m, and pairs where one side has no points, get 0.
    """
    pairs = _candidate_pairs(obs, radius)
    pts, off = _subsample(obs, max_points)
    st = directed_distances(pts, off, pairs)
    h = np.maximum(st[:, 0], st[:, 1])
    with np.errstate(invalid="ignore", over="ignore"):
        if sigma is None:
            sc = local_scale(len(obs), pairs, h, knn)
            val = np.exp(-(h**2) / (sc[pairs[:, 0]] * sc[pairs[:, 1]]))
        else:
            val = np.exp(-h / sigma)
    return _symmetric_sparse(len(obs), pairs, np.where(np.isfinite(h), val, 0.0))


# --------------------------------------------------------------------------- (2) nearest neighbour


@register_similarity("nearest_neighbour")
def nearest_neighbour_similarity(obs: Observations, threshold: float = 0.1, sigma: float | None = None,
                                 radius: float = 4.0, max_points: int | None = 60, knn: int = 7) -> sparse.csr_array:
    """Nearest-neighbour similarity 1 / (1 + R / sigma) (thesis Algorithm 1, bounded and symmetric).

    A point of O_i with a point of O_j closer than ``threshold`` m is shared and
    adds nothing; any other point adds its nearest distance to the residual.
    R is the residual of both directions over the points of both scans (m per
    point), so S = 1 for identical scans and S -> 0 as the scans part (the
    thesis's 1 / residual is unbounded). ``sigma`` m sets the scale; with
    ``sigma=None`` it is sqrt(sigma_i sigma_j), sigma_i the ``knn``-th
    smallest R of observation i (:func:`local_scale`). At most ``max_points``
    points per scan; pairs farther apart than ``radius`` m get 0.
    """
    pairs = _candidate_pairs(obs, radius)
    pts, off = _subsample(obs, max_points)
    st = directed_distances(pts, off, pairs, threshold)
    n = st[:, 4] + st[:, 5]
    both = (st[:, 4] > 0) & (st[:, 5] > 0)
    with np.errstate(invalid="ignore", divide="ignore"):
        r = np.where(both, (st[:, 2] + st[:, 3]) / n, np.inf)
    if sigma is None:
        sc = local_scale(len(obs), pairs, r, knn)
        scale = np.sqrt(sc[pairs[:, 0]] * sc[pairs[:, 1]])
    else:
        scale = float(sigma)
    val = np.where(both, 1.0 / (1.0 + r / scale), 0.0)
    return _symmetric_sparse(len(obs), pairs, val)


# --------------------------------------------------------------------------- (3) feature points


def _moving_mean(x: np.ndarray, window: int, circular: np.ndarray) -> np.ndarray:
    """Row-wise moving mean (N, B) with NaN-aware edges; rows with ``circular`` wrap around."""
    h = window // 2
    pad_c = np.concatenate([x[:, -h:], x, x[:, :h]], axis=1) if h else x
    pad_e = np.pad(x, ((0, 0), (h, h)), constant_values=np.nan) if h else x
    pad = np.where(circular[:, None], pad_c, pad_e)
    ok = np.isfinite(pad)
    c = np.cumsum(np.pad(np.where(ok, pad, 0.0), ((0, 0), (1, 0))), axis=1)
    k = np.cumsum(np.pad(ok.astype(np.float64), ((0, 0), (1, 0))), axis=1)
    s = c[:, window:] - c[:, :-window]
    m = k[:, window:] - k[:, :-window]
    with np.errstate(invalid="ignore", divide="ignore"):
        return s / m


def _padded_beams(obs: Observations) -> tuple[np.ndarray, np.ndarray]:
    """Ranges (N, B) padded with NaN (no-return beams NaN too) and the beam index of each slot."""
    counts = np.diff(obs.beam_offsets)
    b = int(counts.max()) if len(counts) else 0
    owner = np.repeat(np.arange(len(obs)), counts)
    rank = np.arange(len(obs.beam_ranges)) - obs.beam_offsets[owner]
    r = np.full((len(obs), b), np.nan)
    idx = np.full((len(obs), b), -1, dtype=np.int64)
    r[owner, rank] = np.where(obs.beam_hit, obs.beam_ranges, np.nan)
    idx[owner, rank] = np.arange(len(obs.beam_ranges))
    return r, idx


def _full_circle(obs: Observations) -> np.ndarray:
    """Whether each observation's beams cover 360 deg evenly (then corners wrap around)."""
    counts = np.diff(obs.beam_offsets)
    first = obs.beam_angles[np.minimum(obs.beam_offsets[:-1], max(len(obs.beam_angles) - 1, 0))]
    last = obs.beam_angles[np.maximum(obs.beam_offsets[1:] - 1, 0)]
    step = 2 * np.pi / np.maximum(counts, 1)
    gap = np.mod(first - last, 2 * np.pi)
    return (counts > 2) & (np.abs(gap - step) < 0.5 * step)


def extract_corners(obs: Observations, window: int = 3, baseline: int = 4, min_angle_deg: float = 45.0,
                    jump: float = 0.3, edge: int = 2) -> tuple[np.ndarray, np.ndarray]:
    """Corners of every scan (thesis 2.3): points (C, 2) in the map frame and their observation (C,).

    Ranges are mean-filtered over ``window`` beams and turned into the scan
    curve; its first derivative (direction over ``baseline`` beams, before and
    after each beam) turns sharply at a corner. A corner is a local maximum
    (within +-baseline) of that turn, of at least ``min_angle_deg``. The turn
    of the curve, unlike the extrema of r' the thesis uses, is the same from
    any viewpoint (r' also peaks along walls seen at grazing angles).
    Rejected: beams within +-baseline of a range jump > ``jump`` m (or 10 %
    of the range) or of a no-return beam, and the first/last ``edge`` beams of
    a scan that does not cover 360 deg (full circles wrap around).
    """
    r, idx = _padded_beams(obs)
    if r.size == 0:
        return np.zeros((0, 2)), np.zeros(0, dtype=np.int64)
    circ = _full_circle(obs)
    rs = _moving_mean(r, window, circ)
    ang = np.where(idx >= 0, obs.beam_angles[np.maximum(idx, 0)], np.nan)
    x, y = rs * np.cos(ang), rs * np.sin(ang)
    fx, fy = _roll_c(x, -baseline, circ) - x, _roll_c(y, -baseline, circ) - y
    bx, by = x - _roll_c(x, baseline, circ), y - _roll_c(y, baseline, circ)
    with np.errstate(invalid="ignore", divide="ignore"):
        cos_t = (fx * bx + fy * by) / (np.hypot(fx, fy) * np.hypot(bx, by))
    turn = np.degrees(np.arccos(np.clip(cos_t, -1.0, 1.0)))
    raw_jump = np.abs(_diff_c(r, circ))
    bad = ~np.isfinite(raw_jump) | (raw_jump > np.maximum(jump, 0.1 * np.nan_to_num(r, nan=0.0)))
    near_bad = np.zeros_like(bad)
    for sh in range(-baseline, baseline + 1):  # a few shifts, each vectorised over all beams
        near_bad |= _roll_c(bad, sh, circ, fill=True)
    turn = np.where(np.isfinite(turn) & ~near_bad, turn, -1.0)
    ok = (turn >= min_angle_deg) & (turn >= _window_max(turn, baseline, circ)) & (idx >= 0)
    cols = np.arange(r.shape[1])[None, :]
    counts = np.diff(obs.beam_offsets)[:, None]
    ok &= circ[:, None] | ((cols >= edge) & (cols < counts - edge))
    n_i, col = np.nonzero(ok)
    beam = idx[n_i, col]
    rr, a = obs.beam_ranges[beam], obs.beam_angles[beam]
    pts = obs.poses[n_i, :2] + rr[:, None] * np.column_stack([np.cos(a), np.sin(a)])
    return pts, n_i.astype(np.int64)


def _roll_c(x: np.ndarray, shift: int, circular: np.ndarray, fill=np.nan) -> np.ndarray:
    """out[:, i] = x[:, i - shift], wrapping for circular rows, ``fill`` past the ends otherwise."""
    rolled = np.roll(x, shift, axis=1)
    if shift == 0:
        return rolled
    flat = rolled.copy()
    if shift > 0:
        flat[:, :shift] = fill
    else:
        flat[:, shift:] = fill
    return np.where(circular[:, None], rolled, flat)


def _diff_c(x: np.ndarray, circular: np.ndarray) -> np.ndarray:
    """out[:, i] = x[:, i+1] - x[:, i] (NaN at the end of non-circular rows)."""
    return _roll_c(x, -1, circular) - x


def _window_max(x: np.ndarray, window: int, circular: np.ndarray) -> np.ndarray:
    """Row-wise maximum over +-window (wrapping for circular rows)."""
    from scipy.ndimage import maximum_filter1d

    wrap = maximum_filter1d(x, 2 * window + 1, axis=1, mode="wrap")
    near = maximum_filter1d(x, 2 * window + 1, axis=1, mode="nearest")
    return np.where(circular[:, None], wrap, near)


def associate_corners(points: np.ndarray, threshold: float = 0.3) -> np.ndarray:
    """Global corner id (C,) per corner: connected components of the ``threshold``-m radius graph.

    The order-independent form of the thesis's global list (Algorithm 2):
    corners closer than ``threshold`` m, directly or through a chain, are one
    corner.
    """
    n = len(points)
    if n == 0:
        return np.zeros(0, dtype=np.int64)
    pairs = cKDTree(points).query_pairs(threshold, output_type="ndarray")
    g = sparse.coo_array((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(n, n))
    return csgraph.connected_components(g, directed=False)[1].astype(np.int64)


@register_similarity("feature_points", options_of=(extract_corners,))
def feature_point_similarity(obs: Observations, threshold: float = 0.3, min_views: int = 2,
                             norm: str = "min", **corner_kw) -> sparse.csr_array:
    """Shared corners |C_i & C_j| / min(|C_i|, |C_j|) (``norm="min"``) or Jaccard (``norm="jaccard"``).

    Corners from :func:`extract_corners` (keyword arguments pass through),
    associated globally by :func:`associate_corners` (``threshold`` m); global
    corners seen by fewer than ``min_views`` observations are dropped (thesis:
    a corner in one observation only is spurious). Observations without
    corners are similar to nothing but themselves.
    """
    if norm not in ("min", "jaccard"):
        raise InputError("feature_point_similarity", f"norm must be 'min' or 'jaccard', got {norm!r}")
    pts, owner = extract_corners(obs, **corner_kw)
    gid = associate_corners(pts, threshold)
    n = len(obs)
    m = sparse.csr_array((np.ones(len(gid)), (owner, gid)), shape=(n, int(gid.max()) + 1 if len(gid) else 0))
    m.sum_duplicates()
    m.data[:] = 1.0  # a global corner seen twice in one scan counts once
    views = np.asarray(m.sum(axis=0)).ravel()
    m = (m @ sparse.diags_array((views >= min_views).astype(np.float64))).tocsr()
    m.eliminate_zeros()
    inter = (m @ m.T).tocoo()
    size = np.asarray(m.sum(axis=1)).ravel()
    i, j, c = inter.row, inter.col, inter.data
    up = i < j
    i, j, c = i[up], j[up], c[up]
    den = np.minimum(size[i], size[j]) if norm == "min" else size[i] + size[j] - c
    return _symmetric_sparse(n, np.column_stack([i, j]), c / den)


# --------------------------------------------------------------------------- (4) virtual visibility


def virtual_points(obs: Observations, spacing_m: float | None = None) -> np.ndarray:
    """Virtual feature points (P, 2), m: the free cells of the observations' grid on a square
    lattice every ``spacing_m`` m; without a grid (or spacing), the observation positions."""
    if obs.free is None or spacing_m is None:
        return obs.poses[:, :2].copy()
    step = max(1, int(round(spacing_m / obs.resolution)))
    off = step // 2
    sub = obs.free[off::step, off::step]
    rows, cols = np.nonzero(sub)
    return cell_centres(np.column_stack([rows * step + off, cols * step + off]), obs.resolution, obs.origin)


@register_similarity("visibility")
def visibility_similarity(obs: Observations, spacing_m: float | None = 1.0, norm: str = "jaccard",
                          slack: float = 0.05) -> np.ndarray:
    """Virtual-visibility similarity (thesis eq. 19): shared visible virtual points, normalised.

    Obv_i = virtual points (:func:`virtual_points`, lattice every ``spacing_m``
    m) that observation i sees (:meth:`Observations.sees`, ``slack`` m). With
    V the (N, P) visibility matrix, the counts |Obv_i & Obv_j| are V V^T (one
    float32 matrix product); normalised by Jaccard |A & B| / |A | B|
    (``norm="jaccard"``) or cosine |A & B| / sqrt(|A| |B|) (``norm="cosine"``).
    An observation that sees no virtual point is similar to nothing but itself.
    Returns a dense (N, N) array. V is kept dense: a viewpoint sees a good
    share of the virtual points, and one BLAS product beats a sparse one at
    these sizes (N, P ~ 10^3).
    """
    if norm not in ("jaccard", "cosine"):
        raise InputError("visibility_similarity", f"norm must be 'jaccard' or 'cosine', got {norm!r}")
    vp = virtual_points(obs, spacing_m)
    v = obs.sees_all(vp, slack).astype(np.float32)
    c = (v @ v.T).astype(np.float64)
    size = np.diag(c).copy()
    with np.errstate(invalid="ignore", divide="ignore"):
        if norm == "jaccard":
            s = c / (size[:, None] + size[None, :] - c)
        else:
            s = c / np.sqrt(size[:, None] * size[None, :])
    s = np.nan_to_num(s, nan=0.0, posinf=0.0)
    np.fill_diagonal(s, 1.0)
    return s


SIMILARITIES = SIMILARITY_MEASURES
"""Similarity measures by name (the registry: iterating gives the names)."""


def similarity_matrix(obs: Observations, name: str = "visibility", **params):
    """The named similarity measure (see :data:`SIMILARITIES`) of the observations.

    Unknown measure names and parameters are an :class:`InputError` naming them.
    """
    return SIMILARITY_MEASURES.create(name, params, obs)
