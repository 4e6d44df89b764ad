"""Where a run drives twice: the path driven again (the path repetition metric's samples) goal by goal.

Usage:
  nice .venv/bin/python benchmarks/exploration_repeats.py WORLD [--strategy tour] [--seed 0] [--max-time 1500]
        [--min 0.0]

Runs one exploration with the benchmark's config (``benchmarks/exploration.py``'s ``one_run``) and prints, for each
goal, when it was set, its kind and outcome, the metres driven towards it and of those the metres driven again
(within ``REPEAT_RADIUS`` of earlier path, as ``path_repetition`` counts them) before and after 99 % coverage; for
the ``tour``, the decision's first subspace: its frontier cells, the robot's path to it (m), whether it was begun.
``--min`` m: only the goals with at least that much driven again before 99 %. Last, the metres driven again before
99 %, in all and on subspaces holding fewer frontier cells than a region's least (the robot's width).
"""

from __future__ import annotations

import argparse

import numpy as np


def trace(world: str, strategy: str, seed: int, max_time: float):
    """The run and, for each decision with a goal, the tour's first subspace (key, frontier cells, path m, begun)
    or None."""
    from slam2d.exploration import config
    from slam2d.exploration import tour as T
    from slam2d.exploration.loop import explore

    firsts, seen = [], {}
    subspaces, order = T._subspaces, T.TourPlanner._global_order

    def _subspaces(view, found, cell, distance):
        out = subspaces(view, found, cell, distance)
        seen["cells"] = dict(zip(out[0], (len(m) for m in out[3])))
        return out

    def _global_order(self, keys, cost, solver_ms, horizon):
        out = order(self, keys, cost, solver_ms, horizon)
        k = keys[out[0]]
        seen["first"] = k, seen["cells"][k], float(cost[0, out[0] + 1]), k in self.begun
        return out

    choose = T.TourPlanner.choose

    def chosen(self, explorer, pose, view, distance):
        seen.clear()
        goal = choose(self, explorer, pose, view, distance)
        seen["goal"] = goal
        return goal

    from slam2d.exploration import explorer as E

    decide = E.Explorer.decide

    def decided(self, pose, view):
        seen.clear()
        goal = decide(self, pose, view)
        if goal is not None:
            firsts.append((goal.position.copy(), seen.get("first") if seen.get("goal") is goal else None))
        return goal

    T._subspaces, T.TourPlanner._global_order, T.TourPlanner.choose, E.Explorer.decide = (
        _subspaces, _global_order, chosen, decided)  # fmt: skip
    cfg = config.load(None, {"dataset.simulator.world": world, "seed": seed, "exploration.strategy": strategy,
                             "exploration.max_time": max_time, "exploration.animation": False})  # fmt: skip
    run = explore(cfg)
    firsts = firsts[len(firsts) - len(run.goals) :]  # the warm-up's throwaway decisions left out
    return run, [f for _, f in firsts]


def main() -> None:
    from slam2d.exploration.coverage import SAMPLE_STEP, repeated_path

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("world")
    ap.add_argument("--strategy", default="tour")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--max-time", type=float, default=1500.0)
    ap.add_argument("--min", type=float, default=0.0)
    a = ap.parse_args()
    run, firsts = trace(a.world, a.strategy, a.seed, a.max_time)
    m = run.metrics
    xy, t = run.truth[:, :2], run.stamps - run.stamps[0]
    at, again = repeated_path(xy)
    s = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(xy, axis=0).T))])
    when = np.interp(at, s, t)  # each sample's time (s)
    before = at <= m["distance_to_99"]
    starts = [g["time"] for g in run.goals] + [np.inf]
    small = int(np.ceil(run.explorer.min_frontier / run.grid.resolution))
    total = scraps = 0.0
    print(f"{m['world']} {a.strategy} seed {a.seed}: {m['distance']:.1f} m, to 90 / 99 % {m['distance_to_90']:.1f} / "
          f"{m['distance_to_99']:.1f} m, path repetition {m['path_repetition']:.3f}")  # fmt: skip
    print("goal | time (s) | kind | outcome | at (x, y) m | driven (m) | again before / after 99 % (m) | first subspace")
    for k, (g, first) in enumerate(zip(run.goals, firsts)):
        mine = (when >= starts[k]) & (when < starts[k + 1])
        pre, post = SAMPLE_STEP * np.sum(mine & again & before), SAMPLE_STEP * np.sum(mine & again & ~before)
        total += pre
        if first is not None and first[1] < small:
            scraps += pre
        if pre < a.min:
            continue
        sub = "" if first is None else f"{first[0]}: {first[1]} cells, {first[2]:.1f} m{', begun' if first[3] else ''}"
        print(f"{k} | {g['time']:.1f} | {g['kind']} | {g['outcome']} | ({g['position'][0]:.1f}, {g['position'][1]:.1f}) | "
              f"{SAMPLE_STEP * mine.sum():.1f} | {pre:.1f} / {post:.1f} | {sub}")  # fmt: skip
    print(f"driven again before 99 %: {total:.1f} m; on subspaces of fewer than {small} frontier cells: {scraps:.1f} m")


if __name__ == "__main__":
    main()
