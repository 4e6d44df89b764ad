"""Monte Carlo localisation: slam2d's filter beside a re-implementation of ROS amcl's defaults,
on the office and the room plans, global localisation, kidnapping and tracking.

Usage: nice .venv/bin/python benchmarks/localization.py [--worlds office rooms ring wings] [--runs N] [--first-seed 0]
       [--workers 2] [--scenarios global active kidnap active_kidnap tracking] [--filters slam2d amcl amcl_recovery]
       [--out results/bench-localization]

Every seeded run records one stream of the wandering robot (scans, odometry,
truth) and replays it through every filter, so that all see the same data:
- global: no initial pose, 40 s of driving; converged = state tracking with an error < 0.2 m
  and < 5 deg held for 5 s, counted when it starts within 10 m of travel; a false
  convergence is the state tracking more than 0.5 m wrong for 5 s (any scenario); the
  state at the end (tracking / ambiguous / lost) is counted;
- active: global localisation (slam2d's filter) with active moves: the same start, but while
  the filter is ambiguous the robot drives towards the places that tell its hypotheses apart
  (slam2d.localization.active.Looker), so the stream is its own; counted as global;
- kidnap: tracking from the true pose (sd 0.1 m, 3 deg) for 10 s, then a teleport of
  at least 5 m; recovered = converged again within 15 s of driving;
- active_kidnap: kidnap (slam2d's filter) with active moves: the same start and teleport, but while
  the filter is ambiguous after it the robot drives as in active; counted as kidnap;
- tracking: from the true pose with the rough initial spread (0.5 m, 15 deg), 60 s;
  RMSE and median particle count from convergence on.
Filters: slam2d (defaults), amcl (ROS 1 defaults, recovery off as shipped),
amcl_recovery (recovery_alpha_slow / fast 0.001 / 0.1). Each row also has, at the end, the rank of the
hypothesis holding the true pose (truth_rank, null: none does), the number of hypotheses and the evidence
of the best over the runner-up (null: none). Rows go to runs.jsonl, the
summary (medians and rates per world and filter) to table.md, followed by the success of the global and
kidnap scenarios raw and with the runs that end ambiguous at a look-alike place of the map's analysis (and
are no success) counted apart, as the targets count them: the true pose at the end held by a hypothesis and
in a transform's region (lookalikes_at_end), or where the laser sees the same at it and at its image
(seen_alike_at_end).
"""

from __future__ import annotations

import argparse
import functools
import json
import math
import os
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

FILTERS = {"global": ["slam2d", "amcl", "amcl_recovery"], "kidnap": ["slam2d", "amcl", "amcl_recovery"],
           "tracking": ["slam2d", "amcl"], "active": ["slam2d"], "active_kidnap": ["slam2d"]}  # fmt: skip
SECONDS = {"global": 40.0, "kidnap": 30.0, "tracking": 60.0, "active": 40.0, "active_kidnap": 30.0}
ACTIVE = {"active": "global", "active_kidnap": "kidnap"}  # scenarios whose robot drives for the filter: as which counted
KIDNAP_AT = 10.0  # s
GLOBAL_TRAVEL = 10.0  # m
RECOVERY = 15.0  # s


def _ring() -> np.ndarray:
    """A square ring corridor (22 m outside, 2.5 m wide) whose four sides, boxes included, are alike."""
    g = np.full((440, 440), 205, np.uint8)
    g[20:420, 20:420] = 0
    g[24:416, 24:416] = 255
    g[74:366, 74:366] = 0
    g[78:362, 78:362] = 205
    g[24:40, 100:124] = 0  # a cupboard on the outer wall of each side
    g[55:65, 250:262] = 0  # a pillar
    return np.min([np.rot90(g, k) for k in range(4)], axis=0)


def _wings() -> np.ndarray:
    """A U-shaped plan: two identical wings (a 3.1 m corridor, three furnished rooms off its west side)
    17.5 m apart, joined at their south ends by a corridor."""
    g = np.full((400, 640), 205, np.uint8)
    for c0 in (120, 470):
        g[20:380, c0:c0 + 70] = 0
        g[24:376, c0 + 4:c0 + 66] = 255
        for r0, r1 in ((100, 180), (190, 280), (290, 370)):
            g[r0:r1, c0 - 100:c0 + 4] = 0
            g[r0 + 4:r1 - 4, c0 - 96:c0] = 255
            g[r0 + 20:r0 + 40, c0:c0 + 4] = 255  # the door
            g[r0 + 10:r0 + 24, c0 - 90:c0 - 60] = 0  # a desk
        g[120:136, c0 - 40:c0 - 24] = 0  # a cupboard in the first room
    g[20:90, 120:540] = 0
    g[24:86, 124:536] = 255
    for c0 in (120, 470):
        g[24:376, c0 + 4:c0 + 66] = 255  # each wing opens onto the joining corridor
    return g


