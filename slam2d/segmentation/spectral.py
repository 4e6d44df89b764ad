"""Spectral clustering of observations and room labels for a grid (thesis ch. 4.4-4.7).

Pipeline of :func:`segment_spectral`:

1. viewpoints on a lattice over the free space, 360 deg virtual scans
   (:func:`~slam2d.segmentation.observations.virtual_observations`);
2. similarity matrix S (:mod:`~slam2d.segmentation.similarity`), optionally
   its second-order form or binarised by the thesis's acceptance ratio;
3. random-walk Laplacian L_rw = I - D^-1 S (diagonal of S set to 1, D + 0.01 I
   if singular), eigenvectors of its k smallest eigenvalues, rows normalised,
   k-means; k is the one with the highest mean silhouette over a range;
4. every free cell takes the label of the observations that see it
   (:func:`label_free_cells`);
5. optionally, elongated segments cut where there is no doorway are merged
   again (:func:`merge_open_boundaries`): the silhouette favours compact
   clusters and cuts corridors, a weakness the thesis notes (4.6).
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field
from typing import Annotated, Literal

import numpy as np
from numba import njit
from pydantic import Field, ValidationError, create_model
from scipy import linalg, sparse
from scipy.sparse.linalg import eigsh
from threadpoolctl import threadpool_limits

from slam2d.config import Section
from slam2d.errors import InputError
from slam2d.registry import Choice, validation_error
from slam2d.segmentation.base import SEGMENTATION_METHODS, SIMILARITY_MEASURES, register_method
from slam2d.segmentation.observations import Observations, dda_start, dda_step, virtual_observations
from slam2d.segmentation.similarity import similarity_matrix

__all__ = [
    "SpectralConfig",
    "SpectralOptions",
    "SegmentationResult",
    "binarise",
    "second_order",
    "random_walk_laplacian",
    "spectral_embedding",
    "row_normalise",
    "silhouette",
    "choose_k",
    "orthogonal_init",
    "k_window",
    "silhouette_samples",
    "spectral_clusters",
    "label_free_cells",
    "merge_open_boundaries",
    "segment_spectral",
    "spectral",
]

log = logging.getLogger(__name__)

DENSE_EIGEN_MAX = 700
"""Up to this many observations the eigenproblem is solved densely (LAPACK), above by eigsh."""

EIGSH_TOL = 1e-6
"""Relative accuracy of the ARPACK eigenpairs."""

SECOND_ORDER_DEFAULT = ("hausdorff", "nearest_neighbour")
"""Measures clustered on their second-order form by default: they only relate observations
a few metres apart, and sharing neighbours reaches further (benchmarked: +2 to +4 recall)."""
"""Relative accuracy of the ARPACK eigenvalues (k-means needs no more)."""


class SpectralConfig(Section):
    """Parameters of :func:`segment_spectral` (defaults are the benchmarked best)."""

    similarity: Annotated[str, Choice("similarity_measures")] = "visibility"
    spacing_m: float = Field(1.2, gt=0, description="viewpoint lattice step, m")
    beams: int = Field(360, gt=3, description="beams per virtual scan over 360 deg")
    max_range: float = Field(20.0, gt=0, description="virtual scan range, m")
    clearance_m: float = Field(0.2, ge=0, description="least distance of a viewpoint to an obstacle, m")
    clutter_m: float = Field(1.0, ge=0, description="obstacles smaller than this do not stop virtual beams, m")
    similarity_params: dict = Field(default_factory=dict, description="keyword arguments of the measure")
    second_order: bool | None = Field(
        None, description="cluster on the cosine of the rows of S; None: on for hausdorff, nearest_neighbour"
    )
    accept_ratio: float | None = Field(
        None, ge=0, le=1, description="binarise S at S_min + d (S_max - S_min); None keeps weights"
    )
    k: int | None = Field(None, gt=0, description="fixed cluster count; None chooses k by silhouette")
    k_min: int = Field(2, gt=0, description="smallest k tried")
    k_max: int = Field(60, gt=0, description="largest k tried (and eigenvectors computed)")
    eig_threshold: float | None = Field(
        0.8, gt=0, lt=1, description="try k around the count of L_rw eigenvalues below this; None: all of k_min..k_max"
    )
    k_window: int = Field(5, ge=0, description="half-width of that k range")
    n_init: int = Field(3, gt=0, description="k-means restarts per k")
    threads: int | None = Field(1, gt=0, description="BLAS / OpenMP threads while clustering (None: library default)")
    seed: int = Field(0, description="k-means seed")
    silhouette_space: Literal["similarity", "embedding"] = Field(
        "similarity", description="silhouette on 1 - S, or on the spectral embedding (sklearn)"
    )
    silhouette_sample: int | None = Field(2000, gt=1, description="embedding silhouette on at most this many rows")
    coarse_step: int = Field(1, gt=0, description="try every k (1) or a coarse grid of k, then refine")
    label_radius_m: float = Field(2.5, gt=0, description="farthest a viewpoint labels cells it sees, m")
    label_rule: Literal["fraction", "vote", "nearest"] = Field(
        "fraction", description="how cells take observation labels (see label_free_cells)"
    )
    label_cell_m: float = Field(0.1, gt=0, description="cell size of the labelling pass, m")
    min_segment_m2: float = Field(0.0, ge=0, description="segments smaller than this are absorbed, m^2")
    merge_ratio: float | None = Field(
        0.7, gt=0, description="merge segments whose boundary is at least this fraction of their width; None: off"
    )
    merge_min_contact_m: float = Field(0.5, ge=0, description="least common boundary for a merge, m")
    merge_elongation: float = Field(3.0, ge=0, description="merge only segments with area >= this * width^2")


SpectralOptions = create_model(
    "SpectralOptions", __base__=Section, __doc__="The options of the ``spectral`` method (``segmentation.params``): "
    "SpectralConfig's but the measure (``segmentation.similarity``); the seed defaults to the run's.",
    **{name: (f.annotation, f) for name, f in SpectralConfig.model_fields.items()
       if name not in ("similarity", "seed")},
    seed=(int | None, Field(None, description="k-means seed; None: the run's seed")),
)


@dataclass(eq=False)
class SegmentationResult:
    """Room labels (H, W) int32 (0 off the free space, segments 1..R), the cluster
    count k, the mean silhouette of the chosen clustering, and wall time (s).

    observation_labels: cluster 0..k-1 of each observation; R can be below k
    after merging. timings: per-stage ``wall`` and ``cpu`` seconds, ``cpu_total``.
    """

    labels: np.ndarray
    k: int
    silhouette: float
    seconds: float
    observation_labels: np.ndarray = field(default=None, repr=False)
    observations: Observations | None = field(default=None, repr=False)
    timings: dict = field(default_factory=dict, repr=False)


# --------------------------------------------------------------------------- graph and Laplacian


def _as_matrix(s):
    """Symmetric similarity as dense float64 or csr, with unit diagonal."""
    if sparse.issparse(s):
        s = sparse.csr_array(s, dtype=np.float64)
        s.setdiag(1.0)
        return s
    s = np.array(s, dtype=np.float64)
    if s.ndim != 2 or s.shape[0] != s.shape[1]:
        raise InputError("similarity", f"matrix must be square, got shape {s.shape}")
    np.fill_diagonal(s, 1.0)
    return s


def second_order(s):
    """Cosine similarity of the rows of S: observations are alike when they are alike to the
    same observations. Symmetric, unit diagonal, in [0, 1]; reaches two steps further than S."""
    s = _as_matrix(s)
    n = np.sqrt(np.asarray((s.multiply(s) if sparse.issparse(s) else s * s).sum(axis=1)).ravel())
    inv = sparse.diags_array(1.0 / np.maximum(n, 1e-12))
    out = inv @ (s @ s.T) @ inv if sparse.issparse(s) else (s @ s.T) / np.outer(n, n)
    return _as_matrix(out)


def binarise(s, accept_ratio: float = 0.95):
    """S_ij = 1 where S_ij > S_min + d (S_max - S_min) (thesis eq. 21-22, d = ``accept_ratio``), else 0.

    S_min and S_max are taken over the off-diagonal entries (stored entries
    for sparse input); the diagonal is 1 afterwards.
    """
    if sparse.issparse(s):
        c = sparse.coo_array(s)
        off = c.row != c.col
        vals = c.data[off]
        lo, hi = (vals.min(), vals.max()) if vals.size else (0.0, 1.0)
        sw = lo + accept_ratio * (hi - lo)
        keep = off & (c.data > sw)
        out = sparse.csr_array((np.ones(int(keep.sum())), (c.row[keep], c.col[keep])), shape=c.shape)
        return _as_matrix(out)
    s = np.asarray(s, dtype=np.float64)
    off = ~np.eye(len(s), dtype=bool)
    vals = s[off]
    lo, hi = (vals.min(), vals.max()) if vals.size else (0.0, 1.0)
    out = (s > lo + accept_ratio * (hi - lo)).astype(np.float64)
    np.fill_diagonal(out, 1.0)
    return out


def _degrees(s) -> np.ndarray:
    """Row sums of S; + 0.01 everywhere if any is 0 (D + 0.01 I, thesis 4.4)."""
    d = np.asarray(s.sum(axis=1)).ravel()
    if np.any(d <= 0):
        d = d + 0.01
    return d


def random_walk_laplacian(s) -> np.ndarray:
    """Dense L_rw = I - D^-1 S (diagonal of S set to 1 first)."""
    s = _as_matrix(s)
    s = s.toarray() if sparse.issparse(s) else s
    return np.eye(len(s)) - s / _degrees(s)[:, None]


def spectral_embedding(s, k: int) -> tuple[np.ndarray, np.ndarray]:
    """The k smallest eigenvalues (k,) of L_rw and their eigenvectors U (N, k), ascending.

    Solved on the symmetric form: L_sym = I - D^-1/2 S D^-1/2 has the same
    eigenvalues, and u = D^-1/2 v maps its eigenvectors v to those of L_rw.
    Dense LAPACK up to ``DENSE_EIGEN_MAX`` observations, else ARPACK (eigsh,
    largest eigenvalues of D^-1/2 S D^-1/2). Columns are scaled to unit norm.
    """
    s = _as_matrix(s)
    n = s.shape[0]
    k = int(min(max(k, 1), n))
    d = _degrees(s)
    isq = 1.0 / np.sqrt(d)
    if sparse.issparse(s):
        a = sparse.diags_array(isq) @ s @ sparse.diags_array(isq)
    else:
        a = s * isq[:, None] * isq[None, :]
    if n <= DENSE_EIGEN_MAX or k >= n - 1:
        dense = a.toarray() if sparse.issparse(a) else a
        mu, v = linalg.eigh(dense, subset_by_index=[n - k, n - 1], driver="evr")
    else:
        mu, v = eigsh(a, k=k, which="LA", v0=np.sqrt(d) / np.linalg.norm(np.sqrt(d)), tol=EIGSH_TOL)
    order = np.argsort(-mu)
    lam = 1.0 - mu[order]
    u = v[:, order] * isq[:, None]
    u /= np.linalg.norm(u, axis=0, keepdims=True)
    return lam, u


def row_normalise(u: np.ndarray) -> np.ndarray:
    """Rows scaled to unit Euclidean length (zero rows stay zero)."""
    n = np.linalg.norm(u, axis=1, keepdims=True)
    return np.divide(u, n, out=np.zeros_like(u), where=n > 0)


# --------------------------------------------------------------------------- silhouette and k


def silhouette_samples(d: np.ndarray, labels: np.ndarray) -> np.ndarray:
    """Silhouettes s_i = (b_i - a_i) / max(a_i, b_i) (thesis eq. 29-33) from distances d (N, N).

    a_i: mean distance to the other members of i's cluster; b_i: least mean
    distance to the members of another cluster; s_i = 0 in singleton
    clusters. Vectorised: the per-cluster distance sums are one product d @ onehot.
    """
    labels = np.unique(np.asarray(labels), return_inverse=True)[1]
    k = int(labels.max()) + 1 if labels.size else 0
    if k < 2:
        raise InputError("silhouette", "needs at least 2 clusters")
    n = len(labels)
    onehot = np.zeros((n, k))
    onehot[np.arange(n), labels] = 1.0
    sums = (d @ onehot.astype(d.dtype)).astype(np.float64)  # (N, k): total distance to each cluster
    size = onehot.sum(axis=0)
    own = size[labels]
    a = sums[np.arange(n), labels] / np.maximum(own - 1, 1)
    mean = sums / size
    mean[np.arange(n), labels] = np.inf
    b = mean.min(axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        s = (b - a) / np.maximum(a, b)
    s[own == 1] = 0.0
    return np.nan_to_num(s)


def silhouette(x: np.ndarray, labels: np.ndarray) -> float:
    """Mean silhouette of points x (N, D) under Euclidean distance (:func:`silhouette_samples`)."""
    x = np.asarray(x, dtype=np.float64)
    sq = (x * x).sum(axis=1)
    d = np.sqrt(np.maximum(sq[:, None] + sq[None, :] - 2.0 * x @ x.T, 0.0))
    np.fill_diagonal(d, 0.0)
    return float(silhouette_samples(d, labels).mean())


def orthogonal_init(f: np.ndarray, k: int) -> np.ndarray:
    """k starting centres among the unit rows of f, as mutually orthogonal as possible
    (Ng, Jordan & Weiss 2001): first the row most aligned with the mean direction, then
    repeatedly the row whose largest |cosine| to the chosen ones is smallest."""
    first = int(np.argmax(f @ f.mean(axis=0)))
    chosen = [first]
    worst = np.abs(f @ f[first])
    for _ in range(1, k):
        i = int(np.argmin(worst))
        chosen.append(i)
        worst = np.maximum(worst, np.abs(f @ f[i]))
    return f[chosen]


def _kmeans(f: np.ndarray, k: int, n_init: int, seed: int) -> np.ndarray:
    """k-means (scikit-learn) on the rows of f: one run from :func:`orthogonal_init`, plus
    ``n_init - 1`` restarts from seeded random rows; the run with the least inertia wins."""
    from sklearn.cluster import KMeans

    best = KMeans(n_clusters=k, init=orthogonal_init(f, k), n_init=1, max_iter=100).fit(f)
    if n_init > 1:
        other = KMeans(n_clusters=k, init="random", n_init=n_init - 1, random_state=seed, max_iter=100).fit(f)
        if other.inertia_ < best.inertia_:
            best = other
    return best.labels_


def _k_candidates(k_lo: int, k_hi: int, step: int) -> list[int]:
    """A coarse grid of k from k_lo to k_hi (both included) every ``step``."""
    ks = list(range(k_lo, k_hi + 1, max(step, 1)))
    if ks[-1] != k_hi:
        ks.append(k_hi)
    return ks


def choose_k(u: np.ndarray, k_range, distances: np.ndarray | None = None, n_init: int = 3, seed: int = 0,
             sample: int | None = 2000, coarse_step: int = 1) -> tuple[int, np.ndarray, float, dict]:
    """k with the highest mean silhouette (thesis 4.7): for each k, k-means on the
    row-normalised first k eigenvectors of ``u``.

    The silhouette is computed on ``distances`` (N, N) when given (e.g. 1 - S),
    else on the k-dimensional embedding itself (scikit-learn, at most ``sample``
    rows, seeded). With ``coarse_step`` > 1, k is first tried every
    ``coarse_step`` values, then at every value around the best coarse k.
    Returns (k, labels (N,), silhouette, {k: silhouette}).
    """
    from sklearn.metrics import silhouette_score

    n = len(u)
    ks = [k for k in k_range if 2 <= k < n]
    scores, labels = {}, {}

    def evaluate(k):
        if k in scores:
            return
        f = row_normalise(u[:, :k])
        lab = _kmeans(f, k, n_init, seed)
        if len(np.unique(lab)) < 2:
            return
        if distances is not None:
            scores[k] = float(silhouette_samples(distances, lab).mean())
        else:
            ss = sample if sample and sample < n else None
            scores[k] = float(silhouette_score(f, lab, sample_size=ss, random_state=seed))
        labels[k] = lab

    if not ks:
        return 1, np.zeros(n, dtype=np.int64), 0.0, scores
    for k in _k_candidates(ks[0], ks[-1], coarse_step) if coarse_step > 1 else ks:
        evaluate(k)
    if coarse_step > 1 and scores:
        kb = max(scores, key=scores.get)
        for k in range(max(ks[0], kb - coarse_step + 1), min(ks[-1], kb + coarse_step - 1) + 1):
            evaluate(k)
    if not scores:
        return 1, np.zeros(n, dtype=np.int64), 0.0, scores
    kb = max(scores, key=scores.get)
    return kb, labels[kb], scores[kb], scores


def _distances(s) -> np.ndarray:
    """Dissimilarity 1 - S, dense float32, for the silhouette; 1 - Jaccard is a metric."""
    d = 1.0 - (s.toarray() if sparse.issparse(s) else np.asarray(s)).astype(np.float32)
    np.fill_diagonal(d, 0.0)
    return d


def k_window(eigenvalues: np.ndarray, threshold: float = 0.8, window: int = 5) -> tuple[int, int]:
    """k range [n - window, n + window] around n = number of L_rw eigenvalues below ``threshold``
    (near-zero eigenvalues count weakly coupled groups: the eigengap reading of the spectrum)."""
    n = int(np.sum(np.asarray(eigenvalues) < threshold))
    return max(2, n - window), n + window


def spectral_clusters(s, k: int | None = None, k_min: int = 2, k_max: int = 60, n_init: int = 3,
                      seed: int = 0, accept_ratio: float | None = None, silhouette_space: str = "similarity",
                      silhouette_sample: int | None = 2000, coarse_step: int = 1,
                      eig_threshold: float | None = 0.8, k_window_size: int = 5) -> tuple[np.ndarray, int, float]:
    """Cluster labels (N,) of observations from their similarity S, the k used, its silhouette.

    ``accept_ratio`` binarises S first (:func:`binarise`). ``k`` fixed, or chosen
    by :func:`choose_k` in [k_min, k_max], narrowed to :func:`k_window` of the
    eigenvalues unless ``eig_threshold`` is None; the silhouette is measured on
    1 - S (``silhouette_space="similarity"``, the weighted S even when
    binarised) or on the spectral embedding (``"embedding"``).
    """
    if silhouette_space not in ("similarity", "embedding"):
        raise InputError("silhouette_space", f"must be 'similarity' or 'embedding', got {silhouette_space!r}")
    s = _as_matrix(s)
    g = binarise(s, accept_ratio) if accept_ratio is not None else s
    n = s.shape[0]
    if n < 3:
        return np.zeros(n, dtype=np.int64), 1, 0.0
    kmax = min(k if k else k_max, n - 1)
    lam, u = spectral_embedding(g, kmax)
    d = _distances(s) if silhouette_space == "similarity" else None
    if k:
        ks = [kmax]
    else:
        lo, hi = max(k_min, 2), kmax
        if eig_threshold is not None:
            wlo, whi = k_window(lam, eig_threshold, k_window_size)
            lo, hi = max(lo, min(wlo, kmax)), min(hi, whi)
        ks = range(lo, hi + 1)
    k_best, lab, sc, _ = choose_k(u, ks, d, n_init, seed, silhouette_sample, coarse_step)
    return lab, k_best, sc


# --------------------------------------------------------------------------- labelling the grid


@njit(cache=True, nogil=True)
def _march(gx, gy, angle, lim, h, w, cells_r, cells_c, cells_t):
    """Cells (row, col) a ray from (gx, gy) crosses up to distance ``lim`` (cells), with
    the entry distance of each; returns how many were written (exact grid traversal)."""
    dx, dy = np.cos(angle), np.sin(angle)
    c, r = int(np.floor(gx)), int(np.floor(gy))
    step_c, step_r, inv_x, inv_y, tmx, tmy = dda_start(gx, gy, dx, dy)
    t = 0.0
    n = 0
    while t < lim and 0 <= c < w and 0 <= r < h and n < cells_r.shape[0]:
        cells_r[n], cells_c[n], cells_t[n] = r, c, t
        n += 1
        t, tmx, tmy, c, r = dda_step(tmx, tmy, inv_x, inv_y, c, r, step_c, step_r)
    return n


@njit(cache=True, nogil=True)
def _paint_votes(h, w, gxy, table, obs_label, max_t, votes):
    """votes[r, c, l] += 1 for every beam of an observation labelled l that crosses cell (r, c)."""
    nb = table.shape[1]
    cap = int(max_t) * 2 + 4
    cr = np.empty(cap, np.int64)
    cc = np.empty(cap, np.int64)
    ct = np.empty(cap)
    for i in range(gxy.shape[0]):
        lab = obs_label[i]
        for b in range(nb):
            n = _march(gxy[i, 0], gxy[i, 1], 2.0 * np.pi * b / nb, min(table[i, b], max_t), h, w, cr, cc, ct)
            for q in range(n):
                votes[cr[q], cc[q], lab] += 1


@njit(cache=True, nogil=True)
def _paint_seen(h, w, gxy, table, obs_label, max_t, seen):
    """seen[r, c, l] = number of observations labelled l whose beams reach cell (r, c)."""
    nb = table.shape[1]
    cap = int(max_t) * 2 + 4
    cr = np.empty(cap, np.int64)
    cc = np.empty(cap, np.int64)
    ct = np.empty(cap)
    stamp = np.full((h, w), -1, np.int64)
    for i in range(gxy.shape[0]):
        lab = obs_label[i]
        for b in range(nb):
            n = _march(gxy[i, 0], gxy[i, 1], 2.0 * np.pi * b / nb, min(table[i, b], max_t), h, w, cr, cc, ct)
            for q in range(n):
                if stamp[cr[q], cc[q]] != i:
                    stamp[cr[q], cc[q]] = i
                    seen[cr[q], cc[q], lab] += 1


@njit(cache=True, nogil=True)
def _pick_fraction(gxy, obs_label, radius, seen, out):
    """out[r, c] = the label l maximising seen / (near + 1), where ``near`` counts the
    observations labelled l within ``radius`` cells of the cell (seen or not)."""
    h, w, nl = seen.shape
    n = gxy.shape[0]
    bs = max(radius, 1.0)
    nbx = int(np.floor(w / bs)) + 1
    nby = int(np.floor(h / bs)) + 1
    bucket = np.empty(n, np.int64)
    for i in range(n):
        bx = min(max(int(np.floor(gxy[i, 0] / bs)), 0), nbx - 1)
        by = min(max(int(np.floor(gxy[i, 1] / bs)), 0), nby - 1)
        bucket[i] = by * nbx + bx
    order = np.argsort(bucket)
    start = np.zeros(nbx * nby + 1, np.int64)
    for i in range(n):
        start[bucket[i] + 1] += 1
    for j in range(nbx * nby):
        start[j + 1] += start[j]
    near = np.zeros(nl, np.int64)
    r2 = radius * radius
    for r in range(h):
        by = int(np.floor((r + 0.5) / bs))
        for c in range(w):
            any_seen = False
            for l in range(nl):
                if seen[r, c, l] > 0:
                    any_seen = True
                    break
            if not any_seen:
                continue
            for yy in range(max(by - 1, 0), min(by + 2, nby)):
                bx = int(np.floor((c + 0.5) / bs))
                for xx in range(max(bx - 1, 0), min(bx + 2, nbx)):
                    b = yy * nbx + xx
                    for q in range(start[b], start[b + 1]):
                        i = order[q]
                        dx = c + 0.5 - gxy[i, 0]
                        dy = r + 0.5 - gxy[i, 1]
                        if dx * dx + dy * dy <= r2:
                            near[obs_label[i]] += 1
            best, bv = 0, -1.0
            for l in range(nl):
                if seen[r, c, l] > 0:
                    v = seen[r, c, l] / (near[l] + 1.0)
                    if v > bv:
                        bv, best = v, l
                near[l] = 0
            out[r, c] = best


@njit(cache=True, nogil=True)
def _paint_nearest(h, w, gxy, table, obs_label, max_t, out):
    """out[r, c] = label of the nearest observation whose beams cross cell (r, c)."""
    nb = table.shape[1]
    cap = int(max_t) * 2 + 4
    cr = np.empty(cap, np.int64)
    cc = np.empty(cap, np.int64)
    ct = np.empty(cap)
    zbuf = np.full((h, w), np.inf)
    for i in range(gxy.shape[0]):
        for b in range(nb):
            n = _march(gxy[i, 0], gxy[i, 1], 2.0 * np.pi * b / nb, min(table[i, b], max_t), h, w, cr, cc, ct)
            for q in range(n):
                if ct[q] < zbuf[cr[q], cc[q]]:
                    zbuf[cr[q], cc[q]] = ct[q]
                    out[cr[q], cc[q]] = obs_label[i]


@njit(cache=True, nogil=True)
def _bfs_flood(labels, free):
    """Breadth-first flood of labels into unlabelled free cells over 8-neighbours (in place)."""
    h, w = labels.shape
    qr = np.empty(h * w, np.int64)
    qc = np.empty(h * w, np.int64)
    head, tail = 0, 0
    for r in range(h):
        for c in range(w):
            if labels[r, c] > 0:
                qr[tail], qc[tail] = r, c
                tail += 1
    while head < tail:
        r, c = qr[head], qc[head]
        head += 1
        for dr in range(-1, 2):
            for dc in range(-1, 2):
                rr, cc = r + dr, c + dc
                if 0 <= rr < h and 0 <= cc < w and free[rr, cc] and labels[rr, cc] == 0:
                    labels[rr, cc] = labels[r, c]
                    qr[tail], qc[tail] = rr, cc
                    tail += 1


def _fill(labels: np.ndarray, free: np.ndarray) -> np.ndarray:
    """Unlabelled free cells take the label of the nearest labelled cell through the free
    space (breadth-first over 8-neighbours); free components without any label get new
    labels of their own."""
    from scipy import ndimage

    labels = np.where(free, labels, 0).astype(np.int32)
    if not (free & (labels == 0)).any():
        return labels
    _bfs_flood(labels, np.ascontiguousarray(free))
    orphan = free & (labels == 0)
    if orphan.any():
        comp, n = ndimage.label(orphan, structure=np.ones((3, 3), dtype=int))
        labels = np.where(orphan, comp + labels.max(), labels).astype(np.int32)
    return labels


def _clean(labels: np.ndarray, free: np.ndarray, resolution: float, min_segment_m2: float) -> np.ndarray:
    """Keep each label's largest 8-connected piece (and drop segments under ``min_segment_m2``);
    the removed cells are refilled by their neighbours (:func:`_fill`)."""
    from skimage.measure import label as cc

    comp = cc(labels, background=0, connectivity=2)
    n = comp.max()
    if n == 0:
        return labels
    size = np.bincount(comp.ravel(), minlength=n + 1)
    owner = np.zeros(n + 1, dtype=np.int64)
    owner[comp.ravel()] = labels.ravel()
    best = np.zeros(labels.max() + 1, dtype=np.int64)
    order = np.argsort(size[1:], kind="stable") + 1  # ascending, so the largest piece is written last
    best[owner[order]] = order
    keep = np.zeros(n + 1, dtype=bool)
    keep[best[best > 0]] = True
    keep &= size * resolution**2 >= min_segment_m2
    keep[0] = False
    if keep[comp].sum() == (labels > 0).sum():
        return labels
    return _fill(np.where(keep[comp], labels, 0), free)


def label_free_cells(obs: Observations, obs_labels: np.ndarray, free=None, radius_m: float = 2.5,
                     rule: str = "fraction", cell_m: float = 0.1, min_segment_m2: float = 0.0) -> np.ndarray:
    """Room image (H, W) int32 (labels ``obs_labels + 1``, 0 off the free space) from labelled observations.

    Each observation's beams are traced on a grid of ``cell_m`` cells up to
    their range or ``radius_m`` m; an observation sees the cells its beams
    cross. A cell takes the label l that maximises

    - ``rule="fraction"`` (default): seen_l / (near_l + 1), with seen_l the
      observations of label l that see the cell and near_l those of label l
      within ``radius_m`` (seen or not). All viewpoints of a room see its
      cells; of the corridor viewpoints near a door only the few in line with
      it do, so the corridor does not take the cells just inside the door;
    - ``rule="vote"``: beam crossings (one observation's rays cross a cell at
      distance d about 1/d times: a vote weighted 1/d);
    - ``rule="nearest"``: the label of the nearest observation that sees it.

    Free cells no beam reaches, and every piece of a label but its largest,
    take the label of the nearest labelled cell through the free space; free
    components with no label get labels of their own.
    """
    free = obs.free if free is None else np.asarray(free, dtype=bool)
    if free is None or obs.resolution is None:
        raise InputError("label_free_cells", "observations carry no grid; pass free= with a resolution")
    if rule not in ("vote", "nearest", "fraction"):
        raise InputError("label_free_cells", f"rule must be 'fraction', 'vote' or 'nearest', got {rule!r}")
    res = obs.resolution
    f = max(1, int(round(cell_m / res)))
    h, w = -(-free.shape[0] // f), -(-free.shape[1] // f)
    gxy = np.ascontiguousarray((obs.poses[:, :2] - np.asarray(obs.origin)) / (res * f))
    table = np.ascontiguousarray(np.minimum(obs.range_table(), obs.range_max[:, None]) / (res * f))
    lab = np.asarray(obs_labels, dtype=np.int64) + 1
    coarse = np.zeros((h, w), dtype=np.int32)
    if len(lab) and rule == "fraction":
        seen = np.zeros((h, w, int(lab.max()) + 1), dtype=np.uint16)
        _paint_seen(h, w, gxy, table, lab, radius_m / (res * f), seen)
        _pick_fraction(gxy, lab, radius_m / (res * f), seen, coarse)
    elif len(lab) and rule == "vote":
        votes = np.zeros((h, w, int(lab.max()) + 1), dtype=np.uint16)
        _paint_votes(h, w, gxy, table, lab, radius_m / (res * f), votes)
        coarse = np.where(votes.any(axis=2), votes.argmax(axis=2), 0).astype(np.int32)
    elif len(lab):
        _paint_nearest(h, w, gxy, table, lab.astype(np.int32), radius_m / (res * f), coarse)
    cfree = _block_any(free, f)
    coarse = _clean(_fill(coarse, cfree), cfree, res * f, min_segment_m2)
    out = np.repeat(np.repeat(coarse, f, axis=0), f, axis=1)[: free.shape[0], : free.shape[1]]
    return np.where(free, out, 0).astype(np.int32)


def _block_any(mask: np.ndarray, f: int) -> np.ndarray:
    """(ceil(H/f), ceil(W/f)) mask: whether any cell of each f x f block is set."""
    if f == 1:
        return mask.copy()
    h, w = mask.shape
    pad = np.zeros((-(-h // f) * f, -(-w // f) * f), dtype=bool)
    pad[:h, :w] = mask
    return pad.reshape(pad.shape[0] // f, f, pad.shape[1] // f, f).any(axis=(1, 3))


def merge_open_boundaries(labels: np.ndarray, clear: np.ndarray, resolution: float, ratio: float = 0.7,
                          min_contact_m: float = 0.5, elongation: float = 3.0, cell_m: float = 0.1) -> np.ndarray:
    """Merge neighbouring elongated segments whose common boundary is no constriction.

    Free-space width is twice the distance to the nearest obstacle of
    ``clear`` (m). Segments A and B touching along at least ``min_contact_m``
    m are merged when the widest point of their boundary is at least ``ratio``
    times the width of the narrower one (a segment's width: its largest), and
    both are elongated (area >= ``elongation`` * width^2). A corridor cut by
    k-means has a boundary as wide as itself; a door is narrower than the
    spaces it joins; an alcove open to a corridor is not elongated. Merges
    chain (connected components). Computed on ``cell_m`` cells; labels are
    renumbered 1..R.
    """
    labels = np.asarray(labels)
    f = max(1, int(round(cell_m / resolution)))
    k = int(labels.max()) + 1
    if k <= 2:
        return labels.astype(np.int32)
    comp = _merge_map(labels[::f, ::f], clear[::f, ::f], k, resolution * f, ratio, min_contact_m, elongation)
    used = np.unique(comp[np.unique(labels[labels > 0])])
    remap = np.zeros(comp.max() + 1, dtype=np.int32)
    remap[used] = np.arange(1, len(used) + 1, dtype=np.int32)
    return np.where(labels > 0, remap[comp][labels], 0).astype(np.int32)


def _merge_map(labels: np.ndarray, clear: np.ndarray, k: int, resolution: float, ratio: float,
               min_contact_m: float, elongation: float) -> np.ndarray:
    """Component id (k,) per label 0..k-1 of :func:`merge_open_boundaries`' merge graph."""
    from scipy import ndimage
    from scipy.sparse import coo_array
    from scipy.sparse.csgraph import connected_components

    width = ndimage.distance_transform_edt(clear) * (2.0 * resolution)
    key, wide = [], []
    for a, b, wa, wb in (
        (labels[:, :-1], labels[:, 1:], width[:, :-1], width[:, 1:]),
        (labels[:-1, :], labels[1:, :], width[:-1, :], width[1:, :]),
    ):
        m = (a != b) & (a > 0) & (b > 0)
        key.append(np.minimum(a[m], b[m]).astype(np.int64) * k + np.maximum(a[m], b[m]))
        wide.append(np.maximum(wa[m], wb[m]))
    key, wide = np.concatenate(key), np.concatenate(wide)
    contact = np.bincount(key, minlength=k * k) * resolution
    gap = np.zeros(k * k)
    np.maximum.at(gap, key, wide)
    seg = np.zeros(k)
    seg[1:] = ndimage.maximum(width, labels, np.arange(1, k))
    area = np.bincount(labels.ravel(), minlength=k) * resolution**2
    long = area >= elongation * np.maximum(seg, resolution) ** 2
    i, j = np.divmod(np.nonzero(contact)[0], k)
    ok = (contact[i * k + j] >= min_contact_m) & (gap[i * k + j] >= ratio * np.minimum(seg[i], seg[j]))
    ok &= long[i] & long[j]
    g = coo_array((np.ones(int(ok.sum())), (i[ok], j[ok])), shape=(k, k))
    return connected_components(g, directed=False)[1]


class _Stopwatch:
    """Wall and CPU seconds of named stages (CPU time is what the machine's other load does not inflate)."""

    def __init__(self):
        self.wall, self.cpu = {}, {}
        self._t = (time.perf_counter(), time.process_time())
        self._t0 = self._t

    def lap(self, name: str) -> None:
        now = (time.perf_counter(), time.process_time())
        self.wall[name] = now[0] - self._t[0]
        self.cpu[name] = now[1] - self._t[1]
        self._t = now

    def total(self) -> tuple[float, float]:
        return self._t[0] - self._t0[0], self._t[1] - self._t0[1]


def segment_spectral(free, resolution: float, similarity: str = "visibility", *, config: SpectralConfig | None = None,
                     **params) -> SegmentationResult:
    """Segment the free space of a grid into rooms by spectral clustering of virtual observations.

    free: (H, W) bool; resolution: m per cell; similarity: one of
    ``SIMILARITIES``; further keyword arguments are :class:`SpectralConfig`
    fields (or pass ``config``). Returns labels (H, W) int32, k, silhouette,
    wall seconds (and per-stage wall / CPU seconds in ``timings``).
    """
    sw = _Stopwatch()
    base = (config or SpectralConfig()).model_dump()
    try:
        cfg = SpectralConfig.model_validate({**base, **params, "similarity": similarity})
    except ValidationError as err:
        raise validation_error(err, "segment_spectral", model=SpectralConfig) from None
    free = np.asarray(free, dtype=bool)
    if free.ndim != 2:
        raise InputError("segment_spectral", f"free must be a 2-D mask, got shape {free.shape}")
    obs = virtual_observations(free, resolution, cfg.spacing_m, cfg.beams, cfg.max_range,
                               clearance_m=cfg.clearance_m, clutter_m=cfg.clutter_m)
    sw.lap("observations")
    s = similarity_matrix(obs, cfg.similarity, **cfg.similarity_params)
    if cfg.second_order or (cfg.second_order is None and cfg.similarity in SECOND_ORDER_DEFAULT):
        s = second_order(s)
    sw.lap("similarity")
    import sklearn.cluster  # noqa: F401  (loads its OpenMP runtime before the thread limit applies)

    with threadpool_limits(cfg.threads):
        lab, k, sil = spectral_clusters(s, cfg.k, cfg.k_min, cfg.k_max, cfg.n_init, cfg.seed, cfg.accept_ratio,
                                        cfg.silhouette_space, cfg.silhouette_sample, cfg.coarse_step,
                                        cfg.eig_threshold, cfg.k_window)
    sw.lap("clustering")
    labels = label_free_cells(obs, lab, radius_m=cfg.label_radius_m, rule=cfg.label_rule, cell_m=cfg.label_cell_m,
                              min_segment_m2=cfg.min_segment_m2)
    sw.lap("labelling")
    if cfg.merge_ratio is not None:
        labels = merge_open_boundaries(labels, obs.clear, resolution, cfg.merge_ratio, cfg.merge_min_contact_m,
                                       cfg.merge_elongation)
    sw.lap("merging")
    wall, cpu = sw.total()
    log.info("spectral segmentation (%s): %d observations, k=%d, silhouette %.3f, %.2f s (%.2f s CPU)",
             cfg.similarity, len(obs), k, sil, wall, cpu)
    timings = {"wall": sw.wall, "cpu": sw.cpu, "cpu_total": cpu}
    return SegmentationResult(labels, int(k), float(sil), wall, lab, obs, timings)


@register_method("spectral", config=SpectralOptions, takes=("similarity", "seed"))
def spectral(free, resolution: float, options, similarity: str = "visibility", seed: int = 0) -> dict:
    """Spectral clustering of virtual observations compared by a similarity measure, k by silhouette (the thesis)."""
    found = SIMILARITY_MEASURES.canonical(similarity)
    if found is None:
        raise SIMILARITY_MEASURES.unknown(similarity)
    SIMILARITY_MEASURES.resolve_options(found, options.similarity_params,
                                        f"{SEGMENTATION_METHODS.options_key}.similarity_params")  # before any work
    params = {**options.model_dump(), "seed": seed if options.seed is None else options.seed}
    res = segment_spectral(free, resolution, similarity=found, **params)
    return dict(labels=np.asarray(res.labels, np.int32), seconds=float(res.seconds), k=int(res.k),
                silhouette=float(res.silhouette), similarity=found)
