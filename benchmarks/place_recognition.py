"""Global place recognition on 2D laser logs: map_closures (density images + ORB) measured.

Usage: .venv/bin/python benchmarks/place_recognition.py RESULTS_FOLDER [--resolution 0.2] [--travel 10] [--inliers 4]
  (needs `pip install map_closures`; RESULTS_FOLDER is a `slam2d run` of one
  of experiments/*.yaml, whose trajectory stands in for the ground truth)

The log's scans are placed at the run's poses and cut into local maps every
``--travel`` m of path (points in the frame of the map's last scan, z = 0), as
KISS-SLAM feeds map_closures. Every local map queries all earlier ones;
a candidate with at least ``--inliers`` RANSAC inliers is correct when its
relative pose lies within 1 m and 5 deg of the trajectory's. Recall is
counted against the pairs of local maps whose last poses lie within 3 m
of each other, more than 3 maps apart (map_closures skips the last 3).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from slam2d import config, geometry
from slam2d.datasets.registry import open_dataset


def read_tum(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """Stamps (N,) s and planar poses (N, 3) of a TUM trajectory file."""
    t = np.loadtxt(path, ndmin=2)
    return t[:, 0], np.column_stack([t[:, 1], t[:, 2], 2 * np.arctan2(t[:, 6], t[:, 7])])


def local_maps(source, stamps: np.ndarray, poses: np.ndarray, travel: float):
    """(index into ``poses`` of each local map's last scan, its points (M, 2) in that scan's base frame)."""
    world, travelled, last = [], 0.0, None
    for scan in source:
        k = int(np.clip(np.searchsorted(stamps, scan.stamp), 0, len(stamps) - 1))
        if abs(stamps[k] - scan.stamp) > 1e-3:
            continue
        if last is not None:
            travelled += float(np.hypot(*(poses[k, :2] - poses[last, :2])))
        last = k
        world.append(geometry.transform_points(poses[k], geometry.transform_points(scan.sensor_pose, scan.points())))
        if travelled >= travel:
            local = geometry.transform_points(geometry.inverse(poses[k]), np.vstack(world))
            yield k, np.unique(np.round(local / 0.05), axis=0) * 0.05  # one point per 5 cm cell
            world, travelled = [], 0.0


def main() -> None:
    from map_closures.config import MapClosuresConfig
    from map_closures.map_closures import MapClosures

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("results", type=Path)
    ap.add_argument("--resolution", type=float, default=0.2, help="m per density-image pixel")
    ap.add_argument("--travel", type=float, default=10.0, help="m of path per local map")
    ap.add_argument("--inliers", type=int, default=4, help="RANSAC inliers to count a candidate")
    args = ap.parse_args()
    cfg = config.load(args.results / "config.yaml")
    stamps, poses = read_tum(args.results / "trajectory.tum")
    closures = MapClosures(MapClosuresConfig(density_map_resolution=args.resolution, inliers_threshold=args.inliers))
    anchors, found, seconds = [], [], 0.0
    for q, (k, points) in enumerate(local_maps(open_dataset(cfg.dataset), stamps, poses, args.travel)):
        anchors.append(k)
        t0 = time.perf_counter()
        candidates = closures.get_closures(q, np.column_stack([points, np.zeros(len(points))]))
        seconds += time.perf_counter() - t0
        for c in candidates:
            if c.number_of_inliers >= args.inliers:
                m = np.asarray(c.pose)
                measured = np.array([m[0, 3], m[1, 3], np.arctan2(m[1, 0], m[0, 0])])
                err = geometry.between(geometry.between(poses[k], poses[anchors[c.source_id]]), measured)
                found.append((c.source_id, q, np.hypot(err[0], err[1]) < 1.0 and abs(err[2]) < np.deg2rad(5)))
    a = poses[anchors, :2]
    apart = np.abs(np.subtract.outer(np.arange(len(a)), np.arange(len(a)))) > 3
    revisits = {(i, j) for i, j in zip(*np.nonzero((np.hypot(*(a[:, None] - a[None]).transpose(2, 0, 1)) < 3) & apart))
                if i < j}
    correct = {(i, j) for i, j, ok in found if ok}
    print(f"| {cfg.name} | {len(anchors)} | {len(revisits)} | {len(found)} | {len(correct)} "
          f"| {len(correct & revisits)} | {1000 * seconds / max(len(anchors), 1):.0f} |")


if __name__ == "__main__":
    main()
