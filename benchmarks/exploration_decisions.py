"""Decision time of exploration, decision by decision: wall clock and the thread's CPU time against the explored area.

Usage:
  .venv/bin/python benchmarks/exploration_decisions.py --tree TREE --label NAME --worlds W ... --strategies S ...
        [--max-time S] [--seed N] --log decisions.jsonl      # one closed-loop run per world and strategy
  .venv/bin/python benchmarks/exploration_decisions.py --table decisions.jsonl ...    # median / p95 per run
  .venv/bin/python benchmarks/exploration_decisions.py --figure out.png decisions.jsonl ...
  .venv/bin/python benchmarks/exploration_decisions.py --tree TREE --worlds W --strategies S --dump DIR --every K
  .venv/bin/python benchmarks/exploration_decisions.py --tree TREE --replay DIR   # its inputs decided again

Each run explores one world from the seed's start with the slam2d of ``TREE`` (a checkout, e.g.
``git worktree add /tmp/old <commit>``) in a process of its own, and records for every decision
(``Explorer.decide``) the wall clock and the CPU time of the deciding thread (``time.thread_time``: what
the decision itself cost, little changed by other jobs on the machine), the known area of the map (m²),
the grid's size, the kind of goal chosen, its position and score, and the CPU time of each upkeep of the
decisions' grids at the goal's checks between decisions (``Explorer.keep_up``, where the code has it) and of
each check itself (``Explorer.spent``), kept in the log (``upkeep``, ``checks``). The numba kernels and the strategy's libraries
are loaded before the run (as ``Explorer`` does at its first construction). The distance driven and the coverage
are logged too: code that is only faster drives the same route, and the table counts the decisions whose goal
and score equal, to the last bit, those of the first code logged for the same world and strategy.

``--dump`` saves the inputs (explorer, pose, map) of every K-th decision of one run (not timed) with the run's
goals; ``--replay`` decides on each again with the slam2d of ``TREE`` (a fresh copy each time: the map's changes
since that explorer's last decision included), prints its thread CPU and whether goal and score equal the run's.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys

import numpy as np

ONE_RUN = """
import json, sys, time
sys.path.insert(0, sys.argv[1])
import numpy as np
from slam2d.exploration import config
from slam2d.exploration import explorer as E
from slam2d.exploration.gridops import UNKNOWN
from slam2d.exploration.loop import explore
cfg = config.load(None, {"dataset.simulator.world": sys.argv[2], "seed": int(sys.argv[5]),
                         "exploration.strategy": sys.argv[3], "exploration.max_time": float(sys.argv[4]),
                         "exploration.animation": False})
E.Explorer(cfg.exploration, 0.2, 0.05, 12.0)  # loads the kernels (the first decision of a strategy in a process)
records, inner = [], E.Explorer.decide
def decide(self, pose, view):
    w, c = time.perf_counter(), time.thread_time()
    goal = inner(self, pose, view)
    c, w = time.thread_time() - c, time.perf_counter() - w
    known = float(np.count_nonzero(view.state != UNKNOWN) * view.resolution**2)
    records.append([round(1000 * w, 3), round(1000 * c, 3), round(known, 2), int(view.state.size),
                    None if goal is None else goal.kind,
                    None if goal is None else [*map(float, goal.position), float(goal.score)]])
    return goal
def dumped(self, pose, view):  # the inputs of every k-th decision saved (their time is not measured)
    if len(records) % every == every - 1:
        with open(f"{dump}/decision_{len(records)}.pkl", "wb") as f:
            cloudpickle.dump((self, pose, view), f)
    goal = inner(self, pose, view)
    records.append([None, None, None, int(view.state.size), None if goal is None else goal.kind,
                    None if goal is None else [*map(float, goal.position), float(goal.score)]])
    return goal
upkeep = []  # thread CPU (ms) of each upkeep of the decisions' grids between decisions, where the code has one
if hasattr(E.Explorer, "keep_up"):
    kept_up = E.Explorer.keep_up
    def keep_up(self, view):
        c = time.thread_time()
        kept_up(self, view)
        upkeep.append(round(1000 * (time.thread_time() - c), 3))
    E.Explorer.keep_up = keep_up
checks, check = [], E.Explorer.spent  # thread CPU (ms) of each check whether the goal is still worth reaching
def spent(self, goal, view):
    c = time.thread_time()
    out = check(self, goal, view)
    checks.append(round(1000 * (time.thread_time() - c), 3))
    return out
E.Explorer.spent = spent
dump, every = sys.argv[6], int(sys.argv[7])
if dump:
    import cloudpickle
