"""Milliseconds per MCL update against the particle count (60 beams of a 360-beam scan, the office).

Usage: nice .venv/bin/python benchmarks/localization_speed.py [--counts 500 ... 20000] [--updates 40]

The particle count is held fixed (KLD's bounds equal) and every update resamples,
so each update is the whole cycle: odometry motion model, likelihood field over
particles x beams, low-variance resampling with KLD's bin count, clusters and the
pose estimate. The sensor model alone is timed too. Medians over the updates.
"""

from __future__ import annotations

import argparse
import sys
import time

import numpy as np


def main(argv: list[str]) -> None:
    from slam2d.localization import KnownMap, MclConfig, ParticleFilter
    from slam2d.localization.scenario import wander
    from slam2d.sim import World

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--counts", type=int, nargs="+", default=[500, 1000, 2000, 5000, 10000, 20000])
    ap.add_argument("--updates", type=int, default=40)
    ap.add_argument("--beams", type=int, default=60)
    args = ap.parse_args(argv)
    world = World.office()
    known = KnownMap.from_world(world)
    stream = wander(world, known, 30.0, seed=0)
    print("| particles | beams | ms per update (median) | sensor model ms | updates per s |")
    print("|---|---|---|---|---|")
    for n in args.counts:
        cfg = MclConfig(min_particles=n, max_particles=n, beams=args.beams, resample_ess=1.0, update_min_d=0.0,
                        update_min_a=0.0, global_candidates=1)  # fmt: skip
        pf = ParticleFilter(known, cfg, 12.0, seed=0)
        pf.init_pose(stream.truth[0])
        full, sensor = [], []
        for scan in stream.scans[: args.updates + 3]:
            t0 = time.perf_counter()
            pf.add(scan)
            full.append(time.perf_counter() - t0)
            t0 = time.perf_counter()
            pf.sensor.log_likelihood(pf.particles, scan)
            sensor.append(time.perf_counter() - t0)
        f, s = np.median(full[3:]) * 1000, np.median(sensor[3:]) * 1000  # first calls compile
        print(f"| {n} | {args.beams} | {f:.1f} | {s:.1f} | {1000 / f:.0f} |", flush=True)


if __name__ == "__main__":
    main(sys.argv[1:])
