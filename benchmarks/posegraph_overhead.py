"""The whole ``slam2d optimize`` command on clean graphs beside a bare GTSAM script, in one run; with
``--outliers``, the command under injected false loops beside the same command on the clean graph.

The bare script: ``import gtsam``, ``readG2o``, a tight prior on the first pose, GTSAM's
``LevenbergMarquardtOptimizer`` with default parameters, the error printed. The command:
``slam2d optimize GRAPH`` with its defaults (chordal start, verification: SE-Sync's certificate,
and a second start only when it does not hold; graph.g2o, edges.csv, overlay.png, metrics.json). Both run as fresh
processes, interleaved ``--repeats`` times so that a loaded machine slows both alike; the table
gives the median wall time (min-max beside it), the ratio of the medians, and the median of each
step's wall time as the command records it in ``metrics.json`` (``timings``; "other" is the
process's wall time not in a step: interpreter start, imports, the results folder).

    SLAM2D_DATA=... nice .venv/bin/python benchmarks/posegraph_overhead.py [--graphs M3500 intel MIT CSAIL]
        [--repeats 5]
    SLAM2D_DATA=... nice .venv/bin/python benchmarks/posegraph_overhead.py --graphs intel CSAIL M3500 --repeats 3 \
        --outliers 100 1000 --kinds random local group --methods pc_dcs gnc

Every process reads and writes its bytecode under a temporary ``PYTHONPYCACHEPREFIX`` (warmed by one untimed
run of each), as an installed package runs: where ``PYTHONDONTWRITEBYTECODE`` is set, slam2d's modules would
be compiled anew in every run (+0.1-0.2 s), the bare script's gtsam and numpy not.

``--against DIR`` also runs another checkout's command (``PYTHONPATH=DIR``, from DIR), interleaved with
the others, for before / after figures measured in one run.

With ``--outliers`` every robust command (``--robust METHOD --outliers N --outlier-kind KIND --seed 1``)
runs interleaved with the clean command (plain least squares, the defaults); the table gives each one's
median wall time, its ratio to the clean command's median (issue 54's bound: 10 x), and from its
``metrics.json`` the false loops rejected, the true loops kept and whether it verified and certified.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

DATA = Path(os.environ.get("SLAM2D_DATA", Path(__file__).resolve().parents[1] / ".." / "shared" / "datasets"))
BARE = """
import sys, gtsam
graph, initial = gtsam.readG2o(sys.argv[1], False)
first = initial.keys()[0]
graph.add(gtsam.PriorFactorPose2(first, initial.atPose2(first), gtsam.noiseModel.Diagonal.Sigmas([1e-6] * 3)))
result = gtsam.LevenbergMarquardtOptimizer(graph, initial, gtsam.LevenbergMarquardtParams()).optimize()
print(graph.error(result))
"""


def spread(xs: list[float]) -> str:
    return f"{statistics.median(xs):.2f} ({min(xs):.2f}-{max(xs):.2f})"


def wall(cmd: list[str], checkout: Path | None = None) -> float:
    """Wall time (s) of a process (with ``checkout``: its slam2d, run from there); raises if it fails."""
    env = None if checkout is None else {**os.environ, "PYTHONPATH": str(checkout)}
    t0 = time.perf_counter()
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, env=env, cwd=checkout)
    return time.perf_counter() - t0


def command(path: str, out: Path, extra: list[str], checkout: Path | None = None) -> tuple[float, dict]:
    """Wall time (s) and metrics.json of ``slam2d optimize PATH`` with ``extra`` options into ``out``."""
    took = wall([sys.executable, "-m", "slam2d.cli", "optimize", path, "--out", str(out), "-q", *extra], checkout)
    return took, json.loads(next(out.glob("*/metrics.json")).read_text())


def warm_up(tmp: str, path: str, checkouts) -> None:
    """Bytecode under ``tmp`` for every process of this run (see the module), compiled by one untimed run of the
    bare script and of each checkout's command."""
    os.environ.pop("PYTHONDONTWRITEBYTECODE", None)
    os.environ["PYTHONPYCACHEPREFIX"] = str(Path(tmp) / "pycache")
    wall([sys.executable, "-c", BARE, path])
    for k, checkout in enumerate(checkouts):
        command(path, Path(tmp) / f"warm-{k}", [], checkout)


