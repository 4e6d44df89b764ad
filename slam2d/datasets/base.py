"""What every reader shares: the ScanSource interface, the checks on scans, and the registry of readers."""

from __future__ import annotations

import itertools
import logging
import math
from collections import Counter, deque
from collections.abc import Iterator
from typing import Protocol

import numpy as np

from slam2d.errors import InputError
from slam2d.registry import Registry
from slam2d.types import Scan

log = logging.getLogger(__name__)

LOOKAHEAD = 16  # following scans whose stamps and poses outvote a scan that disagrees with them
MAX_COORD = 1e6  # m; a pose farther from the origin is absurd
MAX_SPEED = 50.0  # m/s; odometry moving faster between two scans has jumped ...
MAX_STEP = 10.0  # m; ... by more than this

BAD_STAMP = "scans with a non-finite timestamp"
BAD_POSE = "scans with a non-finite or absurd pose (beyond 1000 km)"
BAD_ANGLES = "scans with non-finite beam angles"
EARLY = "scans stamped before the scan kept before them"
LATE = "scans stamped after most of the scans that follow them"
JUMP = "scans whose odometry jumps away from the scans around them"
EMPTY = "empty scans (no valid beam)"
BAD_LIMITS = "scans with bad range limits (range_min not below range_max)"


def _with_followers(scans: Iterator[Scan], k: int) -> Iterator[tuple[Scan, list[Scan]]]:
    """Each scan with the plausible ones among the ``k`` scans that follow it."""
    window: deque[tuple[Scan, bool]] = deque()
    for scan in scans:
        window.append((scan, _plausible(scan)))
        if len(window) > k:
            yield window.popleft()[0], [s for s, ok in window if ok]
    while window:
        yield window.popleft()[0], [s for s, ok in window if ok]


def _poses_ok(scan: Scan) -> bool:
    """Finite odometry and mounting poses within MAX_COORD of the origin."""
    return bool(np.abs(scan.odom).max() < MAX_COORD and np.abs(scan.sensor_pose).max() < MAX_COORD)


def _plausible(scan: Scan) -> bool:
    """Finite stamp, finite angles and finite poses within MAX_COORD of the origin."""
    return math.isfinite(scan.stamp) and _poses_ok(scan) and bool(np.isfinite(scan.angles).all())


def _jumped_from(scan: Scan, other: Scan) -> bool:
    """Whether ``scan``'s odometry is farther from ``other``'s than a robot drives."""
    dist = math.hypot(scan.odom[0] - other.odom[0], scan.odom[1] - other.odom[1])
    return dist > MAX_STEP + MAX_SPEED * abs(scan.stamp - other.stamp)


def _jumped(scan: Scan, others: list[Scan]) -> np.ndarray:
    """Per scan in ``others``: whether ``scan``'s odometry is farther from it than a robot drives."""
    odom = np.array([s.odom for s in others], dtype=np.float64).reshape(-1, 3)
    dt = np.abs(np.array([s.stamp for s in others], dtype=np.float64) - scan.stamp)
    return np.hypot(*(odom[:, :2] - np.asarray(scan.odom)[:2]).T) > MAX_STEP + MAX_SPEED * dt


def _outvoted(flags: np.ndarray) -> bool:
    """More than half of the votes are against."""
    return 2 * int(np.count_nonzero(flags)) > len(flags)


def _stamp_or_pose_problem(scan: Scan, last: Scan | None, followers: list[Scan]) -> str | None:
    """Why ``scan`` cannot be used, judged against the last kept scan and the plausible scans after it."""
    if not math.isfinite(scan.stamp):
        return BAD_STAMP
    if not _poses_ok(scan):
        return BAD_POSE
    if not np.isfinite(scan.angles).all():
        return BAD_ANGLES
    if last is not None and scan.stamp < last.stamp:
        return EARLY
    if followers and _outvoted(np.array([s.stamp for s in followers]) < scan.stamp):
        return LATE
    if (last is not None and _jumped_from(scan, last)) or (followers and _outvoted(_jumped(scan, followers))):
        return JUMP
    return None


