"""``slam2d explore``: an exploration run (:func:`slam2d.exploration.loop.explore`) written as a results folder.

The folder holds the resolved config, the final map (PGM + YAML, PNG with the path and the hybrid
graph), the hybrid map (``hybrid.json``), the true and estimated trajectories, coverage against time
and distance (``coverage.csv``, ``coverage.png``), the map's wall-to-wall spans against the plan
(``spans.csv``), ``explore.gif`` and ``metrics.json``.
"""

from __future__ import annotations

import json
import logging
from pathlib import Path

import numpy as np

from slam2d import config as config_mod
from slam2d.evaluation.trajectory import align_se2, write_tum
from slam2d.exploration.config import ExploreConfig
from slam2d.exploration.loop import ExplorationRun, explore, resolved
from slam2d.mapping.export import save_map_server
from slam2d.runs.results import json_text, live_view, progress_bar, results_folder
from slam2d.runs.slam_outputs import write_map_accuracy
from slam2d.types import Trajectory

log = logging.getLogger(__name__)


GIF_FRAMES = 80


def run_explore(cfg: ExploreConfig, quiet: bool = False, viz: str | Path | None = None) -> Path:
    """Run ``cfg``'s exploration; return the results folder. ``viz``: ``"viewer"`` or ``FILE.rrd``, the
    robot, goals, map and frontiers streamed to rerun (:class:`slam2d.viz.ExploreView`)."""
    cfg = resolved(cfg)
    with results_folder(cfg.output.root, cfg.name) as (work, published):
        log.info("slam2d explore '%s' (%s) -> %s", cfg.name, cfg.exploration.strategy, cfg.output.root)
        (work / "config.yaml").write_text(config_mod.dump(cfg))
        with live_view(viz, cfg.name, "explore", cfg.mapping) as view, \
                progress_bar("exploring (simulated s)", cfg.exploration.max_time, quiet) as advance:
            run = explore(cfg, lambda now, coverage: advance(now, f"coverage {100 * coverage:.0f} %"), view)
        _write(work, cfg, run)
        run.metrics["map_accuracy"] = write_map_accuracy(work, run.world, cfg.seed,
                                                         align_se2(run.estimate, run.truth), run.grid)["grid"]
        (work / "metrics.json").write_text(json_text(run.metrics))
        m = run.metrics
        log.info("%s: coverage %.1f %% in %.0f s, %.1f m (%.0f s wall)", m["stop_reason"], 100 * m["coverage"],
                 m["time"], m["distance"], m["wall_s"])  # fmt: skip
    return published[0]


def _write(out: Path, cfg: ExploreConfig, run: ExplorationRun) -> None:
    save_map_server(run.grid, out / "map", cfg.mapping)
    write_tum(out / "ground_truth.tum", Trajectory(run.stamps, run.truth))
    write_tum(out / "trajectory.tum", Trajectory(run.stamps, run.estimate))
    run.explorer.hybrid.save(out / "hybrid.json")
    (out / "goals.json").write_text(json.dumps(run.goals, indent=1))
    np.savetxt(out / "coverage.csv", run.curve, delimiter=",", header="time_s,distance_m,coverage", comments="",
               fmt="%.4f")  # fmt: skip
    if cfg.output.figures:
        _figures(out, run)
        if cfg.exploration.animation and run.snapshots:
            _animation(out, run)


def _figures(out: Path, run: ExplorationRun) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    m = run.metrics
    fig, ax = plt.subplots(figsize=(9, 6))
    x0, x1, y0, y1 = run.grid.extent
    ax.imshow(1.0 - run.grid.probability(), cmap="gray", origin="lower", extent=(x0, x1, y0, y1), vmin=0, vmax=1)
    ax.plot(*run.truth[:, :2].T, color="tab:blue", lw=0.9, label="path (true)")
    run.explorer.hybrid.draw(ax)
    ax.plot(*run.truth[0, :2], "g^", ms=9, label="start")
    ax.set_aspect("equal")
    ax.set_title(f"{m['world']} · {m['strategy']}: coverage {100 * m['coverage']:.1f} %, {m['distance']:.0f} m, "
                 f"{m['time']:.0f} s, IoU {m['map_iou']:.3f}", fontsize=9)  # fmt: skip
    ax.legend(loc="upper right", fontsize=7)
    fig.savefig(out / "map.png", dpi=130, bbox_inches="tight")
    plt.close(fig)
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(9, 3.2), sharey=True)
    a1.plot(run.curve[:, 0], 100 * run.curve[:, 2])
    a1.set_xlabel("time (s)")
    a1.set_ylabel("coverage (%)")
    a2.plot(run.curve[:, 1], 100 * run.curve[:, 2])
    a2.set_xlabel("distance (m)")
    for a in (a1, a2):
        a.axhline(99, color="0.6", lw=0.7, ls="--")
        a.grid(alpha=0.3)
    fig.savefig(out / "coverage.png", dpi=120, bbox_inches="tight")
    plt.close(fig)


def _animation(out: Path, run: ExplorationRun) -> None:
    """explore.gif: the map being built, the path, the nodes and the goal."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.animation import FuncAnimation, PillowWriter

    snaps = run.snapshots
    frames = np.unique(np.linspace(0, len(snaps) - 1, min(GIF_FRAMES, len(snaps))).astype(int))
    fig, ax = plt.subplots(figsize=(6, 4.5))
    x0, x1, y0, y1 = run.grid.extent

    def draw(k):
        s = snaps[k]
        ax.clear()
        ax.imshow(s["image"], cmap="gray", origin="lower", extent=s["extent"], vmin=0, vmax=255)
        ax.plot(*run.truth[: s["n"], :2].T, color="tab:blue", lw=0.9)
        ax.plot(*s["nodes"].T, ".", color="tab:purple", ms=3)
        if s["goal"] is not None:
            ax.plot(*s["goal"], "r*", ms=9)
        ax.set_xlim(x0, x1)
        ax.set_ylim(y0, y1)
        ax.set_aspect("equal")
        ax.set_title(f"t = {run.stamps[s['n'] - 1] - run.stamps[0]:.0f} s", fontsize=9)

    FuncAnimation(fig, draw, frames=frames, blit=False).save(out / "explore.gif", writer=PillowWriter(fps=8))
    plt.close(fig)