def under_outliers(args) -> None:
    """The table of the robust commands under false loops against the clean command."""
    cases = [(m, n, k) for n in args.outliers for k in args.kinds for m in args.methods]
    print("| graph | method | false loops | wall s | x clean command | false rejected | true kept | verified, certified |")
    print("|---|---|---|---:|---:|---:|---:|---|")
    with tempfile.TemporaryDirectory() as tmp:
        warm_up(tmp, str(DATA / "posegraphs" / f"{args.graphs[0]}.g2o"), [None])
        for name in args.graphs:
            path = str(DATA / "posegraphs" / f"{name}.g2o")
            times: dict = {case: [] for case in [None, *cases]}
            last: dict = {}
            for r in range(args.repeats):
                for i, case in enumerate(times):
                    extra = [] if case is None else ["--robust", case[0], "--outliers", str(case[1]),
                                                     "--outlier-kind", case[2], "--seed", "1"]  # fmt: skip
                    took, last[case] = command(path, Path(tmp) / f"{name}-{r}-{i}", extra)
                    times[case].append(took)
            clean = statistics.median(times[None])
            print(f"| {name} | none (clean graph) | 0 | {spread(times[None])} | 1.0 | - | - | "
                  f"{last[None]['verified']}, {last[None]['certified']} |")
            for case in cases:
                m = last[case]
                print(f"| {name} | {case[0]} | {case[1]} {case[2]} | {spread(times[case])} | "
                      f"{statistics.median(times[case]) / clean:.1f} | {m.get('outliers_rejected', 0)} / {m.get('outliers_injected', 0)} | "
                      f"{100 * m.get('true_loops_kept', 1.0):.2f} % | {m['verified']}, {m['certified']} |", flush=True)  # fmt: skip


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--graphs", nargs="+", default=["M3500", "intel", "MIT", "CSAIL"])
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--outliers", type=int, nargs="+", help="false loops injected: the robust commands' table")
    ap.add_argument("--kinds", nargs="+", default=["random"])
    ap.add_argument("--methods", nargs="+", default=["pc_dcs", "gnc"])
    ap.add_argument("--against", type=Path, help="another checkout whose command runs interleaved (before / after)")
    args = ap.parse_args()
    if args.outliers:
        return under_outliers(args)
    rows = []
    checkouts = [None] + ([args.against.resolve()] if args.against else [])
    with tempfile.TemporaryDirectory() as tmp:
        warm_up(tmp, str(DATA / "posegraphs" / f"{args.graphs[0]}.g2o"), checkouts)
        for name in args.graphs:
            path = str(DATA / "posegraphs" / f"{name}.g2o")
            bare, runs = [], {c: ([], []) for c in checkouts}
            for r in range(args.repeats):
                bare.append(wall([sys.executable, "-c", BARE, path]))
                for k, (checkout, (ours, steps)) in enumerate(runs.items()):
                    took, metrics = command(path, Path(tmp) / f"{name}-{r}-{k}", [], checkout)
                    ours.append(took)
                    assert metrics["verified"] and metrics["certified"], metrics
                    steps.append(metrics["timings"])
            for checkout, (ours, steps) in runs.items():
                median = {k: statistics.median(s[k] for s in steps) for k in steps[0]}
                other = statistics.median(w - sum(s.values()) for w, s in zip(ours, steps))
                rows.append((name if checkout is None else f"{name} ({checkout})", spread(bare), spread(ours),
                             statistics.median(ours) / statistics.median(bare),
                             " ".join(f"{k} {v:.2f}" for k, v in median.items()) + f" other {other:.2f}"))
            print(f"{name}: done", file=sys.stderr, flush=True)
    print(f"\n{args.repeats} repeats, median (min-max) wall s\n")
    print("| graph | bare GTSAM LM script | slam2d optimize (verified, certified) | x bare | command's steps (median s) |")
    print("|---|---:|---:|---:|---|")
    for name, b, o, ratio, st in rows:
        print(f"| {name} | {b} | {o} | {ratio:.2f} | {st} |")


if __name__ == "__main__":
    main()
