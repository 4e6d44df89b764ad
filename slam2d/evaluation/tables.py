"""Ablation tables: one row per variant, metrics as columns (Markdown, CSV, LaTeX)."""

from __future__ import annotations

import csv
from collections.abc import Sequence
from pathlib import Path
from typing import Any

# Metrics shown in tables, in this order, when present; everything else numeric follows.
PREFERRED = [
    "relations.trans_abs_mean",
    "relations.trans_abs_std",
    "relations.rot_abs_mean",
    "relations.rot_abs_std",
    "odometry_relations.trans_abs_mean",
    "ate.rmse",
    "odometry_ate.rmse",
    "rpe.trans_rmse",
    "rpe.rot_rmse_deg",
    "cpu_ms_per_scan",
    "slam.loop closures kept",
    "slam.loop closures rejected",
    "frontend_fallbacks",
    "scans",
    "runtime_s",
    "peak_rss_mb",
]


def flatten_metrics(metrics: dict[str, Any], prefix: str = "") -> dict[str, Any]:
    """``{'ate': {'rmse': 1}}`` -> ``{'ate.rmse': 1}`` (scalars only)."""
    flat: dict[str, Any] = {}
    for key, value in metrics.items():
        name = f"{prefix}{key}"
        if isinstance(value, dict):
            flat.update(flatten_metrics(value, name + "."))
        elif isinstance(value, (int, float, str, bool)) or value is None:
            flat[name] = value
    return flat


def columns_of(rows: Sequence[dict[str, Any]], leading: Sequence[str] = ("variant",), full: bool = True) -> list[str]:
    """Column order: ``leading``, preferred metrics, (if ``full``) every other key, then error/folder."""
    seen: list[str] = []
    for row in rows:
        seen.extend(k for k in row if k not in seen)
    tail = [c for c in ("error", "folder") if any(r.get(c) for r in rows)]
    cols = [c for c in leading if c in seen] + [c for c in PREFERRED if c in seen]
    if full:
        cols += sorted(c for c in seen if c not in cols and c not in ("error", "folder"))
    return cols + tail


def _fmt(value: Any) -> str:
    if isinstance(value, float):
        return f"{value:.4g}"
    return "" if value is None else str(value)


def to_markdown(rows: Sequence[dict[str, Any]], columns: Sequence[str]) -> str:
    lines = ["| " + " | ".join(columns) + " |", "|" + "|".join("---" for _ in columns) + "|"]
    for row in rows:
        lines.append("| " + " | ".join(_fmt(row.get(c)) for c in columns) + " |")
    return "\n".join(lines) + "\n"


def to_latex(rows: Sequence[dict[str, Any]], columns: Sequence[str]) -> str:
    def esc(s: str) -> str:
        return s.replace("_", r"\_").replace("%", r"\%").replace("&", r"\&")

    lines = [r"\begin{tabular}{" + "l" * len(columns) + "}", r"\hline", " & ".join(map(esc, columns)) + r" \\", r"\hline"]
    lines += [" & ".join(esc(_fmt(r.get(c))) for c in columns) + r" \\" for r in rows]
    lines += [r"\hline", r"\end{tabular}"]
    return "\n".join(lines) + "\n"


def write_table(rows: Sequence[dict[str, Any]], stem: Path, leading: Sequence[str] = ("variant",)) -> list[Path]:
    """Write ``stem.md`` and ``stem.tex`` (main metrics) and ``stem.csv`` (every metric)."""
    stem = Path(stem)
    columns = columns_of(rows, leading, full=False)
    md, tex, csv_path = stem.with_suffix(".md"), stem.with_suffix(".tex"), stem.with_suffix(".csv")
    md.write_text(to_markdown(rows, columns))
    tex.write_text(to_latex(rows, columns))
    with csv_path.open("w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=columns_of(rows, leading), extrasaction="ignore")
        writer.writeheader()
        writer.writerows(rows)
    return [md, csv_path, tex]
