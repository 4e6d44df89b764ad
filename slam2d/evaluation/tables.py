"""Ablation tables: one row per variant, metrics as columns (Markdown, CSV, LaTeX)."""

from __future__ import annotations

import csv
import math
import statistics
from collections.abc import Sequence
from pathlib import Path
from typing import Any

AGGREGATES = {"mean": statistics.fmean, "median": statistics.median, "sum": sum, "min": min, "max": max}
"""Aggregates of a sweep summary, applied to a column's numbers within a group."""


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
    """Column order: ``leading`` (the variant, its keys and the command's main metrics), (if ``full``) every
    other key, then error/folder."""
    seen: list[str] = []
    for row in rows:
        seen.extend(k for k in row if k not in seen)
    tail = [c for c in ("error", "folder") if any(r.get(c) for r in rows)]
    cols = [c for c in dict.fromkeys(leading) if c in seen]
    if full:
        cols += sorted(c for c in seen if c not in cols and c not in ("error", "folder"))
    return cols + tail


def format_value(value: Any) -> str:
    """A table cell: floats to 4 significant digits, None empty."""
    if isinstance(value, float):
        return f"{value:.4g}"
    return "" if value is None else str(value)


def to_markdown(rows: Sequence[dict[str, Any]], columns: Sequence[str]) -> str:
    lines = ["| " + " | ".join(columns) + " |", "|" + "|".join("---" for _ in columns) + "|"]
    for row in rows:
        lines.append("| " + " | ".join(format_value(row.get(c)) for c in columns) + " |")
    return "\n".join(lines) + "\n"


def to_latex(rows: Sequence[dict[str, Any]], columns: Sequence[str]) -> str:
    def esc(s: str) -> str:
        return s.replace("_", r"\_").replace("%", r"\%").replace("&", r"\&")

    lines = [r"\begin{tabular}{" + "l" * len(columns) + "}", r"\hline", " & ".join(map(esc, columns)) + r" \\", r"\hline"]
    lines += [" & ".join(esc(format_value(r.get(c))) for c in columns) + r" \\" for r in rows]
    lines += [r"\hline", r"\end{tabular}"]
    return "\n".join(lines) + "\n"


def check_summary(spec: Any, where: str) -> dict[str, list[str]]:
    """A sweep's ``summary`` spec ({"by": [column...], aggregate: [column...]}) checked; InputError naming ``where``."""
    from slam2d.errors import InputError

    if not isinstance(spec, dict) or not spec.get("by"):
        raise InputError(where, "expected a mapping with 'by' (columns to group by) and aggregates of columns")
    for key, columns in spec.items():
        if key != "by" and key not in AGGREGATES:
            raise InputError(where, f"unknown key '{key}' (by, {', '.join(AGGREGATES)})")
        if not isinstance(columns, list) or not all(isinstance(c, str) for c in columns):
            raise InputError(f"{where}.{key}", "expected a list of column names")
    return spec


def summarize(rows: Sequence[dict[str, Any]], spec: dict[str, list[str]]) -> list[dict[str, Any]]:
    """One row per distinct value of the ``spec["by"]`` columns (in order of appearance): those values,
    ``variants`` (rows in the group), ``failed`` (rows with an error), and ``AGG COLUMN`` for every
    aggregate of ``spec`` over the group's finite numbers (booleans count as 0/1)."""
    groups: dict[tuple, list[dict[str, Any]]] = {}
    for row in rows:
        groups.setdefault(tuple(row.get(c) for c in spec["by"]), []).append(row)
    out = []
    for key, members in groups.items():
        summary: dict[str, Any] = dict(zip(spec["by"], key))
        summary.update(variants=len(members), failed=sum(bool(r.get("error")) for r in members))
        for agg, columns in spec.items():
            for col in columns if agg != "by" else ():
                values = [float(r[col]) for r in members if isinstance(r.get(col), (int, float))
                          and math.isfinite(r[col])]  # fmt: skip
                summary[f"{agg} {col}"] = AGGREGATES[agg](values) if values else None
        out.append(summary)
    return out


def write_table(rows: Sequence[dict[str, Any]], stem: Path, leading: Sequence[str] = ("variant",),
                full: bool = False) -> list[Path]:
    """Write ``stem.md`` and ``stem.tex`` (main metrics, or every column if ``full``) and ``stem.csv`` (every one)."""
    stem = Path(stem)
    columns = columns_of(rows, leading, full=full)
    md, tex, csv_path = stem.with_suffix(".md"), stem.with_suffix(".tex"), stem.with_suffix(".csv")
    md.write_text(to_markdown(rows, columns))
    tex.write_text(to_latex(rows, columns))
    with csv_path.open("w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=columns_of(rows, leading), extrasaction="ignore")
        writer.writeheader()
        writer.writerows(rows)
    return [md, csv_path, tex]
