"""The place a filter last tracked, kept as a hypothesis once its estimate jumps away.

A real robot is rarely kidnapped. Where a map lacks what the laser sees, the right place fits worse
for seconds, the filter draws random particles and a far place can out-fit it meanwhile (FR079 in its
own SLAM map: 21–32 m away). So the place the filter last tracked (or followed since) is kept: moved by
the odometry and refined by the scans (the best-fitting of ``HOME_CANDIDATES`` poses round it), it is
weighed every update against the best hypothesis's heaviest particles on the best-fitting share of the
beams (``recovery_best_beams``, the sharp field: what the map lacks at the right place leaves the rest
explained, a wrong place explains few beams). A new place is claimed only while its *recent* evidence
over the old one (log-likelihood differences decayed by ``EVIDENCE_DECAY`` an update, so that a stretch
the map cannot explain is forgotten once the robot has passed it) reaches the map's evidence threshold;
once the old place's recent evidence over the new one does, it gets its particles back. It is dropped
once its scans read beyond its walls (``seen_through``: a wrong pose, a kidnap) or it stands in a wall.
"""

from __future__ import annotations

import numpy as np

from slam2d import geometry
from slam2d.localization.clusters import same_place
from slam2d.localization.maps import KnownMap

HOME_CANDIDATES = 20  # poses scored round the old place each update (itself included)
HOME_SPREAD = np.array([0.05, 0.05, 0.02])  # m, m, rad: their sd
EVIDENCE_DECAY = 0.7  # an update: the recent evidence forgets a stretch in a few seconds (1 - FIT_ALPHA)


class Home:
    """The last tracked place (``pose`` at odometry ``odom``); ``away`` once the estimate left it, with
    the recent log evidence of the best hypothesis over it and the average share of its readings beyond
    the map's walls."""

    def __init__(self) -> None:
        self.pose: np.ndarray | None = None
        self.odom: np.ndarray | None = None
        self.away = False
        self.evidence = 0.0
        self.through = 0.0

    def moved(self, odom: np.ndarray) -> np.ndarray:
        """The place (3,) moved by the odometry since it was set."""
        return geometry.compose(self.pose, geometry.between(self.odom, odom))

    def candidates(self, odom: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """Poses (K, 3) to weigh with the particles: the old place moved to ``odom`` and poses round it
        (none unless away)."""
        if not self.away:
            return np.zeros((0, 3))
        self.pose, self.odom = self.moved(odom), odom.copy()
        return np.vstack([self.pose, self.cloud(HOME_CANDIDATES - 1, rng)])

    def cloud(self, count: int, rng: np.random.Generator) -> np.ndarray:
        """``count`` poses (count, 3) round the place (sd ``HOME_SPREAD``)."""
        poses = self.pose + rng.standard_normal((count, 3)) * HOME_SPREAD
        poses[:, 2] = geometry.wrap_angle(poses[:, 2])
        return poses

    def weigh(self, candidates: np.ndarray, loglik: np.ndarray, best: float, through: float | None) -> None:
        """Refine the place to the best-fitting candidate (log-likelihoods ``loglik``), add the best
        hypothesis's log-likelihood ``best`` over it to the recent evidence, ``through`` (share of readings
        beyond the walls at the place, None: unknown) to its average."""
        i = int(np.argmax(loglik))
        self.pose = candidates[i].copy()
        self.evidence = EVIDENCE_DECAY * self.evidence + (best - float(loglik[i]))
        if through is not None:
            self.through = EVIDENCE_DECAY * self.through + (1 - EVIDENCE_DECAY) * through

    def update(self, pose: np.ndarray, state: str, odom: np.ndarray, known: KnownMap,
               threshold: float, seen_through: float) -> bool:
        """Follow the estimate (``pose``, ``state``) at ``odom``: set the place while tracking, follow it
        while the estimate stays there, mark it away once the estimate jumps. True when the old place
        should be given back its particles (its recent evidence over the best reached ``threshold``).
        Dropped once its readings beyond the walls average ``seen_through`` or it stands in a wall."""
        if self.pose is None:
            if state == "tracking":
                self._set(pose, odom)
            return False
        here = self.moved(odom)
        if same_place(pose, here):
            if state != "lost":
                self._set(pose, odom)
            return False
        if not self.away:
            self.away, self.evidence, self.through = True, 0.0, 0.0
            self.pose, self.odom = here, odom.copy()
            return False
        if self.through >= seen_through or bool(known.in_wall(here[None, :2])[0]):
            self.pose, self.away = None, False
            if state == "tracking":
                self._set(pose, odom)
            return False
        return self.evidence <= -threshold

    def holds(self, threshold: float) -> bool:
        """Whether the old place still stands against the estimate (away, recent evidence below ``threshold``)."""
        return self.away and self.evidence < threshold

    def _set(self, pose: np.ndarray, odom: np.ndarray) -> None:
        self.pose, self.odom, self.away, self.evidence, self.through = pose.copy(), odom.copy(), False, 0.0, 0.0