SYNTHETIC = {"ring": _ring, "wings": _wings}  # plans made here (0.05 m/px), never used to tune the filter


def world_specs(names: list[str], folder: Path | None = None) -> list[str]:
    """'office', 'rooms' (the furnished plans of SLAM2D_DATA/rooms), 'ring' / 'wings' (plans written to
    ``folder``) or PNG paths."""
    out = []
    for name in names:
        if name in SYNTHETIC:
            from PIL import Image

            path = (folder or Path(".")) / f"{name}.png"
            path.parent.mkdir(parents=True, exist_ok=True)
            Image.fromarray(SYNTHETIC[name]()[::-1]).save(path)
            out.append(str(path))
        elif name == "rooms":
            data = Path(os.environ.get("SLAM2D_DATA", Path(__file__).resolve().parents[1] / ".." / "shared" /
                                       "datasets")) / "rooms"  # fmt: skip
            out += sorted(str(p) for p in data.glob("*_furnitures.png"))
        else:
            out.append(name)
    return out


@functools.lru_cache(maxsize=2)
def _load(spec: str):
    from slam2d.localization import KnownMap
    from slam2d.sim.world import load_world

    world = load_world(spec)
    return world, (KnownMap.from_world(world) if spec == "office" else KnownMap.load(spec))


def _finite(x: float) -> float | None:
    """``x``, None when infinite (JSON has no infinity)."""
    return float(x) if math.isfinite(x) else None


def run_one(spec: str, scenario: str, seed: int, filters: tuple[str, ...] = ()) -> list[dict]:
    """One seeded stream of ``scenario`` in world ``spec`` replayed through its filters (those of them
    in ``filters`` if given); one row per filter."""
    from slam2d.localization import ParticleFilter, preset
    from slam2d.localization.scenario import (
        PERIOD,
        active_run,
        converged_at,
        false_convergence,
        final_state,
        replay,
        truth_rank,
        wander,
    )

    world, known = _load(spec)
    kind = ACTIVE.get(scenario, scenario)
    kidnap = [KIDNAP_AT] if kind == "kidnap" else []
    seconds = PERIOD if scenario in ACTIVE else SECONDS[scenario]  # the active robot drives its own stream
    stream = wander(world, known, seconds, seed, kidnap_at=kidnap)
    rows = []
    for name in [f for f in FILTERS[scenario] if not filters or f in filters]:
        pf = ParticleFilter(known, preset(name), stream.scans[0].range_max, seed=seed)
        if kind == "global":
            pf.init_global()
        elif kind == "kidnap":
            pf.init_pose(stream.truth[0], 0.1, math.radians(3.0))
        else:
            pf.init_pose(stream.truth[0])
        t0 = time.perf_counter()
        if scenario in ACTIVE:
            stream, track = active_run(world, known, pf, SECONDS[scenario], seed, kidnap_at=kidnap)
        else:
            track = replay(pf, stream)
        row = {"world": Path(spec).stem.replace("_furnitures", ""), "scenario": scenario, "filter": name,
               "seed": seed, "wall_s": time.perf_counter() - t0,
               "update_ms": float(np.median(track.update_ms)) if len(track.update_ms) else None,
               "false": bool(false_convergence(track)), "end_state": final_state(track),
               "lookalikes_at_end": None if pf.lookalikes is None else len(pf.lookalikes.at(stream.truth[-1])),
               "seen_alike_at_end": None if pf.lookalikes is None else len(pf.lookalikes.seen(stream.truth[-1],
                                                                                             pf.range_max)),
               "truth_end": [float(v) for v in stream.truth[-1]],
               "truth_rank": truth_rank(pf.estimate.hypotheses, stream.truth[-1]),
               "hypotheses": len(pf.estimate.hypotheses), "evidence": _finite(pf.estimate.evidence)}  # fmt: skip
        if kind == "global":
            c = converged_at(track)
            row.update(converged=bool(c is not None and stream.travelled[c] <= GLOBAL_TRAVEL),
                       travel=None if c is None else float(stream.travelled[c]),
                       max_particles=int(track.particles.max()))
        elif kind == "kidnap":
            k = stream.kidnaps[0]
            c = converged_at(track, k)
            row.update(recovered=bool(c is not None and (c - k) * PERIOD <= RECOVERY),
                       recovery_s=None if c is None else (c - k) * PERIOD,
                       jump=float(np.hypot(*(stream.truth[k, :2] - stream.truth[k - 1, :2]))))  # fmt: skip
        else:
            c = converged_at(track)
            after = slice(c if c is not None else len(stream.scans), None)
            e, h = track.position_error[after], track.heading_error[after]
            row.update(converged=c is not None,
                       rmse=float(np.sqrt(np.mean(e**2))) if len(e) else None,
                       heading_rmse_deg=float(np.degrees(np.sqrt(np.mean(h**2)))) if len(h) else None,
                       particles=float(np.median(track.particles[after])) if len(e) else None)  # fmt: skip
        rows.append(row)
    return rows


