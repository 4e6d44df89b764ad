"""Whether the scan matcher's translation lengths agree with the relations', scan pair by scan pair.

Usage: .venv/bin/python benchmarks/scale_audit.py [intel aces fr079 fr-clinic csail]
       [--pairs 400] [--durations 3 10] [--range-scale 1.0 0.985] [--sweep 0 0.0267 0.2]

For a sample of each log's relations (durations in ``--durations`` s, lengths over 0.3 m) the ICP
frontend (the one default) registers the relation's second scan directly to its first, starting from
the odometry delta: no chain, no local map of many scans, no pose graph. It prints, per variant of the
scans, the matched lengths over the relations' lengths (sum ratio and median of per-pair ratios), the
same for odometry, and the mean relation error (m) and heading error (deg) of the match and of odometry. A matcher or a
chain that drifts scan by scan cannot show here; a scale between the scans and the relations can.

It also prints the turn ratios of the pairs that turn more than 10°. Variants: ``--range-scale s``
multiplies every range by s, ``--angle-scale a`` every beam angle by a; ``--sweep T`` de-skews each scan as if
its beams had been taken over T s from its stamp (first beam at the stamp, as ROS LaserScan), moving
each point by the odometry's velocity (from the neighbouring scans) over its beam's time offset.
``--slam S`` runs the whole SLAM on each bag log with its ranges x S instead (heavy: minutes).
"""

from __future__ import annotations

import argparse
import dataclasses
import sys

import numpy as np

from slam2d import geometry
from slam2d.config import load as load_config
from slam2d.datasets.registry import open_dataset
from slam2d.evaluation.relations import _endpoints, read_relations, relations_frame
from slam2d.frontends import create_frontend
from slam2d.paths import resolve_data_path
from slam2d.types import Scan


def deskewed(scan: Scan, twist: np.ndarray, sweep: float) -> Scan:
    """``scan`` with each hit moved into the base frame at the stamp: beam k of n taken at
    ``sweep`` * k / (n - 1) s after it while the base moves at ``twist`` (vx, vy, w) (m/s, rad/s).
    The result is in the base frame (sensor pose zero); beams without a hit become NaN."""
    hit = scan.hit_mask()
    tau = sweep * np.arange(len(scan.ranges)) / max(len(scan.ranges) - 1, 1)
    motion = twist[None, :] * tau[hit, None]  # first order: base pose at the beam's time
    points = geometry.transform_points(scan.sensor_pose, scan.points())
    c, s = np.cos(motion[:, 2]), np.sin(motion[:, 2])
    moved = np.column_stack([c * points[:, 0] - s * points[:, 1] + motion[:, 0],
                             s * points[:, 0] + c * points[:, 1] + motion[:, 1]])  # fmt: skip
    ranges = np.full(len(scan.ranges), np.nan)
    angles = scan.angles.copy()
    ranges[hit], angles[hit] = np.hypot(moved[:, 0], moved[:, 1]), np.arctan2(moved[:, 1], moved[:, 0])
    return dataclasses.replace(scan, ranges=ranges, angles=angles, sensor_pose=np.zeros(3))


def twists(scans: list[Scan]) -> np.ndarray:
    """Odometry velocity (N, 3) in each scan's base frame, from its neighbours (m/s, rad/s)."""
    out = np.zeros((len(scans), 3))
    for i in range(1, len(scans) - 1):
        dt = scans[i + 1].stamp - scans[i - 1].stamp
        if dt > 0:
            out[i] = geometry.between(scans[i - 1].odom, scans[i + 1].odom) / dt
    return out


def audit(log: str, pairs: int, durations: tuple[float, float], scale: float, sweep: float, scans=None,
          angle_scale: float = 1.0) -> list:
    cfg = load_config(f"experiments/{log}.yaml")
    scans = scans if scans is not None else list(open_dataset(cfg.dataset))
    stamps = np.array([s.stamp for s in scans])
    tol = cfg.evaluation.relation_tolerance
    relations = read_relations(resolve_data_path(cfg.evaluation.relations, "evaluation.relations"))
    frame, _ = relations_frame(stamps, np.array([s.odom for s in scans]), np.array([s.sensor_pose for s in scans]),
                               relations, tol)
    i1, i2, ok = _endpoints(stamps, relations, tol)
    duration = np.abs(relations.t2 - relations.t1)
    length = np.hypot(relations.delta[:, 0], relations.delta[:, 1])
    turn = np.abs(relations.delta[:, 2]) > np.radians(10)
    chosen = np.flatnonzero(ok & (duration >= durations[0]) & (duration < durations[1]) & ((length > 0.3) | turn))
    chosen = np.random.default_rng(0).choice(chosen, min(pairs, len(chosen)), replace=False)
    velocity = twists(scans) if sweep > 0 else None
    rows = []
    for k in chosen:
        a, b = scans[i1[k]], scans[i2[k]]
        mount_a, mount_b = a.sensor_pose, b.sensor_pose
        if scale != 1.0 or angle_scale != 1.0:
            a, b = (dataclasses.replace(s, ranges=s.ranges * scale, angles=s.angles * angle_scale) for s in (a, b))
        if sweep > 0:
            a, b = deskewed(a, velocity[i1[k]], sweep), deskewed(b, velocity[i2[k]], sweep)
        frontend = create_frontend("icp", cfg.frontend.options)
        frontend.process(a, np.zeros(3))
        odom = geometry.between(a.odom, b.odom)
        match = frontend.process(b, odom).delta
        if frame == "laser":
            match, odom = (geometry.between(mount_a, geometry.compose(d, mount_b)) for d in (match, odom))
        truth = relations.delta[k]
        err = [np.hypot(*geometry.compose(d, geometry.inverse(truth))[:2]) for d in (match, odom)]
        turn_err = [abs(geometry.wrap_angle(d[2] - truth[2])) for d in (match, odom)]
        rows.append((np.hypot(*match[:2]), np.hypot(*odom[:2]), length[k], *err, match[2], odom[2], truth[2],
                     *turn_err))
    return rows


