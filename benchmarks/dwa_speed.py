"""DWA speed of two source trees on the same calls: median ms a call, the new ÷ old ratio, and how many
commands differ.

Usage: .venv/bin/python benchmarks/dwa_speed.py OLD_TREE NEW_TREE [--pairs N] [--people P] [--repeat R]

The calls are recorded once, with the installed slam2d, along the navigation benchmark's first N office
pairs (P people walking, the true pose); each tree (a checkout, e.g. ``git worktree add /tmp/old
<commit>``) then replays every call in a process of its own, the trees taking turns R times.
"""

from __future__ import annotations

import argparse
import json
import os
import pickle
import statistics
import subprocess
import sys
import tempfile

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

REPLAY = """
import json, pickle, sys, time
sys.path.insert(0, sys.argv[1])
import numpy as np
from slam2d.navigation.dwa import DynamicWindow
calls = pickle.load(open(sys.argv[2], "rb"))
dwa, ms, out = DynamicWindow(), [], []
for c in calls:
    t = time.perf_counter(); cmd = dwa.command(*c); ms.append(1e3 * (time.perf_counter() - t))
    out.append((cmd.v, cmd.w, cmd.state))
print(json.dumps({"ms": float(np.median(ms)), "commands": out}))
"""


def record(pairs: int, people: int, planner: str = "dwa") -> list[list[tuple]]:
    """Every call's arguments (pose, velocity, points, path, unmapped) to the local planner ``planner``
    ("dwa" or "teb") along the office runs it drives (a list per run)."""
    from navigation import pairs as draw_pairs

    from slam2d import config
    from slam2d.navigation import dwa, teb
    from slam2d.runs.navigate import simulate

    cls = {"dwa": dwa.DynamicWindow, "teb": teb.TimedElasticBand}[planner]
    runs, command = [], cls.command

    def recording(self, pose, velocity, points, path, unmapped=None):
        runs[-1].append(tuple(None if a is None else np.array(a) for a in (pose, velocity, points, path, unmapped)))
        return command(self, pose, velocity, points, path, unmapped)

    cls.command = recording
    try:
        for k, (start, goal) in enumerate(draw_pairs("office", pairs, np.random.default_rng(0))):
            runs.append([])
            simulate(config.load(None, {"seed": k, "navigation.start": start.tolist(), "navigation.goal": goal.tolist(),
                                        "navigation.planner": planner, "navigation.people": people,
                                        "navigation.slam": False}))  # fmt: skip
    finally:
        cls.command = command
    return runs


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("old")
    ap.add_argument("new")
    ap.add_argument("--pairs", type=int, default=3)
    ap.add_argument("--people", type=int, default=5)
    ap.add_argument("--repeat", type=int, default=3)
    a = ap.parse_args()
    calls = [c for run in record(a.pairs, a.people) for c in run]
    with tempfile.NamedTemporaryFile(suffix=".pkl") as f:
        pickle.dump(calls, f)
        f.flush()
        runs = {a.old: [], a.new: []}
        for _ in range(a.repeat):
            for tree in runs:
                out = subprocess.run([sys.executable, "-c", REPLAY, os.path.abspath(tree), f.name],
                                     capture_output=True, text=True, check=True)  # fmt: skip
                runs[tree].append(json.loads(out.stdout.strip().splitlines()[-1]))
                print(f"  {tree}: {runs[tree][-1]['ms']:.2f} ms a call", file=sys.stderr, flush=True)
    old, new = (statistics.median(r["ms"] for r in runs[t]) for t in (a.old, a.new))
    differ = sum(x != y for x, y in zip(runs[a.old][0]["commands"], runs[a.new][0]["commands"]))
    print(f"{len(calls)} calls: old {old:.2f} ms, new {new:.2f} ms a call (medians); new ÷ old {new / old:.2f}; "
          f"{differ} commands differ")


if __name__ == "__main__":
    main()
