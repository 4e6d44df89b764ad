"""SLAM on Radish logs whose wheel odometry lies: freezes, jumps and wild steps injected.

Usage: nice .venv/bin/python benchmarks/slam_perturbed.py [aces fr079 ...] [--seeds 0 1 2]
       [--rates 0.002,0.001,0.002] [--set KEY=VALUE ...]

Runs each experiments/<log>.yaml (the one default) with benchmarks/plugins/perturbed_odometry.py
(its docstring says what is injected; ``--rates``: freeze, jump and wild-step probabilities per
scan), once per seed, and prints the faults injected, the relations error of the perturbed
odometry alone and of slam2d, beside the clean run's and Cartographer's published figure on the
clean log. Median and range over the seeds close each log.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from slam_radish import PUBLISHED, run

PLUGIN = str(Path(__file__).resolve().parent / "plugins" / "perturbed_odometry.py")


def perturbed_run(log: str, seed: int, rates: str, overrides: list[str]) -> tuple[dict, dict]:
    """(metrics, faults injected) of one run of ``log`` with odometry perturbed by ``seed``."""
    with tempfile.TemporaryDirectory() as tmp:
        faults = Path(tmp) / "faults.json"
        env = {**os.environ, "SLAM2D_PERTURB_SEED": str(seed), "SLAM2D_PERTURB_RATES": rates,
               "SLAM2D_PERTURB_LOG": str(faults)}  # fmt: skip
        metrics = run(log, overrides, plugins=[PLUGIN], env=env)
        return metrics, json.loads(faults.read_text())


def main(argv: list[str]) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("logs", nargs="*", default=["aces", "fr079"], help=f"some of {', '.join(PUBLISHED)}")
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2], help="perturbation seeds")
    ap.add_argument("--rates", default="0.002,0.001,0.002", help="freeze,jump,wild-step probability per scan")
    ap.add_argument("--set", dest="overrides", action="append", default=[], help="config override KEY=VALUE")
    args = ap.parse_args(argv)
    unknown = set(args.logs) - set(PUBLISHED)
    if unknown:
        ap.error(f"unknown log(s) {sorted(unknown)}; choose from {list(PUBLISHED)}")
    print("| log | seed | freezes / jumps / wild steps | odometry (m) | slam2d (m) | clean run (m) | Cartographer, clean (m) |")
    print("|---|---|---|---|---|---|---|")
    for log in args.logs:
        clean = run(log, args.overrides)["relations"]["trans_abs_mean"]
        carto = PUBLISHED[log]["Cartographer"]
        errors = []
        for seed in args.seeds:
            m, faults = perturbed_run(log, seed, args.rates, args.overrides)
            errors.append(m["relations"]["trans_abs_mean"])
            counts = " / ".join(str(faults.get(k, 0)) for k in ("freeze", "jump", "wild step"))
            print(f"| {log} | {seed} | {counts} | {m['odometry_relations']['trans_abs_mean']:.3f} | {errors[-1]:.4f} "
                  f"| {clean:.4f} | {carto} |", flush=True)  # fmt: skip
        print(f"| {log} | median [min–max] | | | {statistics.median(errors):.4f} [{min(errors):.4f}–{max(errors):.4f}] "
              f"| {clean:.4f} | {carto} |", flush=True)  # fmt: skip


if __name__ == "__main__":
    main(sys.argv[1:])
