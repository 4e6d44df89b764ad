"""The Radish logs under several draws of the ICP local map's point order: how much a log's figure is one draw.

Usage: .venv/bin/python benchmarks/slam_draws.py [intel aces fr079 fr-clinic csail] [--draws 4] [--first-draw 0]
       [--workers 2] [--set KEY=VALUE ...] [--out results/bench-draws]

Runs each experiments/<log>.yaml with ``frontend.options.map_order=random`` and ``map_seed`` first … first +
draws − 1 (and the ``--set`` overrides, so that a change can be judged over draws rather than on one run), each
`slam2d run` in a process of its own, and prints per log every draw's relations error (m), their median and how
many draws beat Cartographer's published figure (Hess et al. 2016). The default (beam order) is one order of the
points, not a draw: run it with ``slam2d run experiments/<log>.yaml``.
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

CARTOGRAPHER = {"intel": 0.0229, "aces": 0.0375, "fr079": 0.0452, "fr-clinic": 0.1078, "csail": 0.0319}  # m


def draw(log: str, seed: int, overrides: list[str], out: Path) -> float:
    """Relations error (m) of ``log`` under draw ``seed`` of the random order."""
    folder = out / f"{log}-draw{seed}"
    sets = ["frontend.options.map_order=random", f"frontend.options.map_seed={seed}", *overrides]
    cmd = [sys.executable, "-m", "slam2d.cli", "run", f"experiments/{log}.yaml", "-q", "--out", str(folder)]
    subprocess.run(cmd + [a for s in sets for a in ("--set", s)], check=True, stdout=subprocess.DEVNULL)
    metrics = max(folder.glob("*/metrics.json"))
    error = float(json.loads(metrics.read_text())["relations"]["trans_abs_mean"])
    print(f"  {log} draw {seed}: {error:.5f} m", file=sys.stderr, flush=True)
    return error


def table(errors: dict[str, list[float]], first: int = 0) -> str:
    """Markdown table: per log the errors (m) of draws ``first`` on, their median and the draws below
    Cartographer's figure."""
    n = max(len(e) for e in errors.values())
    out = ["| log | " + " | ".join(f"draw {k}" for k in range(first, first + n)) + " | median | beat Cartographer |",
           "|---|" + "---|" * (n + 2)]
    for log, e in errors.items():
        beat = sum(x < CARTOGRAPHER[log] for x in e)
        out.append(f"| {log} | " + " | ".join(f"{x:.5f}" for x in e) + f" | {statistics.median(e):.5f} | "
                   f"{beat} of {len(e)} (< {CARTOGRAPHER[log]}) |")
    return "\n".join(out)


def main(argv: list[str]) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("logs", nargs="*", default=list(CARTOGRAPHER), help=f"some of {', '.join(CARTOGRAPHER)}")
    ap.add_argument("--draws", type=int, default=4, help="how many draws: map_seed first … first + draws - 1")
    ap.add_argument("--first-draw", type=int, default=0, help="the first draw's map_seed")
    ap.add_argument("--workers", type=int, default=2, help="runs at once")
    ap.add_argument("--set", dest="overrides", action="append", default=[], help="config override KEY=VALUE")
    ap.add_argument("--out", type=Path, default=Path("results/bench-draws"))
    args = ap.parse_args(argv)
    unknown = set(args.logs) - set(CARTOGRAPHER)
    if unknown:
        ap.error(f"unknown logs: {', '.join(sorted(unknown))} (known: {', '.join(CARTOGRAPHER)})")
    jobs = [(log, seed) for log in args.logs for seed in range(args.first_draw, args.first_draw + args.draws)]
    with ThreadPoolExecutor(args.workers) as pool:
        found = list(pool.map(lambda job: draw(*job, args.overrides, args.out), jobs))
    errors: dict[str, list[float]] = {}
    for (log, _), error in zip(jobs, found):
        errors.setdefault(log, []).append(error)
    print(table(errors, args.first_draw))


if __name__ == "__main__":
    main(sys.argv[1:])
