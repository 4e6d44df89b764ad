"""Sessions that continue and merge on the Radish logs: a log cut into two halves, mapped as two sessions.

Usage: .venv/bin/python benchmarks/slam_sessions.py [aces intel fr079 fr-clinic csail]

For each log (experiments/<log>.yaml, the defaults), four `slam2d run`s in
fresh processes, as a user runs them:

- the single run over the whole log;
- the first half (``dataset.max_scans``: half the log's scans);
- the second half continuing it (``dataset.first_scan`` there, ``--continue``);
- the second half started at an unknown pose in the first half's map
  (``--localize-in``: placed by a global search, no odometry shared across the cut).

The table gives the relations metric (translational, absolute, over all of the
log's relations: the continued and merged runs' trajectories cover both halves)
of each, the ratio to the single run, the loops between the two sessions, the
global searches it took to place the second, and the wall clock.
"""

from __future__ import annotations

import argparse
import csv
import json
import re
import subprocess
import sys
import time
from pathlib import Path

from slam2d import config
from slam2d.datasets.registry import open_dataset
from slam2d.runs.slam_outputs import read_session

LOGS = ["aces", "intel", "fr079", "fr-clinic", "csail"]
ROOT = Path("results/bench-sessions")


def run(log: str, *args: str) -> dict:
    """metrics.json of one `slam2d run experiments/<log>.yaml ARGS` plus its folder and wall clock (s)."""
    cmd = [sys.executable, "-m", "slam2d.cli", "run", f"experiments/{log}.yaml", "-q", "-o", str(ROOT), *args]
    t0 = time.perf_counter()
    out = subprocess.run(cmd, capture_output=True, text=True, check=True).stdout
    wall = time.perf_counter() - t0
    folder = Path(re.search(r"results: (.+)", out).group(1).strip())
    return {"wall_s": wall, "folder": folder, **json.loads((folder / "metrics.json").read_text())}


def across(folder: Path, first_keyframes: int) -> int:
    """Loops kept in ``folder``'s graph that join a keyframe of the first session to one of the second."""
    with open(folder / "loops.csv") as f:
        rows = list(csv.DictReader(f))
    return sum(int(r["kept"]) and (int(r["keyframe_i"]) < first_keyframes) != (int(r["keyframe_j"]) < first_keyframes)
               for r in rows)  # fmt: skip


def trans(m: dict) -> str:
    r = m["relations"]
    return f"{r['trans_abs_mean']:.4f} ± {r['trans_abs_std']:.4f}"


def main(argv: list[str]) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("logs", nargs="*", help=f"some of {', '.join(LOGS)} (default: aces intel)")
    args = ap.parse_args(argv)
    unknown = set(args.logs) - set(LOGS)
    if unknown:
        ap.error(f"unknown log(s) {sorted(unknown)}; choose from {LOGS}")
    print("| log | scans, cut at | single run (m) | continued (m) | ratio | merged, unknown start (m) | ratio "
          "| loops across the cut: continued / merged | global searches to place | wall clock (s): single / "
          "first half / continued / merged |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for log in args.logs or ["aces", "intel"]:
        n = open_dataset(config.load(Path(f"experiments/{log}.yaml")).dataset).expected()
        cut = n // 2
        single = run(log, "--set", f"name={log}-single")
        first = run(log, "--set", f"name={log}-first", "--set", f"dataset.max_scans={cut}")
        k = read_session(first["folder"]).num_keyframes
        rest = ("--set", f"dataset.first_scan={cut}")
        cont = run(log, "--set", f"name={log}-continued", *rest, "--continue", str(first["folder"]))
        merged = run(log, "--set", f"name={log}-merged", *rest, "--localize-in", str(first["folder"]))
        base = single["relations"]["trans_abs_mean"]
        ratio = {m["folder"]: m["relations"]["trans_abs_mean"] / base for m in (cont, merged)}
        print(f"| {log} | {n}, {cut} | {trans(single)} | {trans(cont)} | {ratio[cont['folder']]:.3f} "
              f"| {trans(merged)} | {ratio[merged['folder']]:.3f} "
              f"| {across(cont['folder'], k)} / {across(merged['folder'], k)} "
              f"| {merged['slam'].get('loop_matcher_global_searches', 0)} "
              f"| {single['wall_s']:.1f} / {first['wall_s']:.1f} / {cont['wall_s']:.1f} / {merged['wall_s']:.1f} |",
              flush=True)  # fmt: skip


if __name__ == "__main__":
    main(sys.argv[1:])
