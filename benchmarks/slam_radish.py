"""Relations metric, wall clock and peak memory of `slam2d run` on the Radish logs.

Usage: .venv/bin/python benchmarks/slam_radish.py [intel aces ...] [--set KEY=VALUE ...]
Runs each experiments/<log>.yaml in a fresh process (as a user would), then
prints the relations metric beside the published figures.
"""

from __future__ import annotations

import json
import re
import subprocess
import sys
import time
from pathlib import Path

PUBLISHED = {  # absolute translational error (m), mean ± std; Cartographer wall clock (s)
    "intel": {"graph mapping": "0.031 ± 0.026", "Cartographer": "0.0229 ± 0.0239", "carto_s": 179},
    "aces": {"graph mapping": "0.044 ± 0.044", "Cartographer": "0.0375 ± 0.0426", "carto_s": 41},
}


def run(log: str, overrides: list[str]) -> dict:
    root = Path("results/bench")
    cmd = [sys.executable, "-m", "slam2d.cli", "run", f"experiments/{log}.yaml", "-q", "--set", f"output.root={root}"]
    for o in overrides:
        cmd += ["--set", o]
    t0 = time.perf_counter()
    out = subprocess.run(cmd, capture_output=True, text=True, check=True).stdout
    wall = time.perf_counter() - t0
    folder = Path(re.search(r"results: (.+)", out).group(1).strip())
    metrics = json.loads((folder / "metrics.json").read_text())
    return {"wall_s": wall, **metrics}


def main(argv: list[str]) -> None:
    overrides = [a for a in argv if "=" in a and not a.startswith("--")]
    logs = [a for a in argv if a in PUBLISHED] or list(PUBLISHED)
    print("| log | trans. abs (m) | trans. sq (m²) | rot. abs (deg) | rot. sq (deg²) | odometry trans. abs (m) "
          "| graph mapping | Cartographer | wall clock (s) | peak RSS (MB) |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for log in logs:
        m = run(log, overrides)
        r, o = m["relations"], m["odometry_relations"]
        p = PUBLISHED[log]
        print(
            f"| {log} | {r['trans_abs_mean']:.4f} ± {r['trans_abs_std']:.4f} | {r['trans_sq_mean']:.5f} ± {r['trans_sq_std']:.5f} "
            f"| {r['rot_abs_mean']:.3f} ± {r['rot_abs_std']:.3f} | {r['rot_sq_mean']:.3f} ± {r['rot_sq_std']:.3f} "
            f"| {o['trans_abs_mean']:.3f} | {p['graph mapping']} | {p['Cartographer']} "
            f"| {m['wall_s']:.1f} (Cartographer {p['carto_s']} on 6 cores) | {m['peak_rss_mb']:.0f} |"
        )


if __name__ == "__main__":
    main(sys.argv[1:])
