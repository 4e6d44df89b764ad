"""Whole-process time of short slam2d commands beside Python's own start-up, in one run.

Each command runs ``--repeats`` times, interleaved with its peers (``python -c pass``,
``python -c "import numpy"``) so that a loaded machine slows all alike; the table gives
median wall and CPU seconds (the process and its children), and for the commands the
work they report themselves (segmentation ``seconds`` and ``cpu_seconds``; planning
``total_ms``, the planning without its figures), so that wall minus work (CPU minus work CPU on a
loaded machine) is the start-up, import and output overhead. The target: a command
doing about half a second of work returns within 1.5 s.

    SLAM2D_DATA=... nice .venv/bin/python benchmarks/command_startup.py [--repeats 5]
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
BIN = Path(sys.executable).parent
MAP = "rooms/office_a.png"


def commands(out: Path) -> dict[str, list[str]]:
    slam2d = str(BIN / "slam2d")
    return {
        "python -c pass": [sys.executable, "-c", "pass"],
        'python -c "import numpy"': [sys.executable, "-c", "import numpy"],
        "slam2d --help": [slam2d, "--help"],
        "slam2d segment MAP --method morphological": [slam2d, "segment", MAP, "--method", "morphological", "-q",
                                                      "-o", str(out)],
        "slam2d plan MAP --start 6,15.4 --goal 30,25.4": [slam2d, "plan", MAP, "--start", "6,15.4", "--goal", "30,25.4",
                                                      "-q", "-o", str(out)],
    }  # fmt: skip


def run_once(cmd: list[str], out: Path) -> tuple[float, float, float | None, float | None]:
    """(wall s, CPU s of the child, work s and work CPU s the command reported, or None)."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    done = subprocess.run(cmd, capture_output=True, text=True, cwd=ROOT)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if done.returncode != 0:
        sys.exit(f"{' '.join(cmd)} failed:\n{done.stderr[-2000:]}")
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    work = work_cpu = None
    folder = next((line.split(": ", 1)[1] for line in done.stdout.splitlines() if line.startswith("results: ")), None)
    if folder:
        metrics = json.loads((ROOT / folder / "metrics.json").read_text())
        work = metrics["seconds"] if "seconds" in metrics else metrics["total_ms"] / 1e3
        work_cpu = metrics.get("cpu_seconds")
    return wall, cpu, work, work_cpu


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=5)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory(prefix="slam2d-startup-") as tmp:
        cmds = commands(Path(tmp))
        for cmd in cmds.values():  # warm the file cache and numba's cache once
            run_once(cmd, Path(tmp))
        times: dict[str, list[tuple]] = {name: [] for name in cmds}
        for _ in range(args.repeats):
            for name, cmd in cmds.items():
                times[name].append(run_once(cmd, Path(tmp)))
    print(f"medians of {args.repeats}, {os.cpu_count()} CPUs, load {os.getloadavg()[0]:.1f}\n")
    print("| command | wall s | CPU s | work s | wall - work s | work CPU s | CPU - work CPU s |")
    print("|---|---:|---:|---:|---:|---:|---:|")
    for name, rows in times.items():
        wall, cpu, work, work_cpu = ([r[i] for r in rows] for i in range(4))
        cells = [wall, cpu, work, [w - x for w, x in zip(wall, work) if x is not None], work_cpu,
                 [c - x for c, x in zip(cpu, work_cpu) if x is not None]]
        cells = [statistics.median(c) if c and None not in c else None for c in cells]
        print(f"| `{name}` | " + " | ".join("" if c is None else f"{c:.2f}" for c in cells) + " |")


if __name__ == "__main__":
    main()
