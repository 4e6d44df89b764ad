"""Which ground-truth relations the laser scans themselves contradict, and how much of the score they carry.

Usage: .venv/bin/python benchmarks/relations_audit.py [intel aces fr079 fr-clinic csail] [--results LOG=FOLDER ...]

For each log, slam2d's estimate (a results folder given with ``--results``,
else a fresh `slam2d run experiments/<log>.yaml`) and the relations file are
compared against the scans at both ends of every relation: scan 2's points
are placed in scan 1's frame by the relation's pose, and their median
distance to scan 1's nearest point is the *scan fit* (m) of that pose. A
relation whose ground-truth pose fits worse than ``CONTRADICTED_M`` and more
than ``RATIO`` times worse than the estimate's is one the scans contradict;
the reverse (the estimate contradicted where the ground truth fits) is
counted too. Pairs whose scans barely overlap (both fits above
``NO_OVERLAP_M``: a return facing the other way) are fitted again against
the scans around scan 1 (``LOCAL_MAP_S``) laid out by the estimate; those
still without overlap are reported apart: the scans say nothing about them.
Prints a table and, with ``--worst N``, the worst contradicted relations of
each log.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

sys.path.insert(0, str(Path(__file__).resolve().parent))
from slam_radish import PUBLISHED, run

from slam2d import geometry
from slam2d.config import load as load_config
from slam2d.datasets.registry import open_dataset
from slam2d.evaluation.relations import _endpoints, _match, read_relations
from slam2d.paths import resolve_data_path

CONTRADICTED_M = 0.15  # m: a pose fitting the scans worse than this ...
RATIO = 2.0  # ... and this many times worse than the other pose is contradicted by them
NO_OVERLAP_M = 0.5  # m: both poses fit worse than this: the two scans see different things
MAX_RANGE = 30.0  # m: hits farther than this are left out of the fit
LOCAL_MAP_S = 30.0  # s: a pair whose scans do not overlap is fitted again against the scans this close to scan 1


def scan_points(cfg) -> tuple[np.ndarray, list[np.ndarray], np.ndarray]:
    """Stamps (N,) s, hit points in the robot frame (list of (M, 2) m) and laser mounts (N, 3) of the
    scans of ``cfg``'s dataset."""
    stamps, points, mounts = [], [], []
    for scan in open_dataset(cfg.dataset):
        hit = scan.hit_mask() & (scan.ranges < MAX_RANGE)
        r, a = scan.ranges[hit], scan.angles[hit]
        stamps.append(scan.stamp)
        points.append(geometry.transform_points(scan.sensor_pose, np.column_stack([r * np.cos(a), r * np.sin(a)])))
        mounts.append(scan.sensor_pose)
    return np.array(stamps), points, np.array(mounts)


