"""Time a call of the TEB and of the DWA on the same calls: median and 95th percentile ms, and TEB ÷ DWA.

Usage: .venv/bin/python benchmarks/teb_speed.py [--pairs N] [--people P] [--repeat R]

The calls (pose, velocity, laser points, path, unmapped) are recorded along the navigation benchmark's first
N office pairs driven by the TEB (P people walking, the true pose and the world's map); then both planners
answer every call in turn, in one process, R times (the TEB warm-started along its own runs, as recorded).
Wall-clock and process CPU time are both given: the wall clock counts whatever else the machine runs.
"""

from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

from dwa_speed import record


def main() -> None:
    from slam2d.navigation import DynamicWindow, TimedElasticBand

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--pairs", type=int, default=3)
    ap.add_argument("--people", type=int, default=5)
    ap.add_argument("--repeat", type=int, default=2)
    a = ap.parse_args()
    runs = record(a.pairs, a.people, "teb")
    ms = {"teb": {"wall": [], "cpu": []}, "dwa": {"wall": [], "cpu": []}}
    for _ in range(a.repeat):
        for calls in runs:
            planners = {"teb": TimedElasticBand(), "dwa": DynamicWindow()}
            for call in calls:
                for name, planner in planners.items():
                    wall, cpu = time.perf_counter(), time.process_time()
                    planner.command(*call)
                    ms[name]["wall"].append(1e3 * (time.perf_counter() - wall))
                    ms[name]["cpu"].append(1e3 * (time.process_time() - cpu))
    n = sum(len(c) for c in runs)
    print(f"{n} calls x {a.repeat} ({a.pairs} office runs, {a.people} people)")
    print("| planner | clock | median ms | p95 ms | Hz at the median | Hz at p95 |")
    print("|---|---|---|---|---|---|")
    for name in ms:
        for clock in ("wall", "cpu"):
            med, p95 = np.median(ms[name][clock]), np.percentile(ms[name][clock], 95)
            print(f"| {name} | {clock} | {med:.1f} | {p95:.1f} | {1e3 / med:.0f} | {1e3 / p95:.0f} |")
    for clock in ("wall", "cpu"):
        print(f"TEB ÷ DWA ({clock}): median {np.median(ms['teb'][clock]) / np.median(ms['dwa'][clock]):.1f}, "
              f"p95 {np.percentile(ms['teb'][clock], 95) / np.percentile(ms['dwa'][clock], 95):.1f}")


if __name__ == "__main__":
    main()
