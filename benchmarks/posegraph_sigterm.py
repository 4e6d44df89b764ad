"""How soon ``slam2d optimize`` ends after SIGTERM during a long solve.

Runs ``slam2d optimize GRAPH --outliers K --outlier-kind KIND --robust METHOD`` (default: least squares
over K injected random false loops, where one GTSAM iteration takes seconds; ``--robust pc_dcs`` or
``gnc`` for their screen, starts, solves and admission) and sends SIGTERM ``--delays`` seconds after its results work folder appears;
prints, per run, the time from the signal to the process's end, the exit code, whether a solve's worker
process was running when the signal was sent, and whether a results folder was left; then the median and
the maximum.

    SLAM2D_DATA=... nice .venv/bin/python benchmarks/posegraph_sigterm.py [--graph M3500] [--outliers 1000]
        [--outlier-kind random] [--robust none] [--delays 1 3 5 8 12 16]
"""

from __future__ import annotations

import argparse
import os
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import psutil

DATA = Path(os.environ.get("SLAM2D_DATA", Path(__file__).resolve().parents[1] / ".." / "shared" / "datasets"))


def one(graph: Path, options: list[str], delay: float, root: Path) -> tuple[float, int, bool, bool]:
    """(s from SIGTERM to exit, exit code, a worker was running, a results folder was left)."""
    proc = subprocess.Popen([sys.executable, "-m", "slam2d.cli", "optimize", str(graph), *options,
                             "--out", str(root), "-q"], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    while not (root.is_dir() and any(root.iterdir())):
        if proc.poll() is not None:
            raise RuntimeError(f"the command ended before its solve (exit {proc.returncode})")
        time.sleep(0.05)
    time.sleep(delay)
    if proc.poll() is not None:
        raise RuntimeError(f"the command ended within {delay} s: pick shorter delays")
    worker = bool(psutil.Process(proc.pid).children())
    proc.send_signal(signal.SIGTERM)
    sent = time.monotonic()
    proc.wait()
    return time.monotonic() - sent, proc.returncode, worker, any(root.iterdir())


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--graph", default="M3500")
    ap.add_argument("--outliers", type=int, default=1000)
    ap.add_argument("--outlier-kind", default="random")
    ap.add_argument("--robust", default="none")
    ap.add_argument("--delays", type=float, nargs="+", default=[1, 3, 5, 8, 12, 16])
    args = ap.parse_args()
    latencies = []
    print("| delay after the folder appears (s) | SIGTERM to exit (s) | exit | worker running | folder left |")
    print("|---:|---:|---:|---|---|")
    with tempfile.TemporaryDirectory() as tmp:
        for k, delay in enumerate(args.delays):
            options = ["--outliers", str(args.outliers), "--outlier-kind", args.outlier_kind, "--robust", args.robust]
            s, code, worker, left = one(DATA / "posegraphs" / f"{args.graph}.g2o", options, delay, Path(tmp) / str(k))
            latencies.append(s)
            print(f"| {delay:g} | {s:.3f} | {code} | {'yes' if worker else 'no'} | {'yes' if left else 'no'} |",
                  flush=True)
    print(f"\nmedian {statistics.median(latencies):.3f} s, max {max(latencies):.3f} s over {len(latencies)} signals")


if __name__ == "__main__":
    main()
