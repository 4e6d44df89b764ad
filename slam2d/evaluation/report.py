"""The sweep report: one self-contained ``report.html`` per ``slam2d ablate`` folder.

The page holds the sweep's summary (when the sweep file asks for one) and the
ablation table (main metrics; click a column header to sort, again to reverse;
``report.html#sort=COLUMN`` or ``#sort=-COLUMN`` opens the ablation table
sorted), each variant's figures as thumbnails and a link to its folder. Styles
and script are inline; figures are linked relative to the sweep folder, so the
folder can be moved or served as a whole.
"""

from __future__ import annotations

import html
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any
from urllib.parse import quote

from slam2d.evaluation.tables import columns_of, format_value

FIRST_FIGURES = ("map.png", "rooms.png", "path.png", "velocity.png")
"""Figures shown first when a variant's folder has them; other PNGs follow by name."""
NOT_FIGURES = ("labels.png",)
"""PNGs in a results folder that are data, not figures."""
MAX_FIGURES = 3
"""Thumbnails per variant (its folder link leads to the rest)."""

_STYLE = """
body{font:14px/1.4 system-ui,sans-serif;margin:1.5em;color:#222}
table{border-collapse:collapse}th,td{border:1px solid #ccc;padding:3px 6px;vertical-align:top}
th{background:#eee;cursor:pointer;user-select:none;position:sticky;top:0}
th[aria-sort=ascending]::after{content:" \\25B2"}th[aria-sort=descending]::after{content:" \\25BC"}
td.num{text-align:right;font-variant-numeric:tabular-nums}td.error{color:#b00}
img{height:110px;margin-right:4px;border:1px solid #ddd;background:#fff}
"""

_SCRIPT = """
document.querySelectorAll("table.sortable").forEach(table => {
  const heads = Array.from(table.tHead.rows[0].cells);
  const value = (row, col) => {
    const cell = row.cells[col];
    return cell.dataset.num !== undefined ? Number(cell.dataset.num) : cell.textContent.trim();
  };
  function sortBy(col, desc) {
    const body = table.tBodies[0];
    const rows = Array.from(body.rows);
    rows.sort((a, b) => {
      const x = value(a, col), y = value(b, col);
      if (x === "" || y === "") return (x === "") - (y === "");  // empty cells last either way
      const d = typeof x === "number" && typeof y === "number" ? x - y
        : String(x).localeCompare(String(y), undefined, {numeric: true});
      return desc ? -d : d;
    });
    rows.forEach(r => body.appendChild(r));
    heads.forEach(h => h.removeAttribute("aria-sort"));
    heads[col].setAttribute("aria-sort", desc ? "descending" : "ascending");
  }
  heads.forEach((th, col) => th.addEventListener("click", () => {
    const desc = th.getAttribute("aria-sort") === "ascending";
    sortBy(col, desc);
    history.replaceState(null, "", "#sort=" + (desc ? "-" : "") + encodeURIComponent(th.dataset.col));
  }));
  const m = table.id === "results" && location.hash.match(/^#sort=(-?)(.+)$/);
  const col = m ? heads.findIndex(h => h.dataset.col === decodeURIComponent(m[2])) : -1;
  if (col >= 0) sortBy(col, m[1] === "-");
});
"""


def write_report(root: Path, rows: Sequence[dict[str, Any]], leading: Sequence[str] = ("variant",),
                 summary: tuple[Sequence[dict[str, Any]], Sequence[str]] | None = None) -> Path:
    """Write ``root/report.html`` for the sweep rows (``variant``, overrides, metrics, ``error``,
    ``folder`` relative to ``root``) and the ``summary`` (its rows and group columns); return its path."""
    root = Path(root)
    columns = [c for c in columns_of(rows, leading, full=False) if c != "folder"]
    names = [columns[0], "figures", *columns[1:]]  # the figures beside the variant's name
    body = "\n".join(_row(root, row, columns) for row in rows)
    name = html.escape(root.name)
    grouped = ""
    if summary is not None and summary[0]:
        cols = list(summary[0][0])
        cells = "\n".join(f"<tr>{''.join(_cell(r.get(c), c) for c in cols)}</tr>" for r in summary[0])
        grouped = (f'<h2>Summary</h2>\n<p><a href="summary.csv">summary.csv</a></p>\n'
                   f'<table class="sortable" id="summary">{_head(cols)}<tbody>\n{cells}\n</tbody></table>\n'
                   f"<h2>Variants</h2>\n")  # fmt: skip
    page = (
        f'<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8"><title>{name}</title>'
        f"<style>{_STYLE}</style></head><body>\n<h1>{name}</h1>\n"
        f'<p>{len(rows)} variants · <a href="sweep.yaml">sweep.yaml</a> · <a href="table.csv">table.csv</a> '
        f"(every metric) · click a column header to sort</p>\n{grouped}"
        f'<table class="sortable" id="results">{_head(names)}<tbody>\n{body}\n</tbody></table>\n'
        f"<script>{_SCRIPT}</script></body></html>\n"
    )
    path = root / "report.html"
    path.write_text(page, encoding="utf-8")
    return path


def _head(names: Sequence[str]) -> str:
    return "<thead><tr>" + "".join(f'<th data-col="{html.escape(c)}">{html.escape(c)}</th>' for c in names) + \
        "</tr></thead>"


def _cell(value: Any, col: str, link: str = "") -> str:
    """A table cell: numbers right-aligned with their full value in ``data-num`` (for sorting)."""
    text = html.escape(format_value(value))
    if link:
        text = f'<a href="{link}">{text}</a>'
    if _is_number(value):
        return f'<td class="num" data-num="{value!r}">{text}</td>'
    return f'<td{" class=error" if col == "error" else ""}>{text}</td>'


def _row(root: Path, row: dict[str, Any], columns: Sequence[str]) -> str:
    folder = row.get("folder") or ""
    cells = [_cell(row.get(c), c, f"{quote(folder)}/" if c == "variant" and folder else "") for c in columns]
    figures = "".join(f'<a href="{quote(f)}"><img src="{quote(f)}" alt="{html.escape(Path(f).name)}" '
                      f'loading="lazy"></a>' for f in figures_of(root, folder)) if folder else ""
    cells.insert(1, f"<td>{figures}</td>")
    return f'<tr data-variant="{html.escape(str(row.get("variant", "")))}">{"".join(cells)}</tr>'


def figures_of(root: Path, folder: str) -> list[str]:
    """Up to MAX_FIGURES figure paths (relative to ``root``) of the run folder ``root/folder``."""
    pngs = sorted(p.name for p in (root / folder).glob("*.png") if p.name not in NOT_FIGURES)
    ordered = [n for n in FIRST_FIGURES if n in pngs] + [n for n in pngs if n not in FIRST_FIGURES]
    return [f"{folder}/{n}" for n in ordered[:MAX_FIGURES]]


def _is_number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)