E.Explorer.decide = dumped if dump else decide
m = explore(cfg).metrics
keep = ("world", "strategy", "seed", "coverage", "distance", "distance_to_90", "distance_to_99", "time", "wall_s",
        "decision_ms_median", "decision_ms_p95", "stop_reason", "collisions", "map_iou")
print(json.dumps({"metrics": {k: m[k] for k in keep}, "decisions": records, "upkeep": upkeep, "checks": checks}))
"""
REPLAY = """
import copy, json, pickle, sys, time
sys.path.insert(0, sys.argv[1])
from slam2d.exploration import explorer as E
for path in sys.argv[2:]:
    ex, pose, view = pickle.load(open(path, "rb"))
    E.Explorer(ex.cfg, ex.radius, ex.inflation, ex.range_max)  # the kernels loaded
    ms = []
    for _ in range(3):  # each on a fresh copy: the map's changes since the explorer's last decision included
        e, v = copy.deepcopy((ex, view))
        c = time.thread_time()
        goal = E.Explorer.decide(e, pose, v)
        ms.append(1000 * (time.thread_time() - c))
    print(json.dumps([path, min(ms), None if goal is None else [goal.kind, *map(float, goal.position), float(goal.score)]]))
"""
FIELDS = "wall_ms", "cpu_ms", "known_m2", "cells", "kind", "goal"  # goal: x, y (m), score


def run(tree: str, world: str, strategy: str, max_time: float, seed: int, dump: str = "", every: int = 0) -> dict:
    out = subprocess.run([sys.executable, "-c", ONE_RUN, os.path.abspath(tree), world, strategy, str(max_time),
                          str(seed), dump, str(every)], capture_output=True, text=True, check=False)  # fmt: skip
    if out.returncode:
        raise SystemExit(f"{world} / {strategy} failed:\n{out.stderr[-3000:]}")
    return json.loads(out.stdout.strip().splitlines()[-1])


def replay(tree: str, folder: str) -> None:
    """Decide again on a --dump folder's inputs with the slam2d of ``tree``: thread CPU (ms, least of 3) and whether
    goal and score equal the dumped run's, one line each, then how many did."""
    with open(os.path.join(folder, "run.json")) as f:
        goals = [d[4:6] for d in json.load(f)["decisions"]]
    inputs = sorted((int(n[9:-4]), os.path.join(folder, n)) for n in os.listdir(folder) if n.startswith("decision_"))
    out = subprocess.run([sys.executable, "-c", REPLAY, os.path.abspath(tree), *[p for _, p in inputs]],
                         capture_output=True, text=True, check=False)  # fmt: skip
    if out.returncode:
        raise SystemExit(out.stderr[-3000:])
    same = 0
    for (k, _), line in zip(inputs, out.stdout.strip().splitlines()):
        _, ms, goal = json.loads(line)
        ok = json.dumps(goals[k]) == json.dumps([None, None] if goal is None else [goal[0], goal[1:]])
        same += ok
        print(f"decision {k}: {ms:.1f} ms, {'the same goal and score' if ok else f'DIFFERENT: {goal} against {goals[k]}'}")
    print(f"{same} of {len(inputs)} the same")


def load(paths) -> list[dict]:
    return [json.loads(line) for p in paths for line in open(p) if line.strip()]


def stats(rec: dict) -> dict:
    d = np.array([r[:2] for r in rec["decisions"]], dtype=float).reshape(-1, 2)
    q = np.percentile(d, [50, 95], axis=0) if len(d) else np.full((2, 2), np.nan)
    return {"n": len(d), "wall_med": q[0, 0], "wall_p95": q[1, 0], "cpu_med": q[0, 1], "cpu_p95": q[1, 1]}


def same_goals(run: dict, first: dict) -> str:
    """How many of ``run``'s decisions chose the goal of ``first``'s decision of the same rank, bit for bit."""
    a, b = [d[4:6] for d in run["decisions"]], [d[4:6] for d in first["decisions"]]
    if any(len(d) < 6 for d in run["decisions"] + first["decisions"]):
        return "–"
    return f"{sum(json.dumps(x) == json.dumps(y) for x, y in zip(a, b))} / {max(len(a), len(b))}"


