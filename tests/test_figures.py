"""The figures of ``slam2d run`` and ``slam2d plan`` say what the metrics say: the estimate drawn above
the ground truth in map.png (both visible), path.png titled with the shortened path's length."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure
from PIL import Image

from slam2d import config
from slam2d.mapping import export
from slam2d.planning.config import PlanConfig
from slam2d.runs import plan as plan_mod
from slam2d.runs import run as run_mod


def test_estimate_drawn_above_ground_truth_which_shows_at_its_edges():
    poses = np.column_stack([np.linspace(0, 5, 20), np.zeros(20), np.zeros(20)])
    ax = Figure().add_subplot()
    est, odom, truth = export.draw_trajectories(ax, {"estimate": poses, "odometry": poses, "ground truth": poses})
    assert [line.get_label() for line in (est, odom, truth)] == ["estimate", "odometry", "ground truth"]
    assert est.get_zorder() > odom.get_zorder() > truth.get_zorder() >= 2  # above the map image
    assert est.get_zorder() < 5  # below the legend
    assert est.get_linewidth() < odom.get_linewidth() < truth.get_linewidth()


def test_run_map_png_puts_the_estimate_first(monkeypatch, tmp_path):
    drawn = []
    draw = export.draw_trajectories
    monkeypatch.setattr(export, "draw_trajectories", lambda ax, trajectories: drawn.append(list(trajectories))
                        or draw(ax, trajectories))
    cfg = config.load(None, ["dataset.max_scans=5", f"output.root={tmp_path}"])
    folder = run_mod.run_experiment(cfg, quiet=True)
    assert drawn == [["estimate", "odometry", "ground truth"]]
    assert (folder / "map.png").is_file()


def test_path_png_title_gives_the_shortened_length(monkeypatch, tmp_path):
    free = np.zeros((130, 255), bool)
    free[5:125, 5:125] = True
    free[5:125, 130:250] = True
    free[51:69, 125:130] = True
    Image.fromarray(np.where(free, 255, 0).astype(np.uint8)).save(tmp_path / "plan.png")
    titles = []
    plot = plan_mod._plot_path
    monkeypatch.setattr(plan_mod, "_plot_path", lambda *a: titles.append(plot(*a)))
    cfg = PlanConfig.model_validate({"map": str(tmp_path / "plan.png"), "planning": {"start": [1, 1], "goal": [11, 5]},
                                     "output": {"root": str(tmp_path)}})
    folder = plan_mod.run_plan(cfg)
    metrics = json.loads((folder / "metrics.json").read_text())
    assert metrics["length_m"] < metrics["grid_length_m"] - 0.01  # the shortcut is shorter than the grid path
    (title,) = titles
    assert title.startswith(f"{metrics['length_m']:.2f} m (grid path {metrics['grid_length_m']:.2f} m), ")
    assert Path(folder / "path.png").is_file()
    page = (folder / "report.html").read_text()
    assert 'alt="path.png"' in page and "the planned path" in page and "<th>length_m</th>" in page
