"""Laser sensor models for particles × beams: the likelihood field and the beam model.

Both return the log-likelihood (P,) of one scan at every particle pose. The
likelihood field scores each beam end point by its distance d to the nearest
occupied cell (the map's exact distance transform, capped at ``max_dist``):
p = z_hit N(d; 0, sigma_hit) + z_rand / range_max; end points off the map or at
"no return" are d = max_dist and skipped respectively, as in amcl; a particle
standing in an occupied cell scores as if every end point lay at max_dist. The beam
model ray-casts the expected range in the grid and mixes hit, short, max and
random readings. Beams combine as a product (each likelihood raised to
``beam_weight``) or as amcl does, 1 + sum of cubes. Numba kernels, parallel
over particles. With beam skipping (amcl's ``do_beamskip``) a beam counts only
where enough of the particles end it near a wall (:func:`counted_beams`).
"""

from __future__ import annotations

import math

import numba
import numpy as np

from slam2d.localization.config import MclConfig
from slam2d.localization.maps import KnownMap
from slam2d.types import Scan

__all__ = ["BeamModel", "LikelihoodField", "counted_beams", "seen_through", "select_beams", "sensor_model"]

THROUGH_MARGIN = 0.3  # m a reading must reach beyond the first wall along its beam to count as seen through
THROUGH_MIN_BEAMS = 10  # fewer returns than this tell nothing
SKIP_AT_MOST = 0.9  # share of the beams beam skipping may leave out; beyond it every beam counts (amcl's)


