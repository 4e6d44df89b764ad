"""What every reader shares: the ScanSource interface and the checks on scans."""

from __future__ import annotations

import logging
from collections import Counter
from collections.abc import Iterator

import numpy as np

from slam2d.types import Scan

log = logging.getLogger(__name__)


class ScanSource:
    """A stream of :class:`Scan` with a name, an expected length and skip counts.

    Subclasses implement :meth:`_raw_scans`; iteration passes every scan through
    :meth:`_checked`, which replaces invalid ranges with NaN (counted in
    ``self.invalid_beams``) and skips empty or out-of-order scans, counting
    each reason in ``self.skipped``.
    """

    name: str = "scans"

    def __init__(self) -> None:
        self.skipped: Counter[str] = Counter()
        self.invalid_beams = 0

    def __len__(self) -> int:
        """Number of scans the source expects to yield (before skips)."""
        raise NotImplementedError

    def _raw_scans(self) -> Iterator[Scan]:
        raise NotImplementedError

    def __iter__(self) -> Iterator[Scan]:
        self.skipped = Counter()
        self.invalid_beams = 0
        yield from self._checked(self._raw_scans())
        self.log_skips()

    def _checked(self, scans: Iterator[Scan]) -> Iterator[Scan]:
        last_stamp = -np.inf
        index = 0
        for scan in scans:
            ranges = np.asarray(scan.ranges, dtype=np.float64)
            with np.errstate(invalid="ignore"):
                bad = ~np.isfinite(ranges) | (ranges < 0)
            n_bad = int(bad.sum())
            if n_bad:
                self.invalid_beams += n_bad
                ranges = np.where(bad, np.nan, ranges)
            if not np.isfinite(scan.stamp) or scan.stamp < last_stamp:
                self.skipped["scans with out-of-order or invalid timestamp"] += 1
                continue
            if not np.any(~bad & (ranges >= scan.range_min) & (ranges < scan.range_max)):
                self.skipped["empty scans (no valid beam)"] += 1
                continue
            last_stamp = scan.stamp
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
        """Log one line per skip reason with its count, and the invalid-beam count."""
        for reason, count in sorted(self.skipped.items()):
            log.warning("%s: skipped %d %s", self.name, count, reason)
        if self.invalid_beams:
            log.info("%s: %d beams had no valid range (NaN, inf or negative) and were ignored", self.name, self.invalid_beams)
