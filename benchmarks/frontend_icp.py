"""Frontend accuracy and speed on the Radish logs: odometry vs the ICP frontend.

Chains each frontend's deltas into a trajectory and scores it with the
relations metric (Kümmerle et al. 2009) over all relations and over the
relations whose endpoints are less than 10 s apart (what a frontend controls):
mean ± std of the translational (m) and |rotational| (deg) error. Time is the
CPU time of the frontend alone (bag reading excluded), one thread.

    .venv/bin/python benchmarks/frontend_icp.py [--data DIR] [--datasets intel aces]
        [--methods point_to_line point_to_point] [--set key=value ...] [--max-scans N]
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

import numpy as np
import yaml

from slam2d import geometry
from slam2d.datasets.rosbag import RosbagSource
from slam2d.evaluation.relations import Relations, read_relations, relations_metric
from slam2d.frontends import create_frontend
from slam2d.frontends.icp import STILL_EVENT

SHORT = 10.0  # s; relations shorter than this measure local accuracy
DEFAULT_DATA = Path(os.environ.get("SLAM2D_DATA", Path(__file__).resolve().parents[1] / ".." / "shared" / "datasets"))


def odometry_deltas(scans) -> np.ndarray:
    """(N, 3) base motion between consecutive scans from their odometry poses (first: zeros)."""
    odom = np.array([s.odom for s in scans])
    return np.vstack([np.zeros(3), geometry.between(odom[:-1], odom[1:])])


def chain(deltas: np.ndarray) -> np.ndarray:
    """Poses (N, 3) from consecutive deltas, starting at the origin."""
    poses = np.zeros_like(deltas)
    for k in range(1, len(deltas)):
        poses[k] = geometry.compose(poses[k - 1], deltas[k])
    return poses


def run_frontend(scans, options: dict) -> tuple[np.ndarray, float, object]:
    """Deltas (N, 3), CPU time (s, this process) and the frontend after processing ``scans``."""
    frontend = create_frontend("icp", options)
    odom = odometry_deltas(scans)
    out = np.zeros_like(odom)
    start = time.process_time()
    for k, scan in enumerate(scans):
        out[k] = frontend.process(scan, odom[k]).delta
    return out, time.process_time() - start, frontend


def subset(rel: Relations, mask: np.ndarray) -> Relations:
    return Relations(rel.t1[mask], rel.t2[mask], rel.delta[mask])


def score(stamps, poses, rel: Relations) -> dict:
    """Relations metric over all relations and over those shorter than SHORT seconds."""
    short = subset(rel, np.abs(rel.t2 - rel.t1) < SHORT)
    full, near = relations_metric(stamps, poses, rel), relations_metric(stamps, poses, short)
    return {
        "trans": (full["trans_abs_mean"], full["trans_abs_std"]),
        "rot": (full["rot_abs_mean"], full["rot_abs_std"]),
        "short_trans": (near["trans_abs_mean"], near["trans_abs_std"]),
        "short_rot": (near["rot_abs_mean"], near["rot_abs_std"]),
        "n": (full["matched"], near["matched"]),
    }


def row(name: str, label: str, m: dict, seconds: float | None, n_scans: int, fallbacks: int | str) -> str:
    t, r, st, sr = m["trans"], m["rot"], m["short_trans"], m["short_rot"]
    secs = "-" if seconds is None else f"{seconds:7.1f}"
    per = "-" if seconds is None else f"{1e3 * seconds / n_scans:5.2f}"
    return (
        f"| {name:6} | {label:24} | {t[0]:.4f} ± {t[1]:.4f} | {r[0]:.3f} ± {r[1]:.3f} "
        f"| {st[0]:.4f} ± {st[1]:.4f} | {sr[0]:.3f} ± {sr[1]:.3f} | {secs} | {per} | {fallbacks} |"
    )


HEADER = (
    "| data   | estimate                 | trans all (m)   | rot all (deg) | trans <10 s (m) | rot <10 s (deg) "
    "| cpu (s) | ms/scan | fallbacks |\n|---|---|---|---|---|---|---|---|---|"
)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=DEFAULT_DATA)
    ap.add_argument("--datasets", nargs="+", default=["intel", "aces"])
    ap.add_argument("--methods", nargs="+", default=["point_to_line", "point_to_point"])
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="frontend option override")
    ap.add_argument("--max-scans", type=int, default=None)
    args = ap.parse_args()
    overrides = {k: yaml.safe_load(v) for k, v in (s.split("=", 1) for s in args.set)}
    print(HEADER)
    for name in args.datasets:
        scans = list(RosbagSource(args.data / "radish" / f"{name}.bag", max_scans=args.max_scans))
        stamps = np.array([s.stamp for s in scans])
        rel = read_relations(args.data / "radish" / f"{name}.relations")
        odom = chain(odometry_deltas(scans))
        print(row(name, "odometry", score(stamps, odom, rel), None, len(scans), "-"))
        for method in args.methods:
            deltas, seconds, fe = run_frontend(scans, {"method": method, **overrides})
            fb = sum(v for k, v in fe.events.items() if k != STILL_EVENT)
            print(row(name, f"icp {method}", score(stamps, chain(deltas), rel), seconds, len(scans), fb), flush=True)
            for reason, count in fe.events.items():
                print(f"    {reason}: {count}")


if __name__ == "__main__":
    main()
