"""Exploration speed of two source trees on the same run: wall clock, decision median / p95, × real time.

Usage: .venv/bin/python benchmarks/exploration_speed.py OLD_TREE NEW_TREE [--world W] [--strategy S]
       [--max-time S] [--repeat N]

Each tree (a checkout of slam2d, e.g. ``git worktree add /tmp/old <commit>``) explores the same world
from seed 0's start for ``--max-time`` simulated seconds in a process of its own, the trees taking turns
``--repeat`` times; medians and the new ÷ old ratio are printed. The distance driven and the coverage
are printed too: code that is only faster gives the same run.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys

ONE_RUN = """
import json, sys, time
sys.path.insert(0, sys.argv[1])
from slam2d.exploration import config
from slam2d.exploration.loop import explore
cfg = config.load(None, {"dataset.simulator.world": sys.argv[2], "seed": 0, "exploration.strategy": sys.argv[3],
                         "exploration.max_time": float(sys.argv[4]), "exploration.animation": False})
t = time.perf_counter(); m = explore(cfg).metrics; wall = time.perf_counter() - t
print(json.dumps({"wall": wall, "decision_ms_median": m["decision_ms_median"], "decision_ms_p95": m["decision_ms_p95"],
                  "real_time_factor": m["real_time_factor"], "distance": m["distance"], "coverage": m["coverage"]}))
"""


def run(tree: str, a) -> dict:
    out = subprocess.run([sys.executable, "-c", ONE_RUN, os.path.abspath(tree), a.world, a.strategy, str(a.max_time)],
                         capture_output=True, text=True, check=True)  # fmt: skip
    return json.loads(out.stdout.strip().splitlines()[-1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("old")
    ap.add_argument("new")
    ap.add_argument("--world", default="office")
    ap.add_argument("--strategy", default="utility")
    ap.add_argument("--max-time", type=float, default=200.0)
    ap.add_argument("--repeat", type=int, default=2)
    a = ap.parse_args()
    runs = {a.old: [], a.new: []}
    for _ in range(a.repeat):
        for tree in runs:
            runs[tree].append(run(tree, a))
            print(f"  {tree}: {runs[tree][-1]}", file=sys.stderr, flush=True)
    med = {t: {k: statistics.median(r[k] for r in rs) for k in rs[0]} for t, rs in runs.items()}
    print("| tree | wall clock (s) | decision median (ms) | decision p95 (ms) | × real time | distance (m) | coverage |")
    print("|---|---|---|---|---|---|---|")
    for t, m in med.items():
        print(f"| {t} | {m['wall']:.1f} | {m['decision_ms_median']:.1f} | {m['decision_ms_p95']:.1f} | "
              f"{m['real_time_factor']:.2f} | {m['distance']:.2f} | {100 * m['coverage']:.2f} % |")  # fmt: skip
    o, n = med[a.old], med[a.new]
    print(f"\nnew ÷ old: wall clock {n['wall'] / o['wall']:.2f}, decision median "
          f"{n['decision_ms_median'] / o['decision_ms_median']:.2f}")  # fmt: skip


if __name__ == "__main__":
    main()