class ScanSource:
    """A stream of :class:`Scan` with a name, an expected length and skip counts.

    Subclasses implement :meth:`_raw_scans`; iteration passes every scan through
    :meth:`_checked`, which replaces invalid ranges with NaN (counted in
    ``self.invalid_beams``) and skips empty scans and scans whose stamp, angles
    or pose are invalid or disagree with the scans around them, counting each
    reason in ``self.skipped``. A stamp or odometry pose that disagrees with
    most of the next LOOKAHEAD scans is the outlier, not the new reference.
    When more than ``max_skipped`` (a fraction of the scans expected) is skipped,
    iteration stops with an :class:`InputError`. Iteration starts at raw scan
    ``first_scan`` (a window of a log); ``len(self)`` counts the scans before it too.
    """

    name: str = "scans"
    max_skipped: float = 0.05
    first_scan: int = 0

    def __init__(self) -> None:
        self.skipped: Counter[str] = Counter()
        self.invalid_beams = 0

    def __len__(self) -> int:
        """Number of scans the source expects to yield (before skips)."""
        raise NotImplementedError

    @property
    def where(self) -> str:
        """The file (or name) errors are reported against."""
        return str(getattr(self, "path", self.name))

    def _raw_scans(self) -> Iterator[Scan]:
        raise NotImplementedError

    def __iter__(self) -> Iterator[Scan]:
        self.skipped = Counter()
        self.invalid_beams = 0
        raw = self._raw_scans()
        if self.first_scan:
            raw = itertools.islice(raw, self.first_scan, None)
        yield from self._checked(raw)
        self.log_skips()

    def expected(self) -> int:
        """Scans this iteration expects to yield (before skips): ``len(self)`` from ``first_scan`` on."""
        return max(len(self) - self.first_scan, 0)

    def skip(self, reason: str) -> None:
        """Count one unusable scan; an InputError once more than ``max_skipped`` of the input is lost."""
        self.skipped[reason] += 1
        n, total = sum(self.skipped.values()), max(self.expected(), 1)
        if n > self.max_skipped * total:
            reasons = ", ".join(f"{count} {what}" for what, count in sorted(self.skipped.items()))
            raise InputError(self.where, f"{n} of {total} scans ({percent(n / total)}) unusable ({reasons}); "
                             f"more than the {percent(self.max_skipped)} allowed (dataset.max_skipped)")

    def _checked(self, scans: Iterator[Scan]) -> Iterator[Scan]:
        last = None
        index = 0
        for scan, followers in _with_followers(scans, LOOKAHEAD):
            ranges = np.asarray(scan.ranges, dtype=np.float64)
            with np.errstate(invalid="ignore"):
                bad = ~np.isfinite(ranges) | (ranges < 0)
            n_bad = int(bad.sum())
            if n_bad:
                self.invalid_beams += n_bad
                ranges = np.where(bad, np.nan, ranges)
            problem = _stamp_or_pose_problem(scan, last, followers)
            if problem is None and not scan.range_min < scan.range_max:
                problem = BAD_LIMITS
            if problem is None and not np.any(~bad & (ranges >= scan.range_min) & (ranges < scan.range_max)):
                problem = EMPTY
            if problem is not None:
                self.skip(problem)
                continue
            last = scan
            yield Scan(
                stamp=float(scan.stamp),
                ranges=ranges,
                angles=np.asarray(scan.angles, dtype=np.float64),
                range_min=float(scan.range_min),
                range_max=float(scan.range_max),
                sensor_pose=np.asarray(scan.sensor_pose, dtype=np.float64),
                odom=np.asarray(scan.odom, dtype=np.float64),
                ground_truth=None if scan.ground_truth is None else np.asarray(scan.ground_truth, float),
                index=index,
            )
            index += 1

    def log_skips(self) -> None:
        """Log one line per skip reason with its count, the fraction skipped, and the invalid-beam count."""
        for reason, count in sorted(self.skipped.items()):
            log.warning("%s: skipped %d %s", self.name, count, reason)
        n = sum(self.skipped.values())
        if n:
            log.warning("%s: %d of %d scans (%s) skipped", self.where, n, self.expected(),
                        percent(n / max(self.expected(), 1)))
        if self.invalid_beams:
            log.info("%s: %d beams had no valid range (NaN, inf or negative) and were ignored", self.name, self.invalid_beams)


def percent(share: float) -> str:
    """``share`` (a fraction) as a percentage with one decimal: ``"5.3 %"``."""
    return f"{100 * share:.1f} %"


class DatasetReader(Protocol):
    """Opens the scan stream of a dataset config (its ``kind`` names the reader)."""

    def __call__(self, cfg, seed: int) -> ScanSource:
        """The :class:`ScanSource` of ``cfg`` (a :class:`slam2d.config.DatasetConfig`), seeded by ``seed``."""
        ...


DATASETS = Registry("datasets", "dataset kind", key="dataset.kind", builtins={
    "simulator": "slam2d.datasets.simulator",
    "rosbag": "slam2d.datasets.rosbag",
    "carmen": "slam2d.datasets.carmen",
})
"""The readers by name (``dataset.kind``)."""


def register_dataset(name: str, **kw):
    """Decorator of a :class:`DatasetReader`: ``dataset.kind: name`` opens with it."""
    return DATASETS.register(name, **kw)