def select_beams(scan: Scan, count: int, skip_max: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """Ranges and angles (m, rad; sensor frame) of at most ``count`` beams evenly spread over the
    scan's valid ones (finite, >= range_min; below range_max too with ``skip_max``)."""
    r = np.asarray(scan.ranges, dtype=np.float64)
    with np.errstate(invalid="ignore"):
        ok = np.isfinite(r) & (r >= scan.range_min)
        if skip_max:
            ok &= r < scan.range_max
    idx = np.flatnonzero(ok)
    if len(idx) > count:
        idx = idx[np.round(np.linspace(0, len(idx) - 1, count)).astype(np.int64)]
    return np.minimum(r[idx], scan.range_max), np.asarray(scan.angles, dtype=np.float64)[idx]


def kept_beams(beams: int, best: float) -> int:
    """How many of ``beams`` a likelihood over the ``best`` share of them counts (at least one)."""
    return beams if best >= 1.0 else max(1, math.ceil(best * beams))


def counted_beams(near: np.ndarray, share: float) -> np.ndarray:
    """Beam skipping (amcl's): of ``near`` (P, B), whether each particle ends each beam near a wall, the
    beams (B,) bool that more than ``share`` of the particles end near one. A beam few particles explain
    reads what the map lacks (a wall worn off a SLAM grid, a person), and the few it fits would be pulled
    there; when that leaves out more than SKIP_AT_MOST of the beams, the pose is wrong and every beam counts."""
    counted = near.mean(axis=0) > share
    return counted if np.count_nonzero(~counted) < SKIP_AT_MOST * len(counted) else np.ones_like(counted)


class LikelihoodField:
    """Per-cell beam scores of the likelihood field: log p (product) or p^3 (amcl), float64 (H, W);
    ``sigma_hit`` (m) overrides the config's."""

    def __init__(self, known: KnownMap, cfg: MclConfig, range_max: float, sigma_hit: float | None = None):
        self.map, self.cfg = known, cfg
        self.sigma_hit = cfg.sigma_hit if sigma_hit is None else sigma_hit
        d = np.minimum(known.distance(), cfg.max_dist)
        self.table = np.ascontiguousarray(self._score(d, range_max))
        self.outside = float(self._score(np.array(cfg.max_dist), range_max))
        self.near = float(self._score(np.array(cfg.beam_skip_distance), range_max))  # a score at least this: near

    def _score(self, d: np.ndarray, range_max: float) -> np.ndarray:
        cfg = self.cfg
        p = cfg.z_hit * np.exp(-(d**2) / (2 * self.sigma_hit**2)) + cfg.z_rand / range_max
        return p**3 if cfg.combine == "amcl" else cfg.beam_weight * np.log(p)

    def log_likelihood(self, particles: np.ndarray, scan: Scan, best: float = 1.0, skip: float = 0.0,
                       voters: int | None = None) -> tuple[np.ndarray, int]:
        """Log-likelihood (P,) of ``scan`` at ``particles`` (P, 3), and the number of beams it counts:
        all, or with ``best`` < 1 that share of them, the best-scoring at each particle, or with ``skip``
        > 0 those that more than that share of the first ``voters`` particles (all) end near a wall."""
        ranges, angles = select_beams(scan, self.cfg.beams)
        if len(ranges) == 0:
            return np.zeros(len(particles)), 0
        ends = np.column_stack([ranges * np.cos(angles), ranges * np.sin(angles)])
        keep = kept_beams(len(ranges), best)
        m = self.map
        args = (np.ascontiguousarray(particles), np.asarray(scan.sensor_pose, dtype=np.float64), ends, self.table,
                self.outside, m.origin[0], m.origin[1], m.resolution)  # fmt: skip
        skipping = skip > 0 and keep == len(ranges)
        scores = np.empty((len(particles) if skipping or keep < len(ranges) else 0, len(ranges)))
        total = _field_sum(*args, keep, scores)
        if skipping:
            counted = counted_beams(scores[:voters] >= self.near, skip)
            total, keep = scores[:, counted].sum(axis=1), int(np.count_nonzero(counted))
        total = out_of_walls(m, self.cfg, particles, total, keep * self.outside)
        return (np.log1p(total) if self.cfg.combine == "amcl" else total), keep


@numba.njit(parallel=True, fastmath=True, cache=True)
def _field_sum(particles, sensor, ends, table, outside, ox, oy, res, keep, scores):  # pragma: no cover - compiled
    """Sum over beams of the table's score at each particle's beam end points (the ``keep`` highest
    of them when fewer than all), (P,); each score also written to ``scores`` when it holds a row
    per particle ((P, B); (0, B) for none, allowed only with every beam kept)."""
    n, nb, h, w = len(particles), len(ends), table.shape[0], table.shape[1]
    out = np.empty(n)
    inv = 1.0 / res
    for i in numba.prange(n):
        c, s = math.cos(particles[i, 2]), math.sin(particles[i, 2])
        sx = particles[i, 0] + c * sensor[0] - s * sensor[1]
        sy = particles[i, 1] + s * sensor[0] + c * sensor[1]
        st = particles[i, 2] + sensor[2]
        cs, ss = math.cos(st), math.sin(st)
        acc = 0.0
        for b in range(nb):
            col = int(math.floor((sx + cs * ends[b, 0] - ss * ends[b, 1] - ox) * inv))
            row = int(math.floor((sy + ss * ends[b, 0] + cs * ends[b, 1] - oy) * inv))
            v = table[row, col] if 0 <= row < h and 0 <= col < w else outside
            acc += v
            if len(scores):
                scores[i, b] = v
        out[i] = acc if keep >= nb else np.sort(scores[i])[nb - keep :].sum()
    return out


class BeamModel:
    """Beam model: expected ranges ray-cast in the occupied cells, then a four-part mixture per beam."""

    def __init__(self, known: KnownMap, cfg: MclConfig, range_max: float):
        self.map, self.cfg, self.range_max = known, cfg, float(range_max)

    def expected_ranges(self, particles: np.ndarray, sensor, angles: np.ndarray) -> np.ndarray:
        """Ranges (P, n) m to the first occupied cell along ``angles`` (sensor frame) from each particle."""
        return expected_ranges(self.map, particles, sensor, angles, self.range_max)

    def log_likelihood(self, particles: np.ndarray, scan: Scan, best: float = 1.0, skip: float = 0.0,
                       voters: int | None = None) -> tuple[np.ndarray, int]:
        """Log-likelihood (P,) of ``scan`` at ``particles`` (P, 3), and the number of beams it counts
        (with ``best`` < 1 that share of them, the best-scoring at each particle; with ``skip`` > 0 those
        that more than that share of the first ``voters`` particles read within beam_skip_distance of
        the expected range)."""
        ranges, angles = select_beams(scan, self.cfg.beams, skip_max=False)
        if len(ranges) == 0:
            return np.zeros(len(particles)), 0
        expected = self.expected_ranges(particles, scan.sensor_pose, angles)
        p = beam_probability(ranges[None], expected, self.cfg, self.range_max)
        n = kept_beams(len(ranges), best)
        if n < p.shape[1]:
            p = np.sort(p, axis=1)[:, p.shape[1] - n :]
        elif skip > 0:
            p = p[:, counted_beams(np.abs(ranges - expected[:voters]) < self.cfg.beam_skip_distance, skip)]
            n = p.shape[1]
        floor, weight = self.cfg.z_rand / self.range_max, self.cfg.beam_weight  # every beam missed
        if self.cfg.combine == "amcl":
            ll, worst = np.log1p((p**3).sum(axis=1)), math.log1p(n * floor**3)
        else:
            ll, worst = weight * np.log(p).sum(axis=1), n * weight * math.log(floor)
        return out_of_walls(self.map, self.cfg, particles, ll, worst), n


def out_of_walls(known: KnownMap, cfg: MclConfig, particles: np.ndarray, score: np.ndarray, worst: float):
    """``score`` (P,) with the particles standing in an occupied cell set to ``worst`` (unless ``wall_poses``)."""
    if not cfg.wall_poses:
        score[known.in_wall(particles[:, :2])] = worst
    return score


def beam_probability(z: np.ndarray, expected: np.ndarray, cfg: MclConfig, range_max: float) -> np.ndarray:
    """The beam model's p(z | z*) for readings ``z`` and expected ranges ``expected`` (m), broadcast."""
    hit = np.exp(-((z - expected) ** 2) / (2 * cfg.sigma_hit**2)) / (cfg.sigma_hit * math.sqrt(2 * math.pi))
    short = np.where(z < expected, cfg.lambda_short * np.exp(-cfg.lambda_short * z), 0.0)
    at_max = np.where(z >= range_max, 1.0, 0.0)
    return cfg.z_hit * hit + cfg.z_short * short + cfg.z_max * at_max + cfg.z_rand / range_max


@numba.njit(parallel=True, fastmath=True, cache=True)
def _raycast(particles, sensor, angles, occupied, ox, oy, res, range_max):  # pragma: no cover - compiled
    """Grid ray casting (DDA over cells) from each particle's sensor along each angle, (P, n) m."""
    n, k = len(particles), len(angles)
    h, w = occupied.shape
    out = np.full((n, k), range_max)
    for i in numba.prange(n):
        c, s = math.cos(particles[i, 2]), math.sin(particles[i, 2])
        sx = particles[i, 0] + c * sensor[0] - s * sensor[1]
        sy = particles[i, 1] + s * sensor[0] + c * sensor[1]
        for b in range(k):
            a = particles[i, 2] + sensor[2] + angles[b]
            out[i, b] = _ray(sx, sy, math.cos(a), math.sin(a), occupied, ox, oy, res, range_max, h, w)
    return out


@numba.njit(fastmath=True, cache=True)
def _ray(x, y, dx, dy, occupied, ox, oy, res, range_max, h, w):  # pragma: no cover - compiled
    """Distance (m) from (x, y) along unit (dx, dy) to the first occupied cell, or range_max."""
    fx, fy = (x - ox) / res, (y - oy) / res
    col, row = int(math.floor(fx)), int(math.floor(fy))
    step_c = 1 if dx > 0 else -1
    step_r = 1 if dy > 0 else -1
    big = 1e30
    t_dc = abs(1.0 / dx) if dx != 0 else big
    t_dr = abs(1.0 / dy) if dy != 0 else big
    t_c = ((col + 1 - fx) if dx > 0 else (fx - col)) * t_dc if dx != 0 else big
    t_r = ((row + 1 - fy) if dy > 0 else (fy - row)) * t_dr if dy != 0 else big
    t, t_max = 0.0, range_max / res
    while t <= t_max:
        if 0 <= row < h and 0 <= col < w:
            if occupied[row, col]:
                return min(t * res, range_max)
        elif (col < 0 and step_c < 0) or (col >= w and step_c > 0) or (row < 0 and step_r < 0) or (
                row >= h and step_r > 0):
            return range_max
        if t_c < t_r:
            t, col, t_c = t_c, col + step_c, t_c + t_dc
        else:
            t, row, t_r = t_r, row + step_r, t_r + t_dr
    return range_max


def seen_through(known: KnownMap, pose: np.ndarray, scan: Scan, count: int, range_max: float) -> float | None:
    """Share of ``count`` beams of ``scan`` (returns short of range_max) that read more than THROUGH_MARGIN m
    beyond the first occupied cell along them from ``pose`` (3,): beams passing walls the map holds. A map
    that lacks a wall the laser sees makes readings short, not long; a wrong pose makes both. None with
    fewer than THROUGH_MIN_BEAMS returns."""
    ranges, angles = select_beams(scan, count)
    if len(ranges) < THROUGH_MIN_BEAMS:
        return None
    expected = expected_ranges(known, np.reshape(pose, (1, 3)), scan.sensor_pose, angles, range_max)[0]
    return float(np.mean(ranges > expected + THROUGH_MARGIN))


def expected_ranges(known: KnownMap, poses: np.ndarray, sensor, angles: np.ndarray, range_max: float) -> np.ndarray:
    """Ranges (P, n) m to the first occupied cell of ``known`` along ``angles`` (sensor frame, the sensor at
    ``sensor`` (3,) on the robot) from each of ``poses`` (P, 3), at most ``range_max``."""
    return _raycast(np.ascontiguousarray(poses, dtype=np.float64), np.asarray(sensor, dtype=np.float64),
                    np.asarray(angles, dtype=np.float64), known.occupied, known.origin[0], known.origin[1],
                    known.resolution, float(range_max))  # fmt: skip


def sensor_model(known: KnownMap, cfg: MclConfig, range_max: float):
    """The configured sensor model of ``known`` for a laser reaching ``range_max`` m."""
    return LikelihoodField(known, cfg, range_max) if cfg.model == "likelihood_field" else BeamModel(
        known, cfg, range_max)
