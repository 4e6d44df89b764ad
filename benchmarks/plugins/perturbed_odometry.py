"""Plugin for benchmarks/slam_perturbed.py: wheel odometry that freezes, jumps and takes wild steps.

Importing it makes every scan source hand its scans' odometry through :func:`perturb` before the
source's own checks. The odometry's increments (each scan's motion in the previous scan's frame)
are replayed with three kinds of fault, drawn at random per scan (``SLAM2D_PERTURB_SEED``, default 0;
rates per scan from ``SLAM2D_PERTURB_RATES`` = ``freeze,jump,wild``, default ``0.002,0.001,0.002``):

- **freeze**: the odometry stops for 10–40 scans while the robot moves, then catches up in one step
  (an encoder or driver stall);
- **jump**: the pose is displaced once by 0.2–1.0 m in a random direction and 5–30° and goes on
  from there (a re-initialised odometry);
- **wild step**: one increment is multiplied by 3–10 or reversed (a slip or a bad packet).

The counts of each fault go to stderr; they and each fault's kind and scan stamp go to
``SLAM2D_PERTURB_LOG`` (JSON) if set.
"""

from __future__ import annotations

import json
import os
import sys
from collections import Counter
from collections.abc import Iterator
from dataclasses import replace

import numpy as np

from slam2d import geometry
from slam2d.datasets.base import ScanSource
from slam2d.types import Scan

FREEZE_SCANS = (10, 40)  # scans a freeze lasts
JUMP_M = (0.2, 1.0)  # m, how far a jump displaces the pose
JUMP_DEG = (5.0, 30.0)  # deg, how far it turns it
WILD_FACTOR = (3.0, 10.0)  # a wild step's increment is multiplied by this (or by -1)


def perturb(scans: Iterator[Scan], rng: np.random.Generator, rates: tuple[float, float, float],
            counts: Counter, times: list | None = None) -> Iterator[Scan]:
    """``scans`` with their odometry replayed through freezes, jumps and wild steps (module docstring);
    ``counts`` gets the number of each fault, ``times`` (kind, scan stamp s) of each."""
    times = [] if times is None else times
    previous = perturbed = None
    frozen = 0  # scans of the current freeze still to come
    owed = np.zeros(3)  # motion a freeze has held back (in the pose's frame when it started)
    for scan in scans:
        odom = np.asarray(scan.odom, float)
        if previous is None:
            previous, perturbed = odom, odom.copy()
            yield scan
            continue
        step = geometry.between(previous, odom)
        previous = odom
        fault = rng.random(3) < np.asarray(rates)
        if frozen:
            owed = geometry.compose(owed, step)
            frozen -= 1
            step = owed if frozen == 0 else np.zeros(3)
        elif fault[0]:
            frozen = int(rng.integers(*FREEZE_SCANS))
            owed, step = step, np.zeros(3)
            counts["freeze"] += 1
            times.append(("freeze", scan.stamp))
        elif fault[2]:
            step = step * (-1.0 if rng.random() < 0.3 else rng.uniform(*WILD_FACTOR))
            counts["wild step"] += 1
            times.append(("wild step", scan.stamp))
        if fault[1] and not frozen:
            heading = rng.uniform(-np.pi, np.pi)
            distance = rng.uniform(*JUMP_M)
            turn = np.deg2rad(rng.uniform(*JUMP_DEG)) * rng.choice([-1.0, 1.0])
            step = geometry.compose(step, np.array([distance * np.cos(heading), distance * np.sin(heading), turn]))
            counts["jump"] += 1
            times.append(("jump", scan.stamp))
        perturbed = geometry.compose(perturbed, step)
        yield replace(scan, odom=perturbed.copy())


def _iter(self) -> Iterator[Scan]:
    """ScanSource.__iter__ with the odometry perturbed before the source's checks."""
    self.skipped = Counter()
    self.invalid_beams = 0
    rates = tuple(float(r) for r in os.environ.get("SLAM2D_PERTURB_RATES", "0.002,0.001,0.002").split(","))
    counts: Counter = Counter()
    times: list = []
    rng = np.random.default_rng(int(os.environ.get("SLAM2D_PERTURB_SEED", "0")))
    yield from self._checked(perturb(self._raw_scans(), rng, rates, counts, times))
    print(f"perturbed odometry of {self.where}: {dict(counts)}", file=sys.stderr)
    if os.environ.get("SLAM2D_PERTURB_LOG"):
        with open(os.environ["SLAM2D_PERTURB_LOG"], "w") as f:
            json.dump({**counts, "times": times}, f)
    self.log_skips()


ScanSource.__iter__ = _iter
