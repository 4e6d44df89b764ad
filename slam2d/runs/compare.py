"""``slam2d compare``: several results folders side by side, as evo's ``evo_res`` does for evo's results:
one table of their metrics and their trajectories overlaid.

A sweep folder stands for its variants' runs. The table's columns are the given metrics, or the main
metrics of every command (:data:`slam2d.runs.commands.COMMANDS`) that any of the runs has.
"""

from __future__ import annotations

import json
from pathlib import Path

from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from slam2d.errors import InputError
from slam2d.evaluation.tables import flatten_metrics, to_markdown, write_table
from slam2d.evaluation.trajectory import read_tum
from slam2d.runs.commands import COMMANDS

__all__ = ["run_folders", "compare_rows", "write_comparison", "plot_trajectories"]


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
    """Write ``table.md/.csv/.tex`` and ``trajectories.png`` of ``folders`` into ``out``; return the Markdown table."""
    rows, columns = compare_rows(folders, metrics)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    write_table(rows, out / "table", leading=columns)
    plot_trajectories(folders, out / "trajectories.png")
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