def _rate(rows, key) -> str:
    return f"{100.0 * sum(bool(r[key]) for r in rows) / len(rows):.0f} %" if rows else "-"


def _median(rows, key, fmt="{:.3f}") -> str:
    v = [r[key] for r in rows if r.get(key) is not None]
    return fmt.format(float(np.median(v))) if v else "-"


def _states(rows) -> str:
    """End states: tracking / ambiguous / lost counts."""
    return " / ".join(str(sum(r.get("end_state") == s for r in rows)) for s in ("tracking", "ambiguous", "lost"))


def _count(rows, key) -> str:
    return f"{sum(bool(r.get(key)) for r in rows)}" if rows else "-"


SUCCESS = {"global": "converged", "active": "converged", "kidnap": "recovered", "active_kidnap": "recovered"}


def _alike(row: dict, seen: bool) -> bool:
    """Whether the run's true pose at the end lies at a look-alike place of the map's analysis: in a
    transform's region (walls within its radius), or with ``seen`` also where the laser sees the same at
    the pose and at its image (LookAlikes.seen)."""
    return bool(row.get("lookalikes_at_end")) or (seen and bool(row.get("seen_alike_at_end")))


def _predicted(rows) -> str:
    """Runs ending ambiguous whose true pose lies at a look-alike place of the map's analysis (:func:`_alike`: its
    regions or what the laser sees) / all ending ambiguous."""
    amb = [r for r in rows if r.get("end_state") == "ambiguous"]
    return f"{sum(_alike(r, True) for r in amb)} / {len(amb)}" if amb else "-"


def apart(rows: list[dict], key: str, seen: bool = True) -> tuple[int, int, int]:
    """(successes, runs, runs set apart) of ``rows`` by ``key`` (converged / recovered): a run that is no
    success and ends ``ambiguous`` with its true pose at a look-alike place (:func:`_alike`) and held by one
    of the hypotheses (``truth_rank``) is set apart (the filter reported what the plan cannot tell, as the
    issue's targets count it), not a failure."""
    won = sum(bool(r.get(key)) for r in rows)
    alike = sum(not r.get(key) and r.get("end_state") == "ambiguous" and r.get("truth_rank") is not None
                and _alike(r, seen) for r in rows)  # fmt: skip
    return won, len(rows), alike


def _share(won: int, runs: int) -> str:
    return f"{won} / {runs} ({100.0 * won / runs:.1f} %)" if runs else "-"


def counting(rows: list[dict]) -> str:
    """Markdown: global and kidnap success per scenario and filter, all worlds pooled and per world, raw and
    with the runs ending ambiguous at a look-alike place counted apart (:func:`apart`): by the analysis's
    regions alone, and by its regions or what the laser sees."""
    lines = [("| world | filter | scenario | success (raw) | not a success, ambiguous at a look-alike: region / "
              "region or seen | success, those apart (region) | success, those apart (region or seen) | "
              "not a success, elsewhere | false |"), "|" + "---|" * 9]  # fmt: skip
    for world in ["all", *sorted({r["world"] for r in rows})]:
        for name in [n for n in FILTERS["global"] if any(r["filter"] == n for r in rows)]:
            for scenario, key in SUCCESS.items():
                sel = [r for r in rows if r["filter"] == name and r["scenario"] == scenario
                       and world in ("all", r["world"])]  # fmt: skip
                if not sel:
                    continue
                won, runs, region = apart(sel, key, seen=False)
                alike = apart(sel, key)[2]
                lines.append(f"| {world} | {name} | {scenario} | {_share(won, runs)} | {region} / {alike} | "
                             f"{_share(won, runs - region)} | {_share(won, runs - alike)} | {runs - alike - won} | "
                             f"{_count(sel, 'false')} |")  # fmt: skip
    return "\n".join(lines) + "\n"


