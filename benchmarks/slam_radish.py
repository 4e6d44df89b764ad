"""Relations metric, wall clock and peak memory of `slam2d run` on the Radish logs.

Usage: .venv/bin/python benchmarks/slam_radish.py [intel aces fr079 fr-clinic csail] [--repeat N] [--set KEY=VALUE ...]
Runs each experiments/<log>.yaml (the defaults; the files name only the data)
in a fresh process (as a user would), N times
(default 3) alternating with the same run in one process (``parallel=false``)
as the peer: the table gives the median wall clock of each, their ratio, the
real-time factor beside Cartographer's, and the relations metric of the last
run beside the published figures.
"""

from __future__ import annotations

import argparse
import json
import re
import statistics
import subprocess
import sys
import time
from pathlib import Path

PUBLISHED = {  # Hess et al. 2016, Tables II-III: absolute translational / rotational error (mean ± std), wall clock
    "intel": {"graph mapping": "0.031 ± 0.026", "Cartographer": "0.0229 ± 0.0239", "carto_rot": "0.453 ± 1.335",
              "carto_s": 179, "log_s": 2691},
    "aces": {"graph mapping": "0.044 ± 0.044", "Cartographer": "0.0375 ± 0.0426", "carto_rot": "0.373 ± 0.469",
             "carto_s": 41, "log_s": 1366},
    "fr079": {"graph mapping": "0.056 ± 0.042", "Cartographer": "0.0452 ± 0.0354", "carto_rot": "–",
              "carto_s": 62, "log_s": 1061},
    "fr-clinic": {"graph mapping": "0.143 ± 0.180", "Cartographer": "0.1078 ± 0.1943", "carto_rot": "–",
                  "carto_s": None, "log_s": 4820},
    "csail": {"graph mapping": "0.004 ± 0.009", "Cartographer": "0.0319 ± 0.0363", "carto_rot": "–",
              "carto_s": 35, "log_s": 424},
}


def run(log: str, overrides: list[str], plugins: list[str] = (), env: dict | None = None) -> dict:
    """metrics.json of one `slam2d run` (with ``--plugin`` files, in ``env``) plus its wall clock (s) seen
    from outside."""
    root = Path("results/bench")
    cmd = [sys.executable, "-m", "slam2d.cli", "run", f"experiments/{log}.yaml", "-q", "--set", f"output.root={root}"]
    for o in overrides:
        cmd += ["--set", o]
    for p in plugins:
        cmd += ["--plugin", p]
    t0 = time.perf_counter()
    out = subprocess.run(cmd, capture_output=True, text=True, check=True, env=env).stdout
    wall = time.perf_counter() - t0
    folder = Path(re.search(r"results: (.+)", out).group(1).strip())
    metrics = json.loads((folder / "metrics.json").read_text())
    return {"wall_s": wall, "folder": str(folder), **metrics}


def main(argv: list[str]) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("logs", nargs="*", help=f"some of {', '.join(PUBLISHED)} (default: all)")
    ap.add_argument("--repeat", type=int, default=3, help="runs per log and mode; medians are reported")
    ap.add_argument("--set", dest="overrides", action="append", default=[], help="config override KEY=VALUE")
    args = ap.parse_args(argv)
    unknown = set(args.logs) - set(PUBLISHED)
    if unknown:
        ap.error(f"unknown log(s) {sorted(unknown)}; choose from {list(PUBLISHED)}")
    print("| log | trans. abs (m) | trans. sq (m²) | rot. abs (deg) | rot. sq (deg²) | odometry trans. abs (m) "
          "| graph mapping (m) | Cartographer (m) | Cartographer rot. (deg) | loops kept / rejected "
          "| wall clock (s), median [min–max] | one process (s) | CPU (s) "
          "| × real time (Cartographer on 6 cores) | peak RSS (MB) |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for log in args.logs or list(PUBLISHED):
        walls, singles = [], []
        for _ in range(args.repeat):
            m = run(log, args.overrides)
            walls.append(m["wall_s"])
            singles.append(run(log, [*args.overrides, "parallel=false"])["wall_s"])
        r, o, p, slam = m["relations"], m["odometry_relations"], PUBLISHED[log], m.get("slam", {})
        wall, single = statistics.median(walls), statistics.median(singles)
        carto = f"{p['log_s'] / p['carto_s']:.0f}" if p["carto_s"] else "–"
        print(
            f"| {log} | {r['trans_abs_mean']:.4f} ± {r['trans_abs_std']:.4f} "
            f"| {r['trans_sq_mean']:.5f} ± {r['trans_sq_std']:.5f} "
            f"| {r['rot_abs_mean']:.3f} ± {r['rot_abs_std']:.3f} | {r['rot_sq_mean']:.3f} ± {r['rot_sq_std']:.3f} "
            f"| {o['trans_abs_mean']:.3f} | {p['graph mapping']} | {p['Cartographer']} | {p['carto_rot']} "
            f"| {slam.get('loop_closures_kept', 0)} / {slam.get('loop_closures_rejected', 0)} "
            f"| {wall:.1f} [{min(walls):.1f}–{max(walls):.1f}] | {single:.1f} | {m['cpu_ms_per_scan'] * m['scans'] / 1000:.1f} "
            f"| {p['log_s'] / wall:.0f} ({carto}) | {m['peak_rss_mb']:.0f} |",
            flush=True,
        )


if __name__ == "__main__":
    main(sys.argv[1:])
