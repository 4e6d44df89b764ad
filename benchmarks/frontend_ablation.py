"""Frontend ablation: every frontend on the simulator default, intel.bag and aces.bag, alone and with the pose graph.

Reads the variants of a sweep file (default ``experiments/ablation_frontends.yaml``),
runs them one after another in this process with ``slam2d.runs.run.run_experiment``
(one heavy job at a time: the whole Intel log needs up to 1 GB) and builds the
table from each run's ``metrics.json``:

- relations metric (absolute translational error, m, and rotational error, deg,
  mean ± std) where a relations file is given, and the odometry's beside it;
- ATE RMSE (m) against ground truth where there is one (the simulator);
- CPU ms per scan (``cpu_ms_per_scan``: CPU time of the run's reading,
  frontend and back end over the scans, the frontend worker's included); the wall-clock figure
  (``timings_s.slam``) goes to the CSV;
- loop closures accepted (``slam.loop_closures_kept``: added and kept after
  the final optimisation) and rejected (``slam.loop_closures_rejected``: by the
  matcher's score or points, or removed as inconsistent);
- odometry fallbacks (``frontend_fallbacks``: scans after the first answered
  with confidence 0), and their share of the scans.

Writes ``table.md``, ``table.csv`` and ``rows.json`` under ``--out`` and prints the
Markdown table. ``--only REGEX`` runs the matching variants; ``--resume`` keeps
variants already finished under ``--out``.

    nice .venv/bin/python benchmarks/frontend_ablation.py [--sweep FILE] [--out DIR] [--only REGEX] [--resume]
"""

from __future__ import annotations

import argparse
import csv
import json
import re
import sys
from pathlib import Path
from typing import Any

from slam2d.runs.run import run_experiment
from slam2d.runs.sweep import load_sweep, variant_config

DATASETS = {"simulator": "simulator default", "intel.bag": "intel.bag", "aces.bag": "aces.bag"}

def _row(name: str, cfg, folder: Path) -> dict[str, Any]:
    m = json.loads((folder / "metrics.json").read_text())
    dataset = "simulator" if cfg.dataset.kind == "simulator" else Path(cfg.dataset.path).name
    row: dict[str, Any] = {
        "variant": name,
        "dataset": dataset,
        "frontend": cfg.frontend.name,
        "backend": cfg.backend.name,
        "scans": m["scans"],
    }
    for label, key in (("", "relations"), ("odometry_", "odometry_relations")):
        if key in m:
            r = m[key]
            row.update({f"{label}trans_m": r["trans_abs_mean"], f"{label}trans_std_m": r["trans_abs_std"],
                        f"{label}rot_deg": r["rot_abs_mean"], f"{label}rot_std_deg": r["rot_abs_std"]})
    if "ate" in m:
        row["ate_m"], row["odometry_ate_m"] = m["ate"]["rmse"], m["odometry_ate"]["rmse"]
    row["cpu_ms_per_scan"] = m["cpu_ms_per_scan"]
    row["wall_ms_per_scan"] = 1000.0 * m["timings_s"]["slam"] / m["scans"]
    row["loops_accepted"] = m["slam"].get("loop_closures_kept")
    row["loops_rejected"] = m["slam"].get("loop_closures_rejected")
    row["fallbacks"] = m["frontend_fallbacks"]
    row["fallback_share"] = m["frontend_fallbacks"] / max(m["scans"] - 1, 1)
    row["frontend_stats"] = {k[len("frontend_"):]: v for k, v in m["slam"].items() if k.startswith("frontend_")}
    row["folder"] = str(folder)
    return row

def _fmt(row: dict[str, Any], key: str, digits: int) -> str:
    value = row.get(key)
    return "" if value is None else f"{value:.{digits}f}"

def markdown(rows: list[dict[str, Any]]) -> str:
    head = ("| dataset | frontend | backend | relations trans. (m) | relations rot. (deg) | ATE RMSE (m) "
            "| CPU ms / scan | loop closures accepted / rejected | odometry fallbacks |")
    out = [head, "|" + "---|" * 9]
    for r in rows:
        trans = f"{r['trans_m']:.3f} ± {r['trans_std_m']:.3f}" if "trans_m" in r else "–"
        rot = f"{r['rot_deg']:.2f} ± {r['rot_std_deg']:.2f}" if "rot_deg" in r else "–"
        ate = _fmt(r, "ate_m", 4) or "–"
        loops = "–" if r["loops_accepted"] is None else f"{r['loops_accepted']} / {r['loops_rejected']}"
        fallbacks = f"{r['fallbacks']} ({100 * r['fallback_share']:.1f} %)"
        backend = "pose graph" if r["backend"] == "pose_graph" else "alone"
        out.append(f"| {DATASETS.get(r['dataset'], r['dataset'])} | {r['frontend']} | {backend} | {trans} | {rot} "
                   f"| {ate} | {r['cpu_ms_per_scan']:.2f} | {loops} | {fallbacks} |")
    return "\n".join(out) + "\n"

def _finished(runs: Path, name: str) -> Path | None:
    done = sorted(p.parent for p in runs.glob(f"{name}-*/metrics.json") if re.fullmatch(rf"{re.escape(name)}-[\d-]+",
                                                                                          p.parent.name))
    return done[-1] if done else None

def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sweep", default="experiments/ablation_frontends.yaml")
    ap.add_argument("--out", default="results/frontend_ablation")
    ap.add_argument("--only", default=None, help="run only variants whose name matches this regular expression")
    ap.add_argument("--resume", action="store_true", help="keep variants already finished under --out")
    args = ap.parse_args(argv)

    base, variants, _ = load_sweep(args.sweep)
    if args.only:
        variants = [v for v in variants if re.search(args.only, v.name)]
    out = Path(args.out)
    runs = out / "runs"
    rows = []
    for v in variants:
        cfg = variant_config(base, v, runs)
        cfg = cfg.model_copy(update={"output": cfg.output.model_copy(update={"figures": False})})
        folder = _finished(runs, cfg.name) if args.resume else None
        if folder is None:
            print(f"{v.name} ...", file=sys.stderr, flush=True)
            folder = run_experiment(cfg, quiet=True)
        rows.append(_row(v.name, cfg, folder))
        print(f"{v.name}: {rows[-1]['cpu_ms_per_scan']:.2f} ms CPU per scan", file=sys.stderr, flush=True)

    out.mkdir(parents=True, exist_ok=True)
    table = markdown(rows)
    (out / "table.md").write_text(table)
    (out / "rows.json").write_text(json.dumps(rows, indent=1))
    columns = list(dict.fromkeys(k for r in rows for k in r if k != "frontend_stats"))
    with (out / "table.csv").open("w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=columns, extrasaction="ignore")
        writer.writeheader()
        writer.writerows(rows)
    print(table)
    return 0

if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