def read_tum(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """Stamps (N,) s and planar poses (N, 3) of a TUM trajectory file."""
    t = np.loadtxt(path, ndmin=2)
    return t[:, 0], np.column_stack([t[:, 1], t[:, 2], 2 * np.arctan2(t[:, 6], t[:, 7])])


def audit(log: str, folder: Path) -> dict:
    """Scan fits of the ground truth and the estimate in ``folder`` on every relation of ``log``
    whose two ends match both a scan and a trajectory stamp."""
    cfg = load_config(f"experiments/{log}.yaml")
    tolerance = cfg.evaluation.relation_tolerance
    relations = read_relations(resolve_data_path(cfg.evaluation.relations, "evaluation.relations"))
    stamps, poses = read_tum(folder / "trajectory.tum")
    scan_stamps, points, mounts = scan_points(cfg)
    i1, i2, ok = _endpoints(stamps, relations, tolerance)
    s1, s2, scanned = _endpoints(scan_stamps, relations, tolerance)
    ok &= scanned
    i1, i2, s1, s2, truth = i1[ok], i2[ok], s1[ok], s2[ok], relations.delta[ok]
    p1, p2 = poses[i1], poses[i2]
    if json.loads((folder / "metrics.json").read_text())["relations"]["frame"] == "laser":
        p1, p2 = geometry.compose(p1, mounts[s1]), geometry.compose(p2, mounts[s2])  # relations between lasers
        points = [geometry.transform_points(geometry.inverse(m), p) for m, p in zip(mounts, points)]
    estimate = geometry.between(p1, p2)
    err = geometry.compose(estimate, geometry.inverse(truth))
    trees: dict[int, cKDTree] = {}

    def fit(a: int, b: int, delta: np.ndarray) -> float:
        if a not in trees:
            trees[a] = cKDTree(points[a])
        return float(np.median(trees[a].query(geometry.transform_points(delta, points[b]))[0]))

    out = {"error": np.hypot(err[:, 0], err[:, 1]),
           "truth_fit": np.array([fit(a, b, d) for a, b, d in zip(s1, s2, truth)]),
           "ours_fit": np.array([fit(a, b, d) for a, b, d in zip(s1, s2, estimate)]),
           "t1": relations.t1[ok] - scan_stamps[0], "t2": relations.t2[ok] - scan_stamps[0]}  # fmt: skip
    blind = (out["truth_fit"] > NO_OVERLAP_M) & (out["ours_fit"] > NO_OVERLAP_M)
    refit = _local_map_fits(scan_stamps, points, stamps, poses, s1[blind], s2[blind], truth[blind], estimate[blind])
    out["truth_fit"][blind], out["ours_fit"][blind] = refit
    out["map_fitted"] = blind
    return out


def _local_map_fits(scan_stamps, points, stamps, poses, s1, s2, truth, estimate) -> tuple[np.ndarray, np.ndarray]:
    """Scan fits (m) of scan ``s2`` placed by ``truth`` and by ``estimate`` in scan ``s1``'s frame against the
    scans within ``LOCAL_MAP_S`` of scan 1 (and not of scan 2), laid out by the estimated trajectory
    ``(stamps, poses)`` around it: a return driving the other way sees what scan 1's neighbours saw, not
    scan 1 itself. Pairs closer than that in time keep infinite fits (still no overlap)."""
    order = np.argsort(stamps, kind="stable")
    pose_of = order[_match(stamps[order], scan_stamps, np.inf)[0]]  # the trajectory pose nearest each scan
    fits = np.zeros((2, len(s1)))
    for j, (a, b) in enumerate(zip(s1, s2)):
        near = np.flatnonzero((np.abs(scan_stamps - scan_stamps[a]) <= LOCAL_MAP_S)
                              & (np.abs(scan_stamps - scan_stamps[b]) > LOCAL_MAP_S))  # fmt: skip
        if len(near) == 0:  # scan 2 lies among scan 1's neighbours: no independent map
            fits[:, j] = np.inf
            continue
        frame = geometry.inverse(poses[pose_of[a]])
        tree = cKDTree(np.vstack([geometry.transform_points(geometry.compose(frame, poses[pose_of[k]]), points[k])
                                  for k in near]))  # fmt: skip
        for row, delta in enumerate((truth[j], estimate[j])):
            fits[row, j] = np.median(tree.query(geometry.transform_points(delta, points[b]))[0])
    return fits[0], fits[1]


def classes(a: dict) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Masks of the relations whose scans do not overlap, whose ground truth the scans contradict,
    and whose estimate they contradict."""
    ft, fo = a["truth_fit"], a["ours_fit"]
    blind = (ft > NO_OVERLAP_M) & (fo > NO_OVERLAP_M)
    return blind, ~blind & (ft > CONTRADICTED_M) & (ft > RATIO * fo), ~blind & (fo > CONTRADICTED_M) & (fo > RATIO * ft)


def summary(log: str, a: dict) -> str:
    """One table row: relations, the contradicted ones (count, mean error, share of the metric), the rest."""
    e, n = a["error"], len(a["error"])
    blind, truth_bad, ours_bad = classes(a)
    rest = ~blind & ~truth_bad
    return (f"| {log} | {n} | {e.mean():.4f} | {truth_bad.sum()} ({100 * truth_bad.mean():.1f} %) | "
            f"{e[truth_bad].mean() if truth_bad.any() else 0:.3f} | {e[truth_bad].sum() / n:.4f} | "
            f"{ours_bad.sum()} | {blind.sum()} | {e[blind].sum() / n:.4f} | "
            f"{e[rest].mean():.4f} |")  # fmt: skip


def main(argv: list[str]) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("logs", nargs="*", help=f"some of {', '.join(PUBLISHED)} (default: all)")
    ap.add_argument("--results", action="append", default=[], help="LOG=FOLDER: score this results folder")
    ap.add_argument("--worst", type=int, default=0, help="list this many contradicted relations per log")
    args = ap.parse_args(argv)
    given = dict(item.split("=", 1) for item in args.results)
    logs = args.logs or list(PUBLISHED)
    unknown = set(logs) - set(PUBLISHED)
    if unknown:
        ap.error(f"unknown log(s) {sorted(unknown)}; choose from {list(PUBLISHED)}")
    print("| log | relations | slam2d error (m) | ground truth contradicted by the scans | their mean error (m) | "
          "their share of the error (m) | estimate contradicted | no overlap | their share (m) | "
          "error on the rest (m) |")  # fmt: skip
    print("|---|---|---|---|---|---|---|---|---|---|")
    details = []
    for log in logs:
        folder = Path(given[log]) if log in given else Path(run(log, [])["folder"])
        a = audit(log, folder)
        print(summary(log, a), flush=True)
        bad = np.flatnonzero(classes(a)[1])
        for j in bad[np.argsort(-a["error"][bad])][: args.worst]:
            details.append(f"{log}: t = {a['t1'][j]:.1f} -> {a['t2'][j]:.1f} s, error {a['error'][j]:.3f} m, scan fit "
                           f"ground truth {a['truth_fit'][j]:.3f} m, slam2d {a['ours_fit'][j]:.3f} m")  # fmt: skip
    if details:
        print("\n" + "\n".join(details))


if __name__ == "__main__":
    main(sys.argv[1:])
