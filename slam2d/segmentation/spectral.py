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
   (:func:`~slam2d.segmentation.labelling.label_free_cells`);
5. optionally, elongated segments cut where there is no doorway are merged
   again (:func:`~slam2d.segmentation.labelling.merge_open_boundaries`): the
   silhouette favours compact clusters and cuts corridors, a weakness the
   thesis notes (4.6).
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field
from typing import Annotated, Literal

import numpy as np
from pydantic import Field, ValidationError, create_model
from scipy import linalg, sparse
from scipy.sparse.linalg import eigsh
from threadpoolctl import threadpool_limits

from slam2d.config import MAX_BEAMS, Resolution, Section
from slam2d.errors import InputError
from slam2d.registry import Choice, validation_error
from slam2d.segmentation.base import SEGMENTATION_METHODS, SIMILARITY_MEASURES, register_method
from slam2d.segmentation.labelling import label_free_cells, merge_open_boundaries
from slam2d.segmentation.observations import Observations, virtual_observations
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
    beams: int = Field(360, gt=3, le=MAX_BEAMS, description="beams per virtual scan over 360 deg")
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
    k_max: int = Field(60, gt=0, le=1000, description="largest k tried (and eigenvectors computed)")
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
    label_cell_m: Resolution = Field(0.1, description="cell size of the labelling pass, m")
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