def table(runs: list[dict]) -> str:
    head = ("| world | strategy | code | decisions | CPU median / p95 (ms) | wall median / p95 (ms) | target "
            "(CPU ≤ 20 / 100) | same goals as the first code | upkeep between decisions: median / p95 (ms), count | "
            "distance to 99 % (m) | in all (m) | coverage | sim time (s) |")
    lines = [head, "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    first = {}
    for r in runs:
        first.setdefault((r["metrics"]["world"], r["metrics"]["strategy"]), r)
    for r in sorted(runs, key=lambda r: (r["metrics"]["world"], r["metrics"]["strategy"], r["label"])):
        m, s = r["metrics"], stats(r)
        same = same_goals(r, first[m["world"], m["strategy"]])
        up = r.get("upkeep") or []
        up = f"{np.median(up):.1f} / {np.percentile(up, 95):.1f}, {len(up)}" if up else "–"
        met = "met" if s["cpu_med"] <= 20 and s["cpu_p95"] <= 100 else "**not met**"
        d99 = "–" if m["distance_to_99"] is None or not np.isfinite(m["distance_to_99"]) else f"{m['distance_to_99']:.1f}"
        lines.append(f"| {m['world']} | {m['strategy']} | {r['label']} | {s['n']} | {s['cpu_med']:.1f} / "
                     f"{s['cpu_p95']:.1f} | {s['wall_med']:.1f} / {s['wall_p95']:.1f} | {met} | {same} | {up} | {d99} | "
                     f"{m['distance']:.1f} | {100 * m['coverage']:.2f} % | {m['time']:.0f} |")  # fmt: skip
    return "\n".join(lines)


def figure(runs: list[dict], path: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    labels = list(dict.fromkeys(r["label"] for r in runs))  # in the order of the logs
    strategies = sorted({r["metrics"]["strategy"] for r in runs})
    worlds = sorted({r["metrics"]["world"] for r in runs})
    fig, axes = plt.subplots(len(labels), len(strategies), figsize=(4.2 * len(strategies), 3.4 * len(labels)),
                             sharex=True, sharey=True, squeeze=False)  # fmt: skip
    colours = dict(zip(worlds, plt.cm.tab10.colors))
    for i, label in enumerate(labels):
        for j, strategy in enumerate(strategies):
            ax = axes[i, j]
            for r in runs:
                if r["label"] != label or r["metrics"]["strategy"] != strategy or not r["decisions"]:
                    continue
                d = np.array([x[:3] for x in r["decisions"]], dtype=float)
                ax.scatter(d[:, 2], np.maximum(d[:, 1], 0.05), s=6, color=colours[r["metrics"]["world"]],
                           label=r["metrics"]["world"])  # fmt: skip
            ax.axhline(20, color="k", lw=0.8, ls="--")
            ax.axhline(100, color="k", lw=0.8, ls=":")
            ax.set_yscale("log")
            ax.set_title(f"{strategy}: {label}", fontsize=9)
            if i == len(labels) - 1:
                ax.set_xlabel("known area of the map (m²)")
            if j == 0:
                ax.set_ylabel("decision, thread CPU (ms)")
    handles = {h.get_label(): h for ax in axes.flat for h in ax.collections}
    fig.legend(handles.values(), handles.keys(), loc="upper center", ncol=len(worlds), fontsize=8, markerscale=2)
    fig.tight_layout(rect=(0, 0, 1, 0.94))
    fig.savefig(path, dpi=110)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--tree", default=".")
    ap.add_argument("--label", default="new")
    ap.add_argument("--worlds", nargs="*", default=[])
    ap.add_argument("--strategies", nargs="*", default=["nearest_frontier", "utility", "tour"])
    ap.add_argument("--max-time", type=float, default=1500.0)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--log", default="decisions.jsonl")
    ap.add_argument("--table", nargs="*")
    ap.add_argument("--figure", nargs="+", metavar=("PNG", "LOG"))
    ap.add_argument("--dump", help="a folder: save the inputs of every K-th decision of the run (one world, strategy)")
    ap.add_argument("--every", type=int, default=3)
    ap.add_argument("--replay", help="a --dump folder: decide on its inputs again with --tree")
    a = ap.parse_args()
    if a.dump:
        os.makedirs(a.dump, exist_ok=True)
        rec = run(a.tree, a.worlds[0], a.strategies[0], a.max_time, a.seed, os.path.abspath(a.dump), a.every)
        with open(os.path.join(a.dump, "run.json"), "w") as f:
            json.dump(rec, f)
        return
    if a.replay:
        replay(a.tree, a.replay)
        return
    if a.table:
        print(table(load(a.table)))
        return
    if a.figure:
        figure(load(a.figure[1:]), a.figure[0])
        return
    for world in a.worlds:
        for strategy in a.strategies:
            rec = {"label": a.label, **run(a.tree, world, strategy, a.max_time, a.seed)}
            with open(a.log, "a") as f:
                f.write(json.dumps(rec) + "\n")
            print(table([rec]).splitlines()[-1], flush=True)


if __name__ == "__main__":
    main()
