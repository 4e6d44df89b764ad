"""Monte Carlo localisation on a known map: augmented MCL with KLD sampling.

One :class:`ParticleFilter` covers global localisation (:meth:`~ParticleFilter.init_global`),
tracking from a rough pose (:meth:`~ParticleFilter.init_pose`) and recovery after a
kidnapping (random particles, Thrun et al. 2005 Table 8.3). Every scan goes to
:meth:`~ParticleFilter.add`; the filter updates only after ``update_min_d`` m or
``update_min_a`` rad of odometry (as amcl): odometry motion model (four alphas),
sensor model (likelihood field or beams; each cluster's total weight by the
scan's likelihood at its mean pose), then low-variance resampling when the
effective sample size drops or a confident filter's random particles are due,
drawing random free-space poses with probability
max(0, 1 - w_fast / w_slow) (while confident, averages of the likelihood of the
best-fitting half of the beams, so that a map lacking part of what the laser
sees does not pass for a kidnapping) and keeping as many particles as KLD sampling
(Fox 2003) asks. The pose is the weighted mean of the heaviest cluster of
particles (connected histogram bins), with its covariance; between updates it
follows the odometry. Once it jumps away from the place it tracked, that place is
kept (:mod:`slam2d.localization.home`): the new one is claimed only while its recent
evidence over the old one holds. A search from random particles begins with one global sweep
(:mod:`slam2d.localization.sweep`): the places anywhere that fit the scan join as hypotheses.
Vectorised over particles (numba for the sensor models); the same seed gives the same particles.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.special import logsumexp
from scipy.stats import norm

from slam2d import geometry
from slam2d.errors import InputError
from slam2d.limits import check_memory
from slam2d.localization.clusters import (
    MAX_HYPOTHESES,
    Estimate,
    Hypothesis,
    _bins,
    _distinct_so_far,
    _group_logsumexp,
    cluster_means,
    clusters,
    hypotheses,
    same_place,
    with_floors,
)
from slam2d.localization.config import MclConfig
from slam2d.localization.home import Home
from slam2d.localization.lookalike import add_lookalikes, look_alikes
from slam2d.localization.maps import KnownMap
from slam2d.localization.sampling import kld_limit, low_variance_indices, sample_motion
from slam2d.localization.sensor import LikelihoodField, seen_through, sensor_model
from slam2d.localization.sweep import add_swept, clear_elsewhere
from slam2d.types import Scan

__all__ = ["Estimate", "ParticleFilter", "kld_limit", "low_variance_indices", "sample_motion"]

PARTICLE_BEAM_BYTES = 32  # memory per particle and beam while a scan is weighed (float64 temporaries)
CONFIDENT_NOISE = 0.4  # random share below which a confident filter draws no random particle: a map lacking
# walls the laser sees dims the best-fitting half of the beams by up to 30 % (ACES in its SLAM map), a kidnap by ~90 %
SEEN_THROUGH = 0.4  # short-term average share of beams read beyond the map's walls from which the pose is doubted
THROUGH_NOISE = 0.1  # random share below which a confident filter whose scans see through walls draws nothing
DOUBTED = 0.15  # that average from which a confident filter whose every beam asks for random particles probes the
# map (:meth:`ParticleFilter.contradicted`): a map lacking walls reads short (the worn office <= 0.05)
LOCAL_SPREAD = np.array([0.3, 0.3, 0.1])  # m, m, rad: sd of recovery candidates around the current particles
STATES = ("tracking", "ambiguous", "lost")
FIT_DEFICIT = 0.1  # short-term average likelihood this far below the long-term one: the pose is not claimed
FIT_ALPHA = 0.3  # decay of that short-term average (w_fast's 0.1 lags a recovery by seconds)


class ParticleFilter:
    """Augmented MCL with KLD sampling on ``known`` for a laser reaching ``range_max`` m."""

    def __init__(self, known: KnownMap, cfg: MclConfig | None = None, range_max: float = 12.0, seed: int = 0):
        self.map, self.cfg = known, cfg or MclConfig()
        if self.cfg.min_particles > self.cfg.max_particles:
            raise InputError("localization.min_particles", "must not exceed max_particles")
        pool = self.cfg.max_particles * self.cfg.global_candidates
        check_memory(pool * (self.cfg.beams * PARTICLE_BEAM_BYTES + 64), "localization.mcl.max_particles",
                     f"weighing {pool} particles on {self.cfg.beams} beams")
        self.range_max = float(range_max)
        self.sensor = sensor_model(known, self.cfg, range_max)
        self.coarse = self.sensor  # the smoother likelihood field used while the pose is uncertain
        if self.cfg.model == "likelihood_field" and self.cfg.sigma_hit_uncertain != self.cfg.sigma_hit:
            self.coarse = LikelihoodField(known, self.cfg, range_max, self.cfg.sigma_hit_uncertain)
        self.rng = np.random.default_rng(seed)
        self.kld_z = float(norm.ppf(1.0 - self.cfg.kld_delta))
        self._free = known.free_cells(self.cfg.free_clearance)
        self.particles = np.zeros((0, 3))
        self.log_w = np.zeros(0)
        self.w_slow, self.w_fast = np.zeros(2), np.zeros(2)  # of all beams, of the best-fitting share
        self.w_fit = 0.0  # short-term average likelihood of every beam (FIT_ALPHA), for the state
        self.through = 0.0  # short-term average (FIT_ALPHA) share of beams read beyond the map's walls at the pose
        self.updates = self.resamples = self.injected = 0
        self.sharp_beams = np.zeros(2, dtype=np.int64)  # beams of the sharp field's weights: selected, skipped
        self.home = Home()  # the place last tracked, weighed against a far estimate (slam2d.localization.home)
        self._odom: np.ndarray | None = None  # odometry at the last update
        self._estimate: Estimate | None = None
        self._labels: np.ndarray | None = None  # cluster of each particle at the last estimate
        self._best_label = 0  # the heaviest cluster's label
        self._hypothesis_labels = np.zeros(1, dtype=np.int64)  # the cluster label of each hypothesis
        self._tested = False  # the compact best hypothesis's look-alike places were added
        self._anchored = False  # an initial pose rules look-alike places out
        self._searching = False  # no tracking since the global start or the last random particles
        self._swept = False  # a global set was weighed since (the global start's, or add_swept's)
        self._estimate_odom: np.ndarray | None = None  # odometry at the last estimate
        self.lookalikes = None  # the map's look-alike places (slam2d.localization.lookalike), with hypotheses
        self.evidence_threshold = math.inf  # log weight ratio best / runner-up from which the state is tracking
        if self.cfg.hypotheses:
            self.lookalikes = look_alikes(known, self.cfg.lookalike_radius, self.cfg.lookalike_match)
            c = self.cfg.confidence
            self.evidence_threshold = math.log(self.lookalikes.places * c / (1.0 - c))
        self._candidates = False  # the next update weighs global candidates
        self._contradicted = False  # the last update's scan is contradicted (see contradicted())

    # initialisation ------------------------------------------------------

    def random_poses(self, count: int, rng: np.random.Generator | None = None) -> np.ndarray:
        """``count`` poses uniform over the free cells (``free_clearance`` off walls), any heading, from ``rng``."""
        m, rng = self.map, rng or self.rng
        cells = self._free[rng.integers(0, len(self._free), count)]
        row, col = np.divmod(cells, m.shape[1])
        xy = np.column_stack([col, row]) + rng.random((count, 2))
        theta = rng.uniform(-np.pi, np.pi, count)
        return np.column_stack([m.origin[0] + xy[:, 0] * m.resolution, m.origin[1] + xy[:, 1] * m.resolution, theta])

    def guided_random_poses(self, count: int, scan: Scan) -> np.ndarray:
        """``count`` poses drawn by the scan's likelihood (the smoother field) from ``recovery_candidates``
        times as many candidates: half uniform over the free space, half the current particles moved
        by ``LOCAL_SPREAD`` (a cloud slightly off the truth finds it as fast as a far one)."""
        k = self.cfg.recovery_candidates
        if count == 0 or k <= 1:
            return self.random_poses(count)
        near = self.particles[self.rng.integers(0, len(self.particles), count * k // 2)]
        near = near + self.rng.standard_normal(near.shape) * LOCAL_SPREAD
        pool = np.concatenate([self.random_poses(count * k - len(near)), near])
        pool[:, 2] = geometry.wrap_angle(pool[:, 2])
        ll = self.coarse.log_likelihood(pool, scan)[0]
        return pool[low_variance_indices(np.exp(ll - logsumexp(ll)), count, self.rng)]

    def init_global(self) -> None:
        """No initial pose: ``max_particles`` poses uniform over the free space (``global_candidates``
        times as many when the first scan comes, of which it keeps ``max_particles``)."""
        self._reset(self.random_poses(self.cfg.max_particles))
        self._candidates = self.cfg.global_candidates > 1
        self._searching = True

    def init_pose(self, pose, sd_xy: float | None = None, sd_theta: float | None = None) -> None:
        """A rough initial pose (3,): ``max_particles`` Gaussian poses around it (sd m, rad; config's by default);
        its look-alike places are not hypotheses (the given pose rules them out)."""
        pose = geometry.as_pose(pose).reshape(3)
        if not np.isfinite(pose).all():
            raise InputError("initial pose", f"must be finite, got {pose.tolist()}")
        sd = np.array([self.cfg.initial_sd_xy if sd_xy is None else sd_xy] * 2
                      + [self.cfg.initial_sd_theta if sd_theta is None else sd_theta])  # fmt: skip
        poses = pose + self.rng.standard_normal((self.cfg.max_particles, 3)) * sd
        poses[:, 2] = geometry.wrap_angle(poses[:, 2])
        self._reset(poses)
        self._anchored = True  # the given pose rules its look-alike places out (until random particles come)

    def _reset(self, poses: np.ndarray) -> None:
        self._candidates = False
        self.particles = poses
        self.log_w = np.full(len(poses), -math.log(len(poses)))
        self.w_slow, self.w_fast = np.zeros(2), np.zeros(2)
        self.w_fit = self.through = 0.0
        self._estimate = self._labels = None
        self._tested = self._anchored = self._searching = self._swept = False
        self.home = Home()

    # the filter ------------------------------------------------------------

    def add(self, scan: Scan) -> bool:
        """Feed one scan (its ``odom`` pose); True if the filter updated (moved far enough, or first scan)."""
        if len(self.particles) == 0:
            raise RuntimeError("initialise the filter first (init_global or init_pose)")
        odom = np.asarray(scan.odom, dtype=np.float64)
        if not np.isfinite(odom).all():
            raise InputError(f"scan {scan.index}", "odometry pose is not finite")
        if self._odom is not None:
            d = geometry.between(self._odom, odom)
            if math.hypot(d[0], d[1]) < self.cfg.update_min_d and abs(d[2]) < self.cfg.update_min_a:
                return False
            self.particles = sample_motion(self.particles, self._odom, odom, self.cfg, self.rng)
        self._odom = odom.copy()
        if self._candidates:
            self._first_from_candidates(scan)
        else:
            self._measure(scan)
        return True

    def _first_from_candidates(self, scan: Scan) -> None:
        """Weigh ``global_candidates`` x ``max_particles`` uniform poses by the first scan and keep
        ``max_particles`` of them drawn by weight (low variance): the first update."""
        self._candidates, self._swept = False, True
        n = self.cfg.max_particles
        pool = np.concatenate([self.particles, self.random_poses(n * (self.cfg.global_candidates - 1))])
        ll, beams = self.coarse.log_likelihood(pool, scan)
        self.particles = pool[low_variance_indices(np.exp(ll - logsumexp(ll)), n, self.rng)]
        self.log_w = np.full(n, -math.log(n))
        self.updates += 1
        if beams > 0 and self._recovering():
            for i, (fit, counted) in enumerate(self._recovery_fits(pool, scan, ll, beams)):
                self._average(i, float(logsumexp(fit) - math.log(len(pool))), counted)
                self.w_slow[i] = max(self.w_slow[i], self._best_fit(fit, counted))
        self._update_estimate(scan)

    def _best_fit(self, loglik: np.ndarray, beams: int) -> float:
        """Mean likelihood (as :meth:`_average` scales it) of the best 1 % of ``loglik``: what a filter
        converged on the right place should reach, the long-term average a global start begins with."""
        top = np.partition(loglik, len(loglik) - max(1, len(loglik) // 100))[-max(1, len(loglik) // 100):]
        total = float(logsumexp(top) - math.log(len(top)))
        return math.exp(total / (beams * self.cfg.beam_weight)) if self.cfg.combine == "product" else math.exp(total)

    def _measure(self, scan: Scan) -> None:
        """Weigh by the scan, track the likelihood averages, resample when due, estimate.

        Resampling is due when N_eff drops, and when a confident filter's :meth:`random_share` asks
        for random particles: after a kidnap its particles can all fit equally badly, so that N_eff
        stays high (an uncertain filter resamples only by N_eff, so that look-alike places keep
        their particles).

        While the pose is uncertain the weights come from the smoother field (the likelihood averages
        always do, to stay comparable), while certain from the sharp one on the beams ``beam_skip``
        keeps. With ``hypothesis_fit`` the clusters' mean poses are scored in the same pass."""
        self._watch_through(scan)
        sharp = self.confident() and self.coarse is not self.sensor
        refit = self.cfg.hypothesis_fit and self._labels is not None and len(self._labels) == len(self.particles)
        k = int(self._labels.max()) + 1 if refit else 0
        means, old = cluster_means(self.particles, self.log_w, self._labels, k) if refit else (np.zeros((0, 3)), None)
        poses, p = np.concatenate([self.particles, means]), len(self.particles)
        coarse, beams = self.coarse.log_likelihood(poses, scan)
        fine, counted = self.sensor.log_likelihood(poses, scan, skip=self.cfg.beam_skip, voters=p) if sharp else (
            coarse, beams)
        self.sharp_beams += (beams, beams - counted) if sharp else 0
        self.updates += 1
        home = self.home.candidates(self._odom, self.rng) if refit and self.cfg.hypotheses else np.zeros((0, 3))
        if beams > 0 and len(home):
            self._weigh_home(home, scan)
        if beams > 0:
            if self._recovering():
                for i, (fit, counted) in enumerate(self._recovery_fits(self.particles, scan, coarse[:p], beams)):
                    self._average(i, float(logsumexp(self.log_w + fit)), counted)
            joint = self.log_w + fine[:p]
            if refit:
                between = coarse[p:] if self.cfg.hypotheses else fine[p:]  # hypotheses weighed on the smooth field
                joint = joint + (old + between - _group_logsumexp(joint, self._labels, k))[self._labels]
            self.log_w = joint - logsumexp(joint)
        here = self._estimate_here()
        self._contradicted = here is not None and self._doubted_here() and clear_elsewhere(self, here, scan)
        if self._resample_due() or (self.confident() and self.random_share() > 0):
            self._resample(scan)
        self._update_estimate(scan)

    def _weigh_home(self, home: np.ndarray, scan: Scan) -> None:
        """Weigh the old place's candidate poses ``home`` against as many of the best hypothesis's heaviest
        particles, on the sharp field's best-fitting ``recovery_best_beams`` of the beams (a map lacking what
        the laser sees leaves them explained at the right place); the best-fitting pose of each counts."""
        inside = np.flatnonzero(self._labels == self._best_label)
        top = inside[np.argsort(-self.log_w[inside], kind="stable")[:len(home)]]
        poses = np.concatenate([home, self.particles[top]])
        ll = self.sensor.log_likelihood(poses, scan, best=self.cfg.recovery_best_beams)[0]
        through = seen_through(self.map, home[0], scan, self.cfg.beams, self.range_max)
        self.home.weigh(home, ll[:len(home)], float(ll[len(home):].max()), through)

    def _estimate_here(self) -> np.ndarray | None:
        """The last estimate's pose (3,) moved by the odometry since then to this update (None before one)."""
        est, odom = self._estimate, self._estimate_odom
        return None if est is None or odom is None else geometry.compose(est.pose, geometry.between(odom, self._odom))

    def _watch_through(self, scan: Scan) -> None:
        """Average into ``through`` the share of beams the scan reads beyond the map's walls at the last
        estimate moved by the odometry since (only with recovery on)."""
        here = self._estimate_here()
        if not self._recovering() or here is None:
            return
        share = seen_through(self.map, here, scan, self.cfg.beams, self.range_max)
        if share is not None:
            self.through += FIT_ALPHA * (share - self.through)

    def _recovering(self) -> bool:
        return self.cfg.alpha_slow > 0 and self.cfg.alpha_fast > 0

    def _recovery_fits(self, poses: np.ndarray, scan: Scan, loglik: np.ndarray, beams: int) -> list:
        """What the two pairs of w_slow / w_fast average, each as (log-likelihood (P,), beams counted):
        ``loglik`` (the smoother field's, all ``beams``), and the sharp model's of the best
        ``recovery_best_beams`` share of the beams at each of ``poses`` (none when that share is 1)."""
        fits = [(loglik, beams)]
        if self.cfg.recovery_best_beams < 1.0:
            fits.append(self.sensor.log_likelihood(poses, scan, best=self.cfg.recovery_best_beams))
        return fits

    def _average(self, i: int, log_total: float, beams: int) -> None:
        """Update the i-th w_slow and w_fast from the weighted mean likelihood (per beam for the product model)."""
        cfg = self.cfg
        w_avg = math.exp(log_total / (beams * cfg.beam_weight)) if cfg.combine == "product" else math.exp(log_total)
        for w, alpha in ((self.w_slow, cfg.alpha_slow), (self.w_fast, cfg.alpha_fast)):
            w[i] = w_avg if w[i] == 0.0 else w[i] + alpha * (w_avg - w[i])
        if i == 0:  # the fit the state is judged on: as w_fast, quicker
            self.w_fit = w_avg if self.w_fit == 0.0 else self.w_fit + FIT_ALPHA * (w_avg - self.w_fit)

    def _resample_due(self) -> bool:
        if self.cfg.resample_ess > 0:
            ess = 1.0 / float(np.sum(np.exp(2 * self.log_w)))
            return ess < self.cfg.resample_ess * len(self.log_w)
        return self.updates % self.cfg.resample_interval == 0

    def random_share(self) -> float:
        """Probability max(0, 1 - w_fast / w_slow) of a random particle at resampling (0 with recovery off).

        While the filter is confident the averages are those of the best-fitting share of the beams:
        a map that lacks part of what the laser sees (an opened door, glass, a wall worn off a SLAM
        grid) is no kidnapping, a place where even those beams stop fitting is. Once it is not,
        those of every beam: it searches on until a place explains the whole scan, not half of it.
        While confident, a share up to ``CONFIDENT_NOISE`` is the map's imperfection and draws nothing:
        a single random particle on a look-alike corridor would outscore a place whose map lacks a wall,
        and where a SLAM map lacks a wall along metres of corridor the best half fits up to 30 % worse.
        But a map lacking walls makes readings short; readings beyond the map's walls (``through`` at
        least ``SEEN_THROUGH``) mean a wrong pose, and then a share above ``THROUGH_NOISE`` draws.
        A search (no ``tracking`` since the global start or the last random particles) whose cloud has
        settled where the scans fit worse than usual is not confident either: after a kidnap the cloud
        can settle on a wrong place whose best half of the beams fits. Nor is a filter whose scans are
        :meth:`contradicted`: after a kidnap the best half can fit the old place as usual (office kidnap
        seed 3: 0.6-0.95 of it, the whole scan 0.2-0.4)."""
        doubted = (self._searching and not self._fits()) or self._contradicted
        confident = self.cfg.recovery_best_beams < 1.0 and self.confident() and not doubted
        i = 1 if confident else 0
        if not self._recovering() or self.w_slow[i] <= 0:
            return 0.0
        share = 1.0 - self.w_fast[i] / self.w_slow[i]
        noise = (THROUGH_NOISE if self.through >= SEEN_THROUGH else CONFIDENT_NOISE) if confident else 0.0
        return share if share > noise else 0.0

    def contradicted(self) -> bool:
        """Whether the last update's scan contradicts the estimate: every beam's averages ask for random
        particles as a confident filter's best half must (a share above ``CONFIDENT_NOISE``) while the
        scans read beyond the map's walls at the estimate (``through`` at least ``DOUBTED``), and a probe
        of the whole map finds a place that fits the scan better and reads clear of its walls
        (:func:`~slam2d.localization.sweep.clear_elsewhere`). A map lacking walls reads short; a SLAM map
        seen through at the right place reads long too, but so do the places that fit better there; a
        kidnap's true place reads clear."""
        return self._contradicted

    def _doubted_here(self) -> bool:
        """The first two signs of :meth:`contradicted` (every beam misfits, readings beyond the walls)."""
        w_slow, w_fast = self.w_slow[0], self.w_fast[0]
        return self._recovering() and self.through >= DOUBTED and w_slow > 0 and 1 - w_fast / w_slow > CONFIDENT_NOISE

    def _resample(self, scan: Scan) -> None:
        """Low-variance resampling with random free-space poses, as many as KLD sampling asks.

        Each of ``max_particles`` slots of a random-order draw is a uniform random pose with
        probability :meth:`random_share`; KLD's count n comes from the bins of these slots (so that
        random poses raise it, as in amcl). The random slots among the first n are then drawn by
        the scan's likelihood (``recovery_candidates``), the others again with one offset from the
        weights, so that the hypotheses keep their shares."""
        cfg, n_max = self.cfg, self.cfg.max_particles
        weights = np.exp(self.log_w)
        drawn = self.particles[low_variance_indices(weights, n_max, self.rng)][self.rng.permutation(n_max)]
        share = self.random_share()
        is_random = self.rng.random(n_max) < share if share > 0 else np.zeros(n_max, dtype=bool)
        drawn[is_random] = self.random_poses(int(is_random.sum()))
        n = self.kld_count(drawn)  # KLD counts bins along the random order
        n_random = int(is_random[:n].sum())
        kept = low_variance_indices(weights, n - n_random, self.rng)
        per_cluster = cfg.hypotheses and self._labels is not None and len(self._labels) == len(weights)
        if per_cluster:
            kept = with_floors(kept, weights, self._labels, cfg.hypothesis_keep, cfg.hypothesis_particles, self.rng)
        self.particles = np.concatenate([self.particles[kept], self.guided_random_poses(n_random, scan)])
        n = len(self.particles)
        self.log_w = np.full(n, -math.log(n))
        if per_cluster:  # each cluster keeps its weight, shared by the particles drawn into it
            labels = self._labels[kept]
            mass = np.bincount(self._labels, weights=weights)
            self.log_w[:len(kept)] = np.log(mass[labels] / np.bincount(labels)[labels] * len(kept) / n)
            self.log_w -= logsumexp(self.log_w)
        self.resamples += 1
        if n_random:
            self.injected += n_random
            self._anchored = False  # the pose is searched for again: its look-alikes are hypotheses
            self._searching, self._swept = True, self._swept and self._searching  # a new search: sweep
            if cfg.combine == "amcl":  # amcl restarts its averages after injecting
                self.w_slow, self.w_fast = np.zeros(2), np.zeros(2)

    def kld_count(self, poses: np.ndarray) -> int:
        """The first n such that the n leading ``poses`` reach KLD's count for their bins (max if none)."""
        cfg = self.cfg
        k = _distinct_so_far(_bins(poses, cfg.kld_bin_xy, cfg.kld_bin_theta))
        limit = kld_limit(k, cfg.kld_err, self.kld_z, cfg.min_particles, cfg.max_particles, cfg.kld_single_bin)
        enough = np.flatnonzero(np.arange(1, len(poses) + 1) >= limit)
        return int(enough[0]) + 1 if len(enough) else len(poses)

    # estimate -----------------------------------------------------------------

    def _cluster_estimate(self) -> Estimate:
        cfg = self.cfg
        labels = self._labels = clusters(self.particles, cfg.kld_bin_xy, cfg.kld_bin_theta)
        hyps, mass, order = hypotheses(self.particles, self.log_w, labels, MAX_HYPOTHESES if cfg.hypotheses else 1)
        self._best_label, self._hypothesis_labels = int(order[0]), order
        best = hyps[0]
        runner_up = float(np.partition(mass, len(mass) - 2)[-2]) if len(mass) > 1 else 0.0
        evidence = math.log(best.weight / runner_up) if runner_up > 0 else math.inf
        return Estimate(best.pose, best.covariance, best.weight, len(mass), len(self.particles),
                        self._state(best, evidence), tuple(hyps), evidence)  # fmt: skip

    def _state(self, best: Hypothesis, evidence: float) -> str:
        """``lost`` without a compact best hypothesis; ``tracking`` once its evidence over the runner-up
        reaches the threshold, its look-alike places were tested and the scans fit as well as they
        usually do (short-term average likelihood of every beam, ``w_fit``, within FIT_DEFICIT of the
        long-term one: after a kidnap the best of wrong places is no pose) and they read beyond the map's
        walls less than a wrong pose does (``through`` below SEEN_THROUGH); else ``ambiguous``. Without
        ``hypotheses``: tracking whenever the best holds 90 % within converged_sd (as amcl claims)."""
        compact = best.sd_xy < self.cfg.converged_sd
        if not self.cfg.hypotheses:
            return "tracking" if compact and best.weight >= 0.9 else "lost"
        if not compact:
            return "lost"
        claimed = (self._tested and self._fits() and evidence >= self.evidence_threshold
                   and self.through < SEEN_THROUGH)  # fmt: skip
        return "tracking" if claimed and not self.home.holds(self.evidence_threshold) else "ambiguous"

    def _fits(self) -> bool:
        """Whether the scans fit as they usually do (``w_fit`` within FIT_DEFICIT of the long-term average
        of every beam; always without hypotheses or recovery)."""
        return (not self.cfg.hypotheses or not self._recovering() or self.w_slow[0] <= 0
                or self.w_fit >= (1 - FIT_DEFICIT) * self.w_slow[0])  # fmt: skip

    def _update_estimate(self, scan: Scan) -> None:
        """The estimate; when the best hypothesis turns compact (or another one takes the lead), its
        look-alike places join as hypotheses of equal weight (its particles moved onto each place no
        hypothesis holds yet), unless an initial pose rules them out and no random particle came since.
        A search from random particles begins with a global sweep (:func:`~slam2d.localization.sweep.add_swept`)."""
        before, odom_before = self._estimate, self._estimate_odom
        est = self._estimate = self._cluster_estimate()
        if self._follow_home(est):
            est = self._estimate = self._cluster_estimate()
        if self._searching and not self._swept and self.cfg.hypotheses:
            self._swept = True
            if add_swept(self, est, scan):
                est = self._estimate = self._cluster_estimate()
        self._searching = self._searching and est.state != "tracking"
        self._estimate_odom = self._odom.copy() if self._odom is not None else None
        if not self.cfg.hypotheses:
            return
        if est.state == "lost":
            self._tested = False
            return
        if before is not None and odom_before is not None and self._odom is not None:
            expected = geometry.compose(before.pose, geometry.between(odom_before, self._odom))
            if not same_place(est.pose, expected):  # another hypothesis leads: test it too
                self._tested = False
        if not self._tested:
            self._tested = True
            if not self._anchored:  # held places are raised only when the pose turns compact
                add_lookalikes(self, est, before is None or before.state == "lost")
            self._estimate = self._cluster_estimate()

    def _follow_home(self, est: Estimate) -> bool:
        """Move the place last tracked along with ``est`` (:class:`Home`), giving it back particles
        (``hypothesis_particles`` round it, exp(-evidence) times the best hypothesis's weight) once its
        recent evidence over the best reaches the threshold; True when the estimate is to be made again.
        A place not yet left whose scans are :meth:`contradicted` is forgotten: a wrong pose, no map defect."""
        if not self.cfg.hypotheses or self._odom is None:
            return False
        if self._contradicted and not self.home.away:
            self.home = Home()
        held, home = self.home.holds(self.evidence_threshold), self.home
        if not home.update(est.pose, est.state, self._odom, self.map, self.evidence_threshold, SEEN_THROUGH):
            return home.holds(self.evidence_threshold) != held
        n = max(self.cfg.hypothesis_particles, 1)
        best = logsumexp(self.log_w[self._labels == self._best_label])
        self.particles = np.concatenate([self.particles, home.cloud(n, self.rng)])
        self.log_w = np.concatenate([self.log_w, np.full(n, best - home.evidence - math.log(n))])
        self.log_w -= logsumexp(self.log_w)
        return True

    @property
    def state(self) -> str:
        """``tracking``, ``ambiguous`` or ``lost`` (the last estimate's)."""
        return self.estimate.state

    def confident(self) -> bool:
        """Whether the last estimate's cluster holds 90 % of the weight within ``converged_sd`` m."""
        e = self._estimate
        return e is not None and e.share >= 0.9 and e.sd_xy < self.cfg.converged_sd

    @property
    def estimate(self) -> Estimate:
        """The last update's estimate (computed now if there was none)."""
        if self._estimate is None:
            self._estimate = self._cluster_estimate()
        return self._estimate

    def pose(self, odom=None) -> np.ndarray:
        """The pose (3,): the last update's estimate, moved by the odometry since then to ``odom`` (3,)."""
        est = self.estimate.pose
        if odom is None or self._odom is None:
            return est.copy()
        return geometry.compose(est, geometry.between(self._odom, np.asarray(odom, dtype=np.float64)))
