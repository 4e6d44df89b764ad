"""``report.html`` of one results folder, for every command: its main metrics, its table (``table.csv``, as
compare writes), its figures (embedded, so the page stands alone), every metric and the resolved config;
rendered from a Jinja2 template."""

from __future__ import annotations

import base64
import csv
import json
from pathlib import Path

from jinja2 import Environment, PackageLoader, select_autoescape

from slam2d.evaluation.tables import flatten_metrics, format_value
from slam2d.runs.commands import COMMANDS

__all__ = ["write_run_report"]

FIGURE_TYPES = {".png": "image/png", ".gif": "image/gif"}
CAPTIONS = {  # what a figure shows, by file name (a name not here is captioned by itself)
    "map.png": "the map at the estimate, with the estimate, odometry and ground truth drawn on it",
    "ape.png": "absolute position error over time and along the trajectory (after the ATE's alignment)",
    "relations.png": "errors of the ground-truth relations, estimate against odometry; the worst named",
    "loops.png": "loop-closure timeline: which time each closure joined to which, and their count over time",
    "error_particles.png": "particle convergence: pose error and particle count over time",
    "coverage.png": "coverage of the free space over time and over distance driven",
    "rooms.png": "the rooms found", "labels.png": "the room labels", "path.png": "the planned path",
    "errors.png": "position error per pose of each run (median, quartiles, whiskers; RMSE as a diamond)",
    "trajectories.png": "the runs' trajectories overlaid on the ground truth",
}
_TEMPLATES = Environment(loader=PackageLoader("slam2d.runs", "templates"), autoescape=select_autoescape())


def write_run_report(folder: Path, name: str | None = None) -> Path:
    """Write ``folder/report.html`` from what it holds of metrics.json, table.csv, figures (PNG, GIF) and
    config.yaml; return its path."""
    folder = Path(folder)
    has = (folder / "metrics.json").is_file()
    metrics = flatten_metrics(json.loads((folder / "metrics.json").read_text())) if has else {}
    table = list(csv.reader((folder / "table.csv").open())) if (folder / "table.csv").is_file() else []
    main_keys = dict.fromkeys(k for c in COMMANDS for k in COMMANDS.get(c).main_metrics)
    figures = [{"name": p.name, "mime": FIGURE_TYPES[p.suffix.lower()], "caption": CAPTIONS.get(p.name, ""),
                "data": base64.b64encode(p.read_bytes()).decode("ascii")}
               for p in sorted(folder.iterdir()) if p.suffix.lower() in FIGURE_TYPES]  # fmt: skip
    config = (folder / "config.yaml").read_text() if (folder / "config.yaml").is_file() else ""
    page = _TEMPLATES.get_template("run_report.html.j2").render(
        name=name or folder.name, files=sorted(p.name for p in folder.iterdir() if not p.name.startswith(".")),
        main=[(k, format_value(metrics[k])) for k in main_keys if k in metrics],
        metrics=[(k, format_value(v)) for k, v in metrics.items()], figures=figures, config=config, table=table)
    path = folder / "report.html"
    path.write_text(page)
    return path
