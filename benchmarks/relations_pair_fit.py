"""How close the relations are to the best alignment of their own two scans.

Usage: .venv/bin/python benchmarks/relations_pair_fit.py [intel aces fr079 fr-clinic csail] [--results LOG=FOLDER ...]

For every relation whose two ends are scans, scan 2's points are placed in scan 1's frame by the
relation's pose and by slam2d's estimate (a results folder given with ``--results``, else a fresh
`slam2d run experiments/<log>.yaml`), and each pose's *line fit* is the median point-to-line
distance (m) of those points to scan 1's local lines (``slam2d.backend.dense``). The two scans are
also aligned point-to-line from the estimate (``dense.align_pairs``), and that alignment is scored
against the relations as the estimate is. If the relations were the scans' best alignment, the
alignment would score near zero and the relations would fit better than the estimate nearly always.
The last column is the frame (a laser mount, fitted to the relations) in which the estimate scores
best, and that score: a relations file made in another frame than the one scored would show here.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np
from scipy.optimize import minimize

sys.path.insert(0, str(Path(__file__).resolve().parent))
from relations_audit import read_tum, scan_points
from slam_radish import PUBLISHED, run

from slam2d import geometry
from slam2d.backend import dense
from slam2d.backend.probability_grid import voxel_filter
from slam2d.config import load as load_config
from slam2d.evaluation.relations import _endpoints, read_relations
from slam2d.paths import resolve_data_path

MAX_DISTANCE = 0.3  # m: a point farther from scan 1's nearest point has no line


def line_fit(target: dense.Surface, points: np.ndarray) -> float:
    """Median point-to-line distance (m) of ``points`` (in the target's frame) to ``target``'s lines."""
    dist, idx = target.tree.query(points, distance_upper_bound=MAX_DISTANCE)
    hit = np.isfinite(dist)
    hit[hit] &= np.isfinite(target.normals[idx[hit], 0])
    if not hit.any():
        return float("nan")
    return float(np.median(np.abs(np.einsum("ij,ij->i", target.normals[idx[hit]], points[hit] - target.points[idx[hit]]))))


def pair_fit(log: str, folder: Path) -> dict:
    cfg = load_config(f"experiments/{log}.yaml")
    relations = read_relations(resolve_data_path(cfg.evaluation.relations, "evaluation.relations"))
    stamps, poses = read_tum(folder / "trajectory.tum")
    scan_stamps, points, mounts = scan_points(cfg)
    i1, i2, ok = _endpoints(stamps, relations, cfg.evaluation.relation_tolerance)
    s1, s2, scanned = _endpoints(scan_stamps, relations, cfg.evaluation.relation_tolerance)
    ok &= scanned
    i1, i2, s1, s2, truth = i1[ok], i2[ok], s1[ok], s2[ok], relations.delta[ok]
    p1, p2 = poses[i1], poses[i2]
    if json.loads((folder / "metrics.json").read_text())["relations"]["frame"] == "laser":
        p1, p2 = geometry.compose(p1, mounts[s1]), geometry.compose(p2, mounts[s2])
        points = [geometry.transform_points(geometry.inverse(m), p) for m, p in zip(mounts, points)]
    estimate = geometry.between(p1, p2)
    ids = np.unique(np.r_[s1, s2])
    where = {int(s): n for n, s in enumerate(ids)}
    surfaces = [dense.surface(points[s]) for s in ids]
    aligned, _, share = dense.align_pairs(surfaces, [voxel_filter(points[s], 0.05) for s in ids],
                                          [[where[a], where[b]] for a, b in zip(s1, s2)], estimate)

    def error(delta):
        e = geometry.compose(delta, geometry.inverse(truth))
        return np.hypot(e[:, 0], e[:, 1])

    def remounted(m):  # the estimate between frames at ``m`` (x, y, theta) in the laser's
        return error(geometry.compose(geometry.compose(geometry.inverse(m), estimate), m)).mean()

    mount = minimize(remounted, np.zeros(3), method="Nelder-Mead").x

    fits = np.array([[line_fit(surfaces[where[a]], geometry.transform_points(d, points[b])) for d in (t, e)]
                     for a, b, t, e in zip(s1, s2, truth, estimate)])  # fmt: skip
    both = np.isfinite(fits).all(axis=1)
    overlap = share >= 0.25
    return {"n": len(truth), "ours": error(estimate).mean(), "aligned": np.where(overlap, error(aligned), error(estimate)).mean(),
            "overlap": overlap.mean(), "fit": np.median(fits[both], axis=0), "better": np.mean(fits[both, 0] < fits[both, 1]),
            "mount": mount, "remounted": remounted(mount)}


def main(argv: list[str]) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("logs", nargs="*", help=f"some of {', '.join(PUBLISHED)} (default: all)")
    ap.add_argument("--results", action="append", default=[], help="LOG=FOLDER: score this results folder")
    args = ap.parse_args(argv)
    given = dict(item.split("=", 1) for item in args.results)
    print("| log | relations | slam2d error (m) | pairwise alignment's error (m) | pairs aligned | "
          "line fit, relations / slam2d (m) | relations fit better | best frame (x m, y m, θ °): error (m) |")
    print("|---|---|---|---|---|---|---|---|")
    for log in args.logs or list(PUBLISHED):
        folder = Path(given[log]) if log in given else Path(run(log, [])["folder"])
        a = pair_fit(log, folder)
        print(f"| {log} | {a['n']} | {a['ours']:.4f} | {a['aligned']:.4f} | {100 * a['overlap']:.0f} % "
              f"| {a['fit'][0]:.4f} / {a['fit'][1]:.4f} | {100 * a['better']:.1f} % "
              f"| ({a['mount'][0]:.3f}, {a['mount'][1]:.3f}, {np.rad2deg(a['mount'][2]):.2f}): {a['remounted']:.4f} |",
              flush=True)


if __name__ == "__main__":
    main(sys.argv[1:])