def table(rows: list[dict]) -> str:
    """Markdown: per filter, all worlds pooled and per world."""
    worlds = sorted({r["world"] for r in rows})
    lines = [("| world | filter | global converged ≤ 10 m | global end tracking / ambiguous / lost | with active moves "
              "converged ≤ 10 m | active end t / a / l | active median travel (m) | false conv. "
              "global / active / kidnap / active kidnap / tracking | ambiguous at a look-alike | median travel (m) | "
              "kidnap recovered ≤ 15 s | kidnap end t / a / l | median recovery (s) | active kidnap recovered ≤ 15 s | "
              "active kidnap end t / a / l | active median recovery (s) | tracking RMSE (m) | heading RMSE (°) | "
              "particles tracking | ms/update | runs |"),
             "|" + "---|" * 22]  # fmt: skip
    for world in ["all", *worlds]:
        for name in [n for n in FILTERS["global"] if any(r["filter"] == n for r in rows)]:
            sel = [r for r in rows if r["filter"] == name and world in ("all", r["world"])]
            g, a, k, ak, t = ([r for r in sel if r["scenario"] == s] for s in
                              ("global", "active", "kidnap", "active_kidnap", "tracking"))  # fmt: skip
            false = " / ".join(_count(x, "false") for x in (g, a, k, ak, t))
            lines.append(f"| {world} | {name} | {_rate(g, 'converged')} | {_states(g) if g else '-'} | "
                         f"{_rate(a, 'converged')} | {_states(a) if a else '-'} | {_median(a, 'travel', '{:.1f}')} | "
                         f"{false} | {_predicted(sel)} | {_median(g, 'travel', '{:.1f}')} | "
                         f"{_rate(k, 'recovered')} | {_states(k) if k else '-'} | {_median(k, 'recovery_s', '{:.1f}')} | "
                         f"{_rate(ak, 'recovered')} | {_states(ak) if ak else '-'} | "
                         f"{_median(ak, 'recovery_s', '{:.1f}')} | {_median(t, 'rmse')} | "
                         f"{_median(t, 'heading_rmse_deg', '{:.2f}')} | {_median(t, 'particles', '{:.0f}')} | "
                         f"{_median(sel, 'update_ms', '{:.1f}')} | {max(len(g), len(a), len(k), len(ak), len(t))} |")  # fmt: skip
    return "\n".join(lines) + "\n"


def main(argv: list[str]) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--worlds", nargs="+", default=["office", "rooms"])
    ap.add_argument("--runs", type=int, default=10, help="seeded runs per world and scenario")
    ap.add_argument("--first-seed", type=int, default=0, help="seeds first-seed ... first-seed + runs - 1")
    ap.add_argument("--scenarios", nargs="+", default=["global", "kidnap", "tracking"])
    ap.add_argument("--filters", nargs="+", default=[], help="only these filters (default: all)")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--out", default="results/bench-localization")
    args = ap.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    seeds = range(args.first_seed, args.first_seed + args.runs)
    jobs = [(w, s, seed, tuple(args.filters)) for w in world_specs(args.worlds, out / "plans") for s in args.scenarios
            for seed in seeds]  # fmt: skip
    rows: list[dict] = []
    t0 = time.perf_counter()
    os.environ.setdefault("NUMBA_NUM_THREADS", "1")  # one thread per worker process
    with ProcessPoolExecutor(args.workers) as pool, open(out / "runs.jsonl", "w") as f:
        for n, result in enumerate(pool.map(run_one, *zip(*jobs)), start=1):
            rows += result
            f.writelines(json.dumps(r) + "\n" for r in result)
            f.flush()
            if n % 10 == 0 or n == len(jobs):
                print(f"{n}/{len(jobs)} runs, {time.perf_counter() - t0:.0f} s", flush=True)
    text = table(rows) + "\n" + counting(rows)
    (out / "table.md").write_text(text)
    print(text)


if __name__ == "__main__":
    main(sys.argv[1:])
