"""``report.html`` of one results folder, for every command: its main metrics, its figures (embedded, so the
page stands alone), every metric and the resolved config; rendered from a Jinja2 template."""

from __future__ import annotations

import base64
import json
from pathlib import Path

from jinja2 import Environment, PackageLoader, select_autoescape

from slam2d.evaluation.tables import flatten_metrics, format_value
from slam2d.runs.commands import COMMANDS

__all__ = ["write_run_report"]

FIGURE_TYPES = {".png": "image/png", ".gif": "image/gif"}
_TEMPLATES = Environment(loader=PackageLoader("slam2d.runs", "templates"), autoescape=select_autoescape())


def write_run_report(folder: Path, name: str | None = None) -> Path:
    """Write ``folder/report.html`` from its metrics.json, figures (PNG, GIF) and config.yaml; return its path."""
    folder = Path(folder)
    metrics = flatten_metrics(json.loads((folder / "metrics.json").read_text()))
    main_keys = dict.fromkeys(k for c in COMMANDS for k in COMMANDS.get(c).main_metrics)
    figures = [{"name": p.name, "mime": FIGURE_TYPES[p.suffix.lower()],
                "data": base64.b64encode(p.read_bytes()).decode("ascii")}
               for p in sorted(folder.iterdir()) if p.suffix.lower() in FIGURE_TYPES]  # fmt: skip
    config = (folder / "config.yaml").read_text() if (folder / "config.yaml").is_file() else ""
    page = _TEMPLATES.get_template("run_report.html.j2").render(
        name=name or folder.name, files=sorted(p.name for p in folder.iterdir() if not p.name.startswith(".")),
        main=[(k, format_value(metrics[k])) for k in main_keys if k in metrics],
        metrics=[(k, format_value(v)) for k, v in metrics.items()], figures=figures, config=config)
    path = folder / "report.html"
    path.write_text(page)
    return path
