"""Clusters of a particle set: connected histogram bins, their weighted means and the hypotheses a
filter reports (:class:`Hypothesis`: mean pose, covariance, share of the weight) and its :class:`Estimate`."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from slam2d import geometry
from slam2d.localization.sampling import low_variance_indices

__all__ = ["Estimate", "Hypothesis", "cluster_means", "clusters", "hypotheses", "same_place", "weighted_pose",
           "with_floors"]

MAX_HYPOTHESES = 20  # clusters reported and kept alive at resampling, heaviest first
SAME_PLACE = (1.0, 0.5)  # m, rad: a look-alike image this close to a hypothesis is already held


@dataclass(frozen=True)
class Hypothesis:
    """A cluster of particles: weighted mean pose (3,), covariance (3, 3), share of the weight, particles."""

    pose: np.ndarray
    covariance: np.ndarray
    weight: float
    particles: int

    @property
    def sd_xy(self) -> float:
        """m, root of the larger position variance."""
        return float(math.sqrt(max(self.covariance[0, 0], self.covariance[1, 1])))


@dataclass(frozen=True)
class Estimate:
    """The filter's pose (3,), its covariance (3, 3), the heaviest cluster's share of the weight,
    the number of clusters and of particles; the state (``tracking``: one hypothesis holds the
    evidence; ``ambiguous``: compact hypotheses not yet told apart; ``lost``: no compact one), the
    hypotheses (heaviest first) and the log evidence ratio of the best over the runner-up."""

    pose: np.ndarray
    covariance: np.ndarray
    share: float
    clusters: int
    particles: int
    state: str = "tracking"
    hypotheses: tuple[Hypothesis, ...] = ()
    evidence: float = math.inf

    @property
    def sd_xy(self) -> float:
        """m, root of the larger position variance."""
        return float(math.sqrt(max(self.covariance[0, 0], self.covariance[1, 1])))

    @property
    def sd_theta(self) -> float:
        """rad."""
        return float(math.sqrt(self.covariance[2, 2]))


def _bins(poses: np.ndarray, bin_xy: float, bin_theta: float) -> np.ndarray:
    """Integer histogram bins (P, 3) of poses."""
    return np.column_stack([np.floor(poses[:, 0] / bin_xy), np.floor(poses[:, 1] / bin_xy),
                            np.floor((poses[:, 2] + np.pi) / bin_theta)]).astype(np.int64)  # fmt: skip


def _distinct_so_far(bins: np.ndarray) -> np.ndarray:
    """k (P,): the number of distinct bins among the first 1..P rows of ``bins`` (P, 3)."""
    b = bins - bins.min(axis=0)
    span = b.max(axis=0) + 1
    key = (b[:, 0] * span[1] + b[:, 1]) * span[2] + b[:, 2]  # one integer per bin (spans are small)
    _, first = np.unique(key, return_index=True)
    new = np.zeros(len(bins), dtype=np.int64)
    new[first] = 1
    return np.cumsum(new)


def clusters(poses: np.ndarray, bin_xy: float, bin_theta: float) -> np.ndarray:
    """Cluster labels (P,) from 0: particles in histogram bins connected through their 26 neighbours
    (heading wrapping round at the emptiest heading bin)."""
    b = _bins(poses, bin_xy, bin_theta)
    n_theta = math.ceil(2 * math.pi / bin_theta)
    b[:, 2] = np.clip(b[:, 2], 0, n_theta - 1)
    cut = int(np.argmin(np.bincount(b[:, 2], minlength=n_theta)))
    b[:, 2] = (b[:, 2] - cut - 1) % n_theta  # the emptiest bin becomes the last one
    b[:, :2] -= b[:, :2].min(axis=0)
    occupied = np.zeros((*(b[:, :2].max(axis=0) + 1), n_theta), dtype=bool)
    occupied[b[:, 0], b[:, 1], b[:, 2]] = True
    labels, _ = ndimage.label(occupied, structure=np.ones((3, 3, 3), dtype=bool))
    return labels[b[:, 0], b[:, 1], b[:, 2]] - 1


def _group_logsumexp(x: np.ndarray, labels: np.ndarray, k: int) -> np.ndarray:
    """log sum exp of ``x`` (P,) per label 0..k-1, (k,)."""
    top = np.full(k, -np.inf)
    np.maximum.at(top, labels, x)
    top = np.where(np.isfinite(top), top, 0.0)
    return top + np.log(np.bincount(labels, weights=np.exp(x - top[labels]), minlength=k))


def cluster_means(poses: np.ndarray, log_w: np.ndarray, labels: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
    """Weighted mean pose (k, 3) (circular heading) of each cluster 0..k-1 and its log weight (k,)."""
    w = np.exp(log_w - log_w.max())
    total = np.bincount(labels, weights=w, minlength=k)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = np.column_stack([np.bincount(labels, weights=w * poses[:, 0], minlength=k) / total,
                                np.bincount(labels, weights=w * poses[:, 1], minlength=k) / total,
                                np.arctan2(np.bincount(labels, weights=w * np.sin(poses[:, 2]), minlength=k),
                                           np.bincount(labels, weights=w * np.cos(poses[:, 2]), minlength=k))])
        return np.nan_to_num(mean), np.log(total) + log_w.max()


def hypotheses(poses: np.ndarray, log_w: np.ndarray, labels: np.ndarray, count: int = MAX_HYPOTHESES
               ) -> tuple[list[Hypothesis], np.ndarray, np.ndarray]:
    """The ``count`` heaviest clusters of ``poses`` (P, 3) with log weights (P,) and cluster ``labels``
    (P,) as hypotheses, heaviest first; also every cluster's weight (K,) (normalised) and the labels
    of the hypotheses returned (their order)."""
    w = np.exp(log_w - log_w.max())
    mass = np.bincount(labels, weights=w)
    mass = mass / mass.sum()
    order = np.argsort(-mass, kind="stable")[:count]
    out = []
    for c in order:
        inside = labels == c
        mean, cov = weighted_pose(poses[inside], w[inside])
        out.append(Hypothesis(mean, cov, float(mass[c]), int(inside.sum())))
    return out, mass, order


def same_place(a: np.ndarray, b: np.ndarray) -> bool:
    """Whether poses ``a`` and ``b`` (3,) lie within SAME_PLACE of each other."""
    return bool(math.hypot(a[0] - b[0], a[1] - b[1]) < SAME_PLACE[0]
                and abs(float(geometry.wrap_angle(a[2] - b[2]))) < SAME_PLACE[1])  # fmt: skip


def weighted_pose(poses: np.ndarray, weights: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Weighted mean pose (3,) (circular mean heading) and covariance (3, 3) of poses (P, 3)."""
    w = weights / weights.sum()  # sums, not BLAS: its threads contend with numba's
    theta = math.atan2(float(np.sum(w * np.sin(poses[:, 2]))), float(np.sum(w * np.cos(poses[:, 2]))))
    mean = np.array([np.sum(w * poses[:, 0]), np.sum(w * poses[:, 1]), theta])
    d = poses - mean
    d[:, 2] = geometry.wrap_angle(d[:, 2])
    wd = d * w[:, None]
    return mean, np.array([[np.sum(wd[:, i] * d[:, j]) for j in range(3)] for i in range(3)])


def with_floors(kept: np.ndarray, weights: np.ndarray, labels: np.ndarray, keep: float, floor: int,
                rng: np.random.Generator) -> np.ndarray:  # fmt: skip
    """``kept`` indices plus, for each of the MAX_HYPOTHESES heaviest clusters (``labels``, particle
    ``weights``) holding at least ``keep`` of the heaviest one's weight, particles drawn from it by weight
    up to ``floor``: a look-alike place is not lost to sampling before the scans tell."""
    mass = np.bincount(labels, weights=weights)
    top = np.argsort(-mass, kind="stable")[:MAX_HYPOTHESES]
    top = top[mass[top] >= keep * mass[top[0]]]
    have = np.bincount(labels[kept], minlength=len(mass))
    extra = [kept]
    for c in top:
        short = floor - int(have[c])
        if short > 0:
            members = np.flatnonzero(labels == c)
            extra.append(members[low_variance_indices(weights[members] / mass[c], short, rng)])
    return np.concatenate(extra)
