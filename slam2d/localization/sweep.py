"""A global sweep when a search begins: the places anywhere on the map that fit the scan about as well
as the best one found join as hypotheses.

After a kidnap the filter draws random particles by the scans' likelihood, a few thousand over the
whole map; a place can be missed, its twin elsewhere then settles, fits as well as the truth and,
the only hypothesis left, is claimed (lab_a, kidnap seed 17 before this sweep: the room 8.4 m along
the corridor, whose look-alike the map's analysis does not find, what lies behind the rooms' walls
differing). So when random particles first come after tracking (or an initial pose), the filter
sweeps the map once: ``global_candidates`` x ``max_particles`` poses uniform over the free space (as
many as a global start weighs) are scored by the scan on the smooth field, the best of each place
(MAX_HYPOTHESES places at most) refined by a few local rounds, and every place within the evidence
threshold of the best refined one gets ``hypothesis_particles`` particles, each weighing as one of
the random particles drawn with it (a place the map's imperfection makes fit better than the tracked
one must not outweigh it at once); the floors keep them until the scans that follow tell them apart.
The same sweep, on a random stream of its own, probes for a place that contradicts a tracked estimate
(:func:`clear_elsewhere`: one that fits the scan better and reads clear of the map's walls).
"""

from __future__ import annotations

import math

import numpy as np
from scipy.special import logsumexp

from slam2d import geometry
from slam2d.localization.clusters import MAX_HYPOTHESES, same_place
from slam2d.localization.sensor import seen_through
from slam2d.types import Scan

__all__ = ["add_swept", "best_elsewhere", "clear_elsewhere"]

SHORTLIST = 2000  # best-fitting candidates whose places are refined, at most MAX_HYPOTHESES places
REFINE = ((0.3, 0.1), (0.15, 0.05), (0.05, 0.02))  # m, rad: sd of each local round's poses
REFINE_POSES = 30  # poses per place and round
SPREAD = np.array([0.05, 0.05, 0.02])  # m, m, rad: sd of the particles given to a place found
CLEAR = 0.05  # share of readings beyond the walls at most at a place that contradicts the estimate: a kidnap's
# true place reads none (0.02 on the office), where a SLAM map is seen through the places fitting better 0.5-0.9


def add_swept(pf, est, scan: Scan) -> int:
    """Give filter ``pf`` (its estimate ``est``) ``hypothesis_particles`` round every place a global
    sweep finds fitting ``scan`` within ``pf.evidence_threshold`` (log) of the best place found, but
    the best hypothesis's, each weighing as a random particle (one over the particles); how many places."""
    best = est.hypotheses[0]
    places = _sweep(pf, best.pose, scan, pf.rng)
    if not places:
        return 0
    found, fit = _refine(pf, np.array(places), scan)
    n, share = max(pf.cfg.hypothesis_particles, 1), -math.log(len(pf.particles))
    added: list = []
    for i in np.argsort(-fit, kind="stable"):
        if fit[i] < fit.max() - pf.evidence_threshold:
            break
        if same_place(found[i], best.pose) or any(same_place(found[i], p) for p in added):
            continue
        added.append(found[i])
        cloud = found[i] + pf.rng.standard_normal((n, 3)) * SPREAD
        cloud[:, 2] = geometry.wrap_angle(cloud[:, 2])
        pf.particles = np.concatenate([pf.particles, cloud])
        pf.log_w = np.concatenate([pf.log_w, np.full(n, share)])
    if added:
        pf.log_w -= logsumexp(pf.log_w)
    return len(added)


def best_elsewhere(pf, pose: np.ndarray, scan: Scan, rng: np.random.Generator) -> tuple[np.ndarray, float] | None:
    """The best place (3,) a sweep of filter ``pf``'s map (drawn from ``rng``) finds for ``scan`` away from
    ``pose``, refined, and its log-likelihood over ``pose`` refined alike (the smoother field); None if none."""
    places = _sweep(pf, pose, scan, rng)
    if not places:
        return None
    found, fit = _refine(pf, np.vstack([pose, places]), scan, rng)
    i = 1 + int(np.argmax(fit[1:]))
    return found[i], float(fit[i] - fit[0])


def clear_elsewhere(pf, pose: np.ndarray, scan: Scan) -> bool:
    """Whether the best place a sweep of filter ``pf``'s map finds for ``scan`` fits it better than ``pose``
    (3,) and reads at most CLEAR beyond the map's walls. The sweep draws from a generator of its own (seeded
    by the update), so that the filter's draws do not change."""
    found = best_elsewhere(pf, pose, scan, np.random.default_rng(pf.updates))
    if found is None or found[1] <= 0:
        return False
    through = seen_through(pf.map, found[0], scan, pf.cfg.beams, pf.range_max)
    return through is not None and through <= CLEAR


def _sweep(pf, pose: np.ndarray, scan: Scan, rng: np.random.Generator) -> list:
    """The sweep: ``global_candidates`` x ``max_particles`` poses uniform over filter ``pf``'s free space (drawn
    from ``rng``) scored by ``scan`` on the smooth field, the best of up to MAX_HYPOTHESES places none at ``pose``."""
    pool = pf.random_poses(pf.cfg.global_candidates * pf.cfg.max_particles, rng)
    return _places(pool, pf.coarse.log_likelihood(pool, scan)[0], pose)


def _places(pool: np.ndarray, ll: np.ndarray, best: np.ndarray) -> list:
    """Up to MAX_HYPOTHESES poses of ``pool``, best log-likelihood ``ll`` first among the SHORTLIST best,
    each at a place of its own and none at ``best``'s."""
    out: list = []
    for i in np.argsort(-ll, kind="stable")[:SHORTLIST]:
        if not same_place(pool[i], best) and not any(same_place(pool[i], p) for p in out):
            out.append(pool[i])
            if len(out) == MAX_HYPOTHESES:
                break
    return out


def _refine(pf, poses: np.ndarray, scan: Scan, rng: np.random.Generator | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Each pose (K, 3) moved to the best-fitting of REFINE_POSES poses round it (drawn from ``rng``, the
    filter's by default), round after round of REFINE; the poses and their log-likelihoods (K,)."""
    best = poses.copy()
    fit = pf.coarse.log_likelihood(best, scan)[0]
    for sd_xy, sd_theta in REFINE:
        sd = np.array([sd_xy, sd_xy, sd_theta])
        trial = best[:, None, :] + (rng or pf.rng).standard_normal((len(best), REFINE_POSES, 3)) * sd
        trial[..., 2] = geometry.wrap_angle(trial[..., 2])
        tll = pf.coarse.log_likelihood(trial.reshape(-1, 3), scan)[0].reshape(len(best), REFINE_POSES)
        j = np.argmax(tll, axis=1)
        better = tll[np.arange(len(best)), j] > fit
        best[better] = trial[np.arange(len(best)), j][better]
        fit[better] = tll[np.arange(len(best)), j][better]
    return best, fit
