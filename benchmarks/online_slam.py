"""Online SLAM on the simulator default: per-scan cost of ``add`` and of the live grid.

Feeds the default simulator stream (1405 scans) to ``OnlineSlam`` one scan at a
time and times (wall clock) every ``add``, the grid work inside it, and a
``grid`` read after every scan. After every scan whose keyframe added loop
closures that moved keyframes beyond the tolerance, the re-render (the grid
update inside that ``add``) is set beside a full ``build_grid`` of all scans so
far at the current estimates; the same after ``finish()``. The batch pipeline
(``parallel=false``) on the same stream gives the reference total (both after
a 20-scan warm-up that loads the compiled code). Prints
Markdown tables.

    nice .venv/bin/python benchmarks/online_slam.py [--scans N] [--tolerance M]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from slam2d import config
from slam2d.datasets.registry import open_dataset
from slam2d.mapping.occupancy import build_grid
from slam2d.pipeline import SlamPipeline
from slam2d.slam import OnlineSlam


def timed(fn, *args):
    """(result, wall seconds) of ``fn(*args)``."""
    t0 = time.perf_counter()
    out = fn(*args)
    return out, time.perf_counter() - t0


class GridClock:
    """Wraps ``online.update_grid`` to record the wall time of each call, s."""

    def __init__(self, online: OnlineSlam):
        self.seconds: list[float] = []
        self._update = online.update_grid
        online.update_grid = self

    def __call__(self, *args, **kwargs):
        out, dt = timed(lambda: self._update(*args, **kwargs))
        self.seconds.append(dt)
        return out

    def take(self) -> float:
        """Seconds recorded since the last take."""
        total, self.seconds = sum(self.seconds), []
        return total


def run_online(cfg, tolerance):
    """Per-scan timings and loop events (re-render s, build_grid s, keyframes re-traced, keyframes)."""
    online = OnlineSlam(cfg, tolerance)
    clock = GridClock(online)
    add_s, grid_in_add_s, read_s, events = [], [], [], []
    t0 = time.perf_counter()
    for scan in open_dataset(cfg.dataset, seed=cfg.seed):
        loops = online.backend.stats["loop closures added"]
        _, dt = timed(online.add, scan)
        add_s.append(dt)
        grid_in_add_s.append(clock.take())
        update = online.map.last
        if online.backend.stats["loop closures added"] > loops and update.replaced > 0:
            _, rebuild = timed(build_grid, online.poses, online.scans, cfg.mapping)
            events.append((grid_in_add_s[-1], rebuild, update.replaced, online.map.num_keyframes))
        read_s.append(timed(lambda: online.grid)[1])
        clock.take()
    poses, finish_s = timed(online.finish)
    total = time.perf_counter() - t0 - sum(read_s) - sum(e[1] for e in events)
    _, final_render = timed(lambda: online.grid)
    final = (final_render, timed(build_grid, poses, online.scans, cfg.mapping)[1], online.map.last.replaced)
    return online, np.array(add_s), np.array(grid_in_add_s), np.array(read_s), np.array(events), final, total


def warm_up(cfg) -> None:
    """Load the compiled (numba) code and the frontend's first allocations before timing."""
    online = OnlineSlam(cfg.model_copy(update={"dataset": cfg.dataset.model_copy(update={"max_scans": 20})}))
    for scan in open_dataset(online.cfg.dataset, seed=cfg.seed):
        online.add(scan)
        _ = online.grid
    online.finish()
    _ = online.grid


def stats_row(name: str, values_s: np.ndarray) -> str:
    ms = 1e3 * values_s
    return f"| {name} | {np.median(ms):.2f} | {np.percentile(ms, 95):.2f} | {ms.max():.1f} |"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scans", type=int, default=None, help="first N scans (default: all)")
    ap.add_argument("--tolerance", type=float, default=None, help="re-placement tolerance, m (default: a quarter cell)")
    args = ap.parse_args()
    overrides = ["parallel=false"] + ([f"dataset.max_scans={args.scans}"] if args.scans else [])
    cfg = config.load(None, overrides)
    warm_up(cfg)
    batch = timed(lambda: SlamPipeline(cfg).run(open_dataset(cfg.dataset, seed=cfg.seed)))[1]
    online, add_s, grid_s, read_s, events, final, total = run_online(cfg, args.tolerance)
    print(f"{len(add_s)} scans, {online.map.num_keyframes} keyframes, tolerance {online.map.tolerance * 100:.2f} cm, "
          f"{len(events)} loop closures that moved keyframes\n")
    print("| per call (ms) | median | p95 | max |\n|---|---:|---:|---:|")
    print(stats_row("`add` (frontend + back end + grid)", add_s))
    print(stats_row("grid work inside `add`", grid_s))
    print(stats_row("`grid` read (copy + open keyframe)", read_s))
    if len(events):
        print(stats_row("re-render after a loop closure", events[:, 0]))
        print(stats_row("full `build_grid` at the same moments", events[:, 1]))
        ratio = events[:, 0] / events[:, 1]
        print(f"| re-render / `build_grid` (%) | {100 * np.median(ratio):.1f} | {100 * np.percentile(ratio, 95):.1f} | "
              f"{100 * ratio.max():.1f} |")
        share = events[:, 2] / events[:, 3]
        print(f"| keyframes re-traced per re-render (%) | {100 * np.median(share):.1f} | "
              f"{100 * np.percentile(share, 95):.1f} | {100 * share.max():.1f} |")
    print(f"\nAfter `finish()`: re-render {1e3 * final[0]:.1f} ms ({final[2]} keyframes re-traced) vs "
          f"`build_grid` {1e3 * final[1]:.1f} ms. Session {total:.2f} s (grid {grid_s.sum():.2f} s) vs batch "
          f"pipeline {batch:.2f} s; grid memory (patches, beams, grid) {online.map.nbytes / 1e6:.0f} MB.")


if __name__ == "__main__":
    main()
