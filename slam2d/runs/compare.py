"""``slam2d compare``: several results folders side by side, as evo's ``evo_res`` does for evo's results:
one table of their metrics, their trajectories overlaid and the distributions of their position errors.

A sweep folder stands for its variants' runs. The table's columns are the given metrics, or the main
metrics of every command (:data:`slam2d.runs.commands.COMMANDS`) that any of the runs has.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from slam2d import geometry
from slam2d.errors import InputError
from slam2d.evaluation.tables import flatten_metrics, to_markdown, write_table
from slam2d.evaluation.trajectory import align_se2, read_tum
from slam2d.runs.commands import COMMANDS

__all__ = ["compare_rows", "plot_errors", "plot_trajectories", "run_folders", "write_comparison"]


def run_folders(paths) -> list[Path]:
    """The results folders ``paths`` name: a run's folder (its metrics.json), or a sweep folder's runs."""
    folders = []
    for path in map(Path, paths):
        if (path / "metrics.json").is_file():
            folders.append(path)
        elif (path / "sweep.yaml").is_file():
            folders.extend(sorted(p for p in (path / "runs").iterdir() if (p / "metrics.json").is_file()))
        else:
            raise InputError(path, "not a results folder (no metrics.json) or a sweep folder (no sweep.yaml)")
    if not folders:
        raise InputError("runs", "no results folder to compare")
    return folders


def compare_rows(folders, metrics=None) -> tuple[list[dict], list[str]]:
    """One row per folder (``run``: its name, then its flattened metrics) and the columns to show: ``metrics``
    (dotted keys) or every command's main metrics that any row has."""
    rows = [{"run": f.name, **flatten_metrics(json.loads((f / "metrics.json").read_text()))} for f in folders]
    present = set().union(*rows)
    if metrics:
        missing = [m for m in metrics if m not in present]
        if missing:
            raise InputError("--metric", f"no run has '{missing[0]}' (e.g. {', '.join(sorted(present)[:8])})")
        columns = list(metrics)
    else:
        main = (key for name in COMMANDS for key in COMMANDS.get(name).main_metrics)
        columns = [k for k in dict.fromkeys(main) if k in present]
    return rows, ["run", *columns]


def write_comparison(folders, out: Path, metrics=None) -> str:
    """Write ``table.md/.csv/.tex``, ``trajectories.png`` and ``errors.png`` of ``folders`` into ``out``; return
    the Markdown table."""
    rows, columns = compare_rows(folders, metrics)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    write_table(rows, out / "table", leading=columns)
    plot_trajectories(folders, out / "trajectories.png")
    plot_errors(folders, out / "errors.png")
    return to_markdown(rows, columns)


def plot_trajectories(folders, path: Path) -> bool:
    """The runs' ``trajectory.tum`` overlaid (with the first ground truth found) in ``path``; False if no run
    has a trajectory (nothing is drawn)."""
    fig = Figure(figsize=(8, 7))
    FigureCanvasAgg(fig)
    ax = fig.add_subplot()
    truth = next((f / "ground_truth.tum" for f in folders if (f / "ground_truth.tum").is_file()), None)
    if truth is not None:
        xy = read_tum(truth).poses
        ax.plot(xy[:, 0], xy[:, 1], color="0.55", lw=2.5, label="ground truth", zorder=1)
    drawn = False
    for folder in folders:
        if (folder / "trajectory.tum").is_file():
            xy = read_tum(folder / "trajectory.tum").poses
            ax.plot(xy[:, 0], xy[:, 1], lw=0.9, label=folder.name, zorder=2)
            drawn = True
    if not drawn:
        return False
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.legend(loc="best", fontsize="small")
    fig.savefig(path, dpi=120, bbox_inches="tight")
    return True


def position_errors(folder: Path) -> np.ndarray | None:
    """Position error (m) of each pose of ``folder``'s trajectory.tum against its ground_truth.tum after the
    SE(2) alignment (evo_ape ``--align``); None without both files."""
    if not ((folder / "trajectory.tum").is_file() and (folder / "ground_truth.tum").is_file()):
        return None
    est, truth = read_tum(folder / "trajectory.tum").poses, read_tum(folder / "ground_truth.tum").poses
    if len(est) != len(truth):
        raise InputError(folder / "ground_truth.tum", f"{len(truth)} poses for {len(est)} in trajectory.tum")
    est = geometry.compose(align_se2(est, truth), est)
    return np.hypot(*(est[:, :2] - truth[:, :2]).T)


def plot_errors(folders, path: Path) -> bool:
    """Box plots of each run's aligned position errors (evo_res's distribution view) in ``path``; False if no
    run has a trajectory with its ground truth (nothing is drawn)."""
    errors = {f.name: e for f in folders if (e := position_errors(f)) is not None}
    if not errors:
        return False
    fig = Figure(figsize=(max(6.0, 1.1 * len(errors) + 2), 4.5))
    FigureCanvasAgg(fig)
    ax = fig.add_subplot()
    ax.boxplot(list(errors.values()), showfliers=True, flierprops={"markersize": 2})
    rmse = [float(np.sqrt(np.mean(e**2))) for e in errors.values()]
    ax.scatter(range(1, len(errors) + 1), rmse, marker="D", color="tab:red", zorder=3, label="RMSE")
    ax.set_xticks(range(1, len(errors) + 1), list(errors), rotation=30, ha="right", fontsize="small")
    ax.set_ylabel("aligned position error (m)")
    ax.set_title("APE per pose: median, quartiles, 1.5 IQR whiskers", fontsize="small")
    ax.legend(loc="best", fontsize="small")
    fig.savefig(path, dpi=120, bbox_inches="tight")
    return True
