"""Exploration benchmark: every strategy explores the same worlds from the same seeded starts, with online
SLAM in the loop; coverage, efficiency, the simplified hybrid map and path repetition as tables.

Usage: nice .venv/bin/python benchmarks/exploration.py [--worlds office rooms] [--rooms NAME ...]
       [--furniture both|with|without] [--seeds N] [--first-seed K] [--strategies ...] [--workers W] [--max-time S]
       [--log FILE] [--tables LOG [LOG ...] [--figure PNG] [--subject STRATEGY]]

Each run is ``slam2d explore`` without the results folder (``slam2d.exploration.loop.explore``). Worlds:
the office, and the room plans of ``$SLAM2D_DATA/rooms/`` (0.05 m/px; ``--rooms`` picks some by name,
``--furniture`` the furnished and / or unfurnished plans). The seed picks the start (a free place 0.5 m
from walls inside the building) and the noise; every strategy starts from the same place for a seed.
Each finished run is appended to the log (JSON lines), so that ``--tables LOG ...`` redraws the tables (of
several logs: a later run of a world, seed and strategy replaces an earlier one); ``--figure PNG`` draws
their spread over worlds and seeds.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import statistics
import sys
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path

from slam2d.exploration.config import STRATEGIES

REFERENCES = ("nearest_frontier", "explore_lite")  # what the utility is compared with
TARGETS = {"nearest_frontier": 0.85, "explore_lite": 0.90}  # the utility's distance to 99 % over each, at most
ROOMS = ("Freiburg52_scan", "Freiburg79_scan", "lab_b_scan", "lab_c_scan", "lab_d_scan", "lab_ipa", "office_a",
         "office_b", "office_c", "office_d")  # fmt: skip


def worlds(names: list[str], rooms: list[str], furniture: str) -> list[str]:
    data = Path(os.environ.get("SLAM2D_DATA", "../shared/datasets")) / "rooms"
    out = []
    for name in names:
        if name != "rooms":
            out.append(name)
            continue
        for room in rooms or ROOMS:
            if furniture in ("both", "without"):
                out.append(str(data / f"{room}.png"))
            if furniture in ("both", "with"):
                out.append(str(data / f"{room}_furnitures.png"))
    return out


def one_run(world: str, strategy: str, seed: int, max_time: float) -> dict:
    from slam2d.exploration import config
    from slam2d.exploration.loop import explore

    cfg = config.load(None, {"dataset.simulator.world": world, "seed": seed, "exploration.strategy": strategy,
                             "exploration.max_time": max_time, "exploration.animation": False})  # fmt: skip
    m = explore(cfg).metrics
    return {k: (v if not hasattr(v, "item") else v.item()) for k, v in m.items()} | {"world_spec": world}


def med(values) -> float:
    values = [v for v in values if not math.isnan(v)]
    return statistics.median(values) if values else float("nan")


def fmt(x, digits=1) -> str:
    return "–" if math.isnan(x) else f"{x:.{digits}f}"


def tables(runs: list[dict], subject: str = "utility") -> str:
    """The tables of ``runs``; the per-world distances and the paired ratios are ``subject``'s over the others'."""
    out = []
    by = {s: [r for r in runs if r["strategy"] == s] for s in STRATEGIES if any(r["strategy"] == s for r in runs)}
    d99 = {s: med(r["distance_to_99"] for r in rs) for s, rs in by.items()}
    out.append("| strategy | runs | reached 99 % | premature stops | runs with a collision | median coverage | "
               "median map IoU | median distance to 90 % (m) | median distance to 99 % (m) | vs nearest frontier | "
               "vs explore_lite | median total distance (m) | median ATE (cm) | decision median / p95 (ms) | "
               "real-time factor |")  # fmt: skip
    out.append("|" + "---|" * 15)
    for s, rs in by.items():
        n = len(rs)
        reached = sum(r["coverage"] >= 0.99 for r in rs)
        ratio = {ref: fmt(d99[s] / d99[ref], 2) if ref in d99 and not math.isnan(d99[ref]) else "–"
                 for ref in REFERENCES}
        out.append(f"| {s} | {n} | {100 * reached / n:.0f} % | {sum(r['premature_stop'] for r in rs)} | "
                   f"{sum(r['collisions'] > 0 for r in rs)} | {100 * med(r['coverage'] for r in rs):.1f} % | "
                   f"{fmt(med(r['map_iou'] for r in rs), 3)} | {fmt(med(r['distance_to_90'] for r in rs))} | "
                   f"{fmt(d99[s])} | {ratio['nearest_frontier']} | {ratio['explore_lite']} | "
                   f"{fmt(med(r['distance'] for r in rs))} | {fmt(100 * med(r['ate_rmse'] for r in rs))} | "
                   f"{fmt(med(r['decision_ms_median'] for r in rs))} / {fmt(med(r['decision_ms_p95'] for r in rs))} | "
                   f"{fmt(med(r['real_time_factor'] for r in rs))} |")  # fmt: skip
    out.append("")
    out.append("| world | strategy | runs | coverage | distance to 90 % (m) | distance to 99 % (m) | total distance (m) | "
               "path repetition | map IoU | runs with a collision | escapes |")  # fmt: skip
    out.append("|" + "---|" * 11)
    for world in sorted({r["world"] for r in runs}):
        for s in STRATEGIES:
            rs = [r for r in runs if r["world"] == world and r["strategy"] == s]
            if rs:
                out.append(f"| {world} | {s} | {len(rs)} | {100 * med(r['coverage'] for r in rs):.1f} % | "
                           f"{fmt(med(r['distance_to_90'] for r in rs))} | {fmt(med(r['distance_to_99'] for r in rs))} | "
                           f"{fmt(med(r['distance'] for r in rs))} | {100 * med(r['path_repetition'] for r in rs):.0f} % | "
                           f"{fmt(med(r['map_iou'] for r in rs), 3)} | {sum(r['collisions'] > 0 for r in rs)} | "
                           f"{med(r.get('escapes', 0) for r in rs):.0f} |")  # fmt: skip
    out.append("")
    out.append("| world | strategy | runs | nodes made (every node added) | nodes kept (cached hybrid map) | kept |")
    out.append("|---|---|---|---|---|---|")
    for world in sorted({r["world"] for r in runs}):
        for s in ("nearest_candidate", "farthest_candidate", "utility"):
            rs = [r for r in runs if r["world"] == world and r["strategy"] == s]
            if rs:
                a, k = med(r["nodes_all"] for r in rs), med(r["nodes_final"] for r in rs)
                out.append(f"| {world} | {s} | {len(rs)} | {a:.0f} | {k:.0f} | {100 * k / a:.0f} % |")
    out.append("")
    trio = ("nearest_frontier", "explore_lite", "utility") if subject == "utility" else (
        "nearest_frontier", "utility", subject)  # fmt: skip
    out.extend(distances_by_world(runs, trio))
    out.extend(paired_ratios(runs, subject, REFERENCES + (("utility",) if subject != "utility" else ())))
    out.extend(per_run_safety(runs))
    out.append("| strategy | runs | median path repetition | median goals | median inaccessible goals |")
    out.append("|---|---|---|---|---|")
    for s, rs in by.items():
        out.append(f"| {s} | {len(rs)} | {100 * med(r['path_repetition'] for r in rs):.0f} % | "
                   f"{med(r['goals'] for r in rs):.0f} | {med(r['goals_inaccessible'] for r in rs):.0f} |")  # fmt: skip
    return "\n".join(out)


def distances_by_world(runs: list[dict], trio=("nearest_frontier", "explore_lite", "utility")) -> list[str]:
    """Per world and seed run by all of ``trio``: each one's distance to 90 / 99 % (the shortest to 99 % in bold)
    and in all, and the last one's distance to 99 % over each other's."""
    by = {(r["world"], r["seed"], r["strategy"]): r for r in runs}
    head = " | ".join(f"{s}: to 90 / 99 % (m)" for s in trio)
    out = [f"| world | seed | reachable area (m²) | {head} | in all (m) | {trio[-1]} ÷ {trio[0]}, ÷ {trio[1]} (99 %) |",
           "|" + "---|" * (len(trio) + 5)]
    for world, seed in sorted({(w, seed) for w, seed, _ in by}):
        rs = [by.get((world, seed, s)) for s in trio]
        if None in rs:
            continue
        d99 = [r["distance_to_99"] for r in rs]
        best = min(range(len(rs)), key=lambda i: math.inf if math.isnan(d99[i]) else d99[i])
        cells = [f"{fmt(r['distance_to_90'])} / " + (f"**{fmt(d)}**" if i == best else fmt(d))
                 for i, (r, d) in enumerate(zip(rs, d99))]  # fmt: skip
        ratios = ", ".join(fmt(d99[-1] / d, 2) for d in d99[:-1])
        totals = " / ".join(f"{r['distance']:.0f}" for r in rs)
        out.append(f"| {world} | {seed} | {rs[0]['reachable_area_m2']:.0f} | {' | '.join(cells)} | {totals} | {ratios} |")
    return out + [""]


def per_run_safety(runs: list[dict]) -> list[str]:
    """Per run: the online pose error (what the robot drove on against the truth: p95, max and when, the largest
    heading error) and the smallest clearance between the robot's disc and a wall or person, with the targets
    (p95 ≤ 10 cm, max ≤ 25 cm, clearance ≥ 5 cm) met or not; runs logged before these were measured show –."""
    head = ("| world | strategy | seed | pose error p95 / max (cm) | max at (s) | heading error max (°) | "
            "smallest clearance (cm) | coverage | targets met |")  # fmt: skip
    out = [head, "|" + "---|" * 9]
    nan = float("nan")
    for r in sorted(runs, key=lambda r: (r["world"], r["strategy"], r["seed"])):
        p95, worst, clear = r.get("pose_error_p95", nan), r.get("pose_error_max", nan), r["min_clearance"]
        met = "–" if math.isnan(p95) else ("yes" if p95 <= 0.10 and worst <= 0.25 and clear >= 0.05 else "no")
        out.append(f"| {r['world']} | {r['strategy']} | {r['seed']} | {fmt(100 * p95)} / {fmt(100 * worst)} | "
                   f"{fmt(r.get('pose_error_max_time', nan), 0)} | {fmt(r.get('heading_error_max_deg', nan))} | "
                   f"{fmt(100 * clear)} | {100 * r['coverage']:.1f} % | {met} |")  # fmt: skip
    return out + [""]


def paired(runs: list[dict], strategy: str, ref: str, level: int) -> list[tuple[str, int, float]]:
    """(world, seed, ``strategy``'s distance to ``level`` % coverage ÷ ``ref``'s) for every world and seed where
    both runs reached that coverage."""
    d = {(r["world"], r["seed"], r["strategy"]): r[f"distance_to_{level}"] for r in runs}
    return [(w, seed, v / d[(w, seed, ref)]) for (w, seed, s), v in d.items()
            if s == strategy and not math.isnan(v) and not math.isnan(d.get((w, seed, ref), math.nan))]  # fmt: skip


def paired_ratios(runs: list[dict], strategy: str = "utility", refs=REFERENCES) -> list[str]:
    """The table of ``strategy``'s distance to 90 and 99 % over each of ``refs``' on the same world and seed: median,
    quartiles and range over the pairs where both reached that coverage, and how many pairs it was shorter in."""
    out = [f"| {strategy} ÷ | to | pairs (world, seed) | median | quartiles | range | shorter in |",
           "|---|---|---|---|---|---|---|"]
    for ref in refs:
        for level in (90, 99):
            ratios = [x for _, _, x in paired(runs, strategy, ref, level)]
            if len(ratios) < 2:
                continue
            q = statistics.quantiles(ratios, n=4)
            out.append(f"| {ref} | {level} % | {len(ratios)} | {statistics.median(ratios):.2f} | "
                       f"{q[0]:.2f}–{q[2]:.2f} | {min(ratios):.2f}–{max(ratios):.2f} | {sum(x < 1 for x in ratios)} |")  # fmt: skip
    return out + [""]


def figure(runs: list[dict], path: str, strategy: str = "utility") -> None:
    """Draw the spread over worlds and seeds to ``path`` (PNG): left, ``strategy``'s distance to 90 and 99 % over
    each reference's, pair by pair (box: quartiles; dashed: the targets at 99 %, ``TARGETS``); right, every
    run's distance to 99 % against the world's reachable area."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    fig, (left, right) = plt.subplots(1, 2, figsize=(11, 4.3))
    jitter = np.random.default_rng(0)
    for i, (ref, level) in enumerate((ref, level) for ref in REFERENCES for level in (90, 99)):
        pairs = paired(runs, strategy, ref, level)
        x = np.array([v for _, _, v in pairs])
        furnished = np.array(["furnitures" in w for w, _, _ in pairs], dtype=bool)
        if len(x):
            left.boxplot(x, positions=[i], widths=0.55, showfliers=False, medianprops={"color": "black"})
        for mask, colour in ((~furnished, "tab:blue"), (furnished, "tab:orange")):
            left.scatter(i + jitter.uniform(-0.2, 0.2, mask.sum()), x[mask], s=9, alpha=0.6, color=colour, zorder=3)
        if level == 99:
            left.hlines(TARGETS[ref], i - 0.35, i + 0.35, colors="tab:red", linestyles="--", zorder=4)
    left.axhline(1.0, color="grey", lw=0.8)
    left.set_yscale("log")
    left.set_yticks([0.5, 0.6, 0.7, 0.85, 1.0, 1.2, 1.5, 2.0], ["0.5", "0.6", "0.7", "0.85", "1", "1.2", "1.5", "2"])
    left.minorticks_off()
    left.set_xticks(range(4), [f"÷ {ref}\nto {level} %" for ref in REFERENCES for level in (90, 99)], fontsize=8)
    left.set_ylabel(f"{strategy}'s distance ÷ the other's (same world, seed)")
    left.scatter([], [], s=9, color="tab:blue", label="unfurnished")
    left.scatter([], [], s=9, color="tab:orange", label="furnished")
    left.plot([], [], "--", color="tab:red", label="target")
    left.legend(fontsize=8)
    for s in STRATEGIES:
        rs = [r for r in runs if r["strategy"] == s and not math.isnan(r["distance_to_99"])]
        if rs:
            right.scatter([r["reachable_area_m2"] for r in rs], [r["distance_to_99"] for r in rs], s=10, alpha=0.6,
                          label=f"{s} ({len(rs)})")  # fmt: skip
    right.set_xscale("log")
    right.set_yscale("log")
    right.minorticks_off()
    for axis, (lo, hi) in ((right.xaxis, right.get_xlim()), (right.yaxis, right.get_ylim())):
        ticks = [t for t in (10, 20, 50, 100, 200, 500, 1000, 2000) if lo <= t <= hi]
        axis.set_ticks(ticks, [str(t) for t in ticks])
    right.set_xlabel("reachable area (m²)")
    right.set_ylabel("distance to 99 % coverage (m)")
    right.legend(fontsize=8)
    seeds = sorted({r["seed"] for r in runs})
    fig.suptitle(f"{len({r['world'] for r in runs})} worlds, seed{'s' * (len(seeds) > 1)} {', '.join(map(str, seeds))}, "
                 f"{len(runs)} runs", fontsize=10)  # fmt: skip
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def read_logs(paths) -> list[dict]:
    """The runs of the logs ``paths`` (JSON lines), in order; a later run of the same world, seed and strategy
    replaces an earlier one (a re-run on newer code)."""
    runs = {}
    for path in paths:
        for line in Path(path).read_text().splitlines():
            if line.strip():
                r = json.loads(line)
                runs[r["world"], r["seed"], r["strategy"]] = r
    return list(runs.values())


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--worlds", nargs="+", default=["office", "rooms"])
    ap.add_argument("--rooms", nargs="*", default=[])
    ap.add_argument("--furniture", choices=["both", "with", "without"], default="both")
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--first-seed", type=int, default=0)
    ap.add_argument("--strategies", nargs="+", default=list(STRATEGIES), choices=STRATEGIES)
    ap.add_argument("--workers", type=int, default=1)
    ap.add_argument("--max-time", type=float, default=1800.0)
    ap.add_argument("--log", default="exploration_runs.jsonl")
    ap.add_argument("--tables", nargs="+", default=None, metavar="LOG",
                    help="only print the tables of these logs (a later run of a world, seed and strategy replaces an "
                         "earlier one)")  # fmt: skip
    ap.add_argument("--figure", metavar="PNG", help="with --tables: also draw the spread over worlds and seeds")
    ap.add_argument("--subject", default="utility", choices=STRATEGIES,
                    help="the strategy whose distances the per-world and paired tables set over the others'")
    a = ap.parse_args()
    if a.tables:
        runs = read_logs(a.tables)
        print(tables(runs, a.subject))
        if a.figure:
            figure(runs, a.figure)
        return
    jobs = [(w, s, seed, a.max_time) for w in worlds(a.worlds, a.rooms, a.furniture) for seed in range(a.first_seed, a.first_seed + a.seeds)
            for s in a.strategies]  # fmt: skip
    runs = []
    with ProcessPoolExecutor(a.workers) as pool, open(a.log, "a") as log:
        futures = {pool.submit(one_run, *job): job for job in jobs}
        for f in as_completed(futures):
            r = f.result()
            runs.append(r)
            log.write(json.dumps(r) + "\n")
            log.flush()
            print(f"  {r['world']} {r['strategy']} seed {r['seed']}: {r['stop_reason']}, coverage "
                  f"{100 * r['coverage']:.1f} %, {r['distance']:.0f} m, {r['wall_s']:.0f} s wall", file=sys.stderr,
                  flush=True)  # fmt: skip
    print(tables(runs, a.subject))


if __name__ == "__main__":
    main()