def metadata(log: str) -> str:
    """The first LaserScan's sweep timing and beam layout of a bag log (CARMEN logs carry none)."""
    cfg = load_config(f"experiments/{log}.yaml")
    if cfg.dataset.kind != "rosbag":
        return f"{log}: {cfg.dataset.kind} log, no sweep timing"
    from rosbags.highlevel import AnyReader

    with AnyReader([resolve_data_path(cfg.dataset.path, "dataset.path")]) as reader:
        conns = [c for c in reader.connections if c.msgtype == "sensor_msgs/msg/LaserScan"]
        conn, _, raw = next(reader.messages(connections=conns))
        m = reader.deserialize(raw, conn.msgtype)
    return (f"{log}: time_increment {m.time_increment} s, scan_time {m.scan_time} s, {len(m.ranges)} beams "
            f"from {np.degrees(m.angle_min):.2f} deg by {np.degrees(m.angle_increment):.4f} deg, "
            f"range_max {m.range_max:.2f} m")


def slam_with_scaled_ranges(log: str, scale: float) -> None:
    """``slam2d run experiments/LOG.yaml -q`` in this process with every range of the bag x ``scale``; it
    prints the results folder (its metrics.json holds the relations error)."""
    from slam2d.cli import main as cli
    from slam2d.datasets import rosbag

    scans = rosbag.RosbagSource._raw_scans

    def scaled(self):
        for scan in scans(self):
            yield dataclasses.replace(scan, ranges=scan.ranges * scale)

    rosbag.RosbagSource._raw_scans = scaled
    argv, sys.argv = sys.argv, ["slam2d", "run", f"experiments/{log}.yaml", "-q"]
    try:
        cli()
    except SystemExit as done:
        if done.code:
            raise
    finally:
        rosbag.RosbagSource._raw_scans, sys.argv = scans, argv


def report(log: str, variant: str, rows: list) -> str:
    m, o, r, em, eo, ym, yo, yr, hm, ho = np.array(rows).T
    moved, turned = r > 0.3, np.abs(yr) > np.radians(10)
    m, o, r, em, eo, hm, ho = m[moved], o[moved], r[moved], em[moved], eo[moved], hm[moved], ho[moved]
    ym, yo, yr = ym[turned] * np.sign(yr[turned]), yo[turned] * np.sign(yr[turned]), np.abs(yr[turned])
    return (f"| {log} | {variant} | {len(r)} | {m.sum() / r.sum():.4f} | {np.median(m / r):.4f} | "
            f"{o.sum() / r.sum():.4f} | {np.median(o / r):.4f} | {em.mean():.4f} | {eo.mean():.4f} | "
            f"{np.degrees(hm.mean()):.2f} | {np.degrees(ho.mean()):.2f} | "
            f"{len(yr)} | {ym.sum() / yr.sum():.4f} | {yo.sum() / yr.sum():.4f} |")


def main(argv: list[str]) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("logs", nargs="*", default=["intel", "aces", "fr079", "fr-clinic", "csail"])
    ap.add_argument("--pairs", type=int, default=400)
    ap.add_argument("--durations", type=float, nargs=2, default=[3.0, 10.0], help="s: relations kept")
    ap.add_argument("--range-scale", type=float, nargs="+", default=[1.0])
    ap.add_argument("--sweep", type=float, nargs="+", default=[0.0], help="s: sweep time de-skewed")
    ap.add_argument("--angle-scale", type=float, nargs="+", default=[1.0], help="beam angles multiplied by this")
    ap.add_argument("--slam", type=float, metavar="S", help="instead: a full SLAM run of each bag log with ranges x S")
    args = ap.parse_args(argv)
    if args.slam is not None:
        for log in args.logs:
            slam_with_scaled_ranges(log, args.slam)
        return
    print("| log | variant | pairs | match / relations (sum) | (median) | odometry / relations (sum) | (median) "
          "| match error (m) | odometry error (m) | match heading error (deg) | odometry heading error (deg) "
          "| turns | match / relations turn | odometry / relations turn |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for log in args.logs:
        print(metadata(log))
    for log in args.logs:
        scans = list(open_dataset(load_config(f"experiments/{log}.yaml").dataset))
        for scale in args.range_scale:
            for angle in args.angle_scale:
                for sweep in args.sweep:
                    rows = audit(log, args.pairs, tuple(args.durations), scale, sweep, scans, angle)
                    variant = f"ranges x {scale:g}, angles x {angle:g}, sweep {sweep * 1000:g} ms"
                    print(report(log, variant, rows), flush=True)


if __name__ == "__main__":
    main(sys.argv[1:])
