"""Which scans leave directions unconstrained, and whether odometry or the scan matcher is right there.

Usage: .venv/bin/python benchmarks/degeneracy_audit.py [intel aces fr079 fr-clinic csail]
       [--ratios 10 100 300 1000] [--results LOG=FOLDER ...] [--set KEY=VALUE ...] [--range-scale S]

Runs the ICP frontend alone (the one default, no pose graph) over each log and records, per
registered scan, the scan's information on the delta (``IcpFrontend._scan_information`` in the
delta's frame) and the odometry and frontend deltas. It prints:

- the share of scans with a degenerate direction: a generalised eigenvalue of the scan's
  information against the odometry's (``odom_sigma_*``) below each ratio (the frontend's
  ``degeneracy_ratio`` test);
- the relations error (m) by relation duration of chained deltas: odometry alone, the
  frontend, odometry's translation with the frontend's heading, and the frontend's deltas
  remapped offline at each ratio (the correction to odometry kept only in the directions above
  it; the map is not rebuilt, so this approximates running the frontend at that ratio);
- with ``--results``, the same for a SLAM trajectory (a results folder of that log);
- the scan interval, odometry's speed quartiles, and how the frontend's heading increments follow
  odometry's (a time offset between scans and odometry shows as a lag);
- the chained lengths over the relations' lengths on the 3-10 s relations (sum ratio, and the median
  per-relation ratio over those longer than 0.5 m), for odometry and the frontend.

``--set`` overrides config keys (``frontend.options.map_window=3``); ``--range-scale`` multiplies
every range by S before the frontend sees it.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
from itertools import pairwise
from pathlib import Path

import numpy as np

from slam2d import geometry
from slam2d.config import load as load_config
from slam2d.datasets.registry import open_dataset
from slam2d.evaluation.relations import (
    _endpoints,
    read_relations,
    relation_errors,
    relations_frame,
)
from slam2d.frontends import create_frontend
from slam2d.frontends.common import local_information
from slam2d.frontends.icp.degeneracy import constrained_projector
from slam2d.frontends.odometry import odometry_information
from slam2d.paths import resolve_data_path

BINS = (0.0, 3.0, 10.0, 30.0, np.inf)  # s: relation durations


def record(log: str, overrides: tuple[str, ...] = (), range_scale: float = 1.0) -> dict:
    """Per scan of ``log``: stamp, odometry pose, laser mount, odometry delta, frontend delta and the
    scan's information on the delta (NaN where the scan was not registered); config ``overrides``,
    ranges multiplied by ``range_scale``."""
    cfg = load_config(f"experiments/{log}.yaml", list(overrides))
    fe = create_frontend("icp", cfg.frontend.options)
    seen: list[np.ndarray] = []
    scan_information = fe._scan_information

    def spy(fit):  # the frontend's pose is still the previous scan's: the delta's frame
        seen.append(local_information(scan_information(fit), fe.pose[2]))
        return scan_information(fit)

    fe._scan_information = spy
    rows, previous = [], None
    for scan in open_dataset(cfg.dataset):
        if range_scale != 1.0:
            scan = dataclasses.replace(scan, ranges=scan.ranges * range_scale)
        odom = np.zeros(3) if previous is None else geometry.between(previous.odom, scan.odom)
        seen.clear()
        delta = fe.process(scan, odom).delta
        rows.append((scan.stamp, scan.odom, scan.sensor_pose, odom, delta, seen[0] if seen else np.full((3, 3), np.nan)))
        previous = scan
    out = {k: np.array([r[i] for r in rows]) for i, k in enumerate(("stamp", "odom", "mount", "od", "delta", "info"))}
    out["odom_information"] = odometry_information(fe.config.odom_sigma_xy, fe.config.odom_sigma_theta_deg)
    return out


def chain(deltas: np.ndarray) -> np.ndarray:
    """Poses (N, 3) of chained deltas (N, 3) from the origin (the first delta is skipped)."""
    poses = np.zeros_like(deltas)
    for i in range(1, len(deltas)):
        poses[i] = geometry.compose(poses[i - 1], deltas[i])
    return poses


def remapped(rec: dict, ratio: float) -> tuple[np.ndarray, int]:
    """The frontend's deltas with their correction to odometry kept only where the scan's information
    exceeds ``ratio`` x odometry's; and the number of scans changed."""
    out, changed = rec["delta"].copy(), 0
    for i in np.flatnonzero(np.isfinite(rec["info"][:, 0, 0])):
        projector, free = constrained_projector(rec["info"][i], rec["odom_information"], ratio)
        if free:
            c = rec["delta"][i] - rec["od"][i]
            c[2] = geometry.wrap_angle(c[2])
            out[i], changed = rec["od"][i] + projector @ c, changed + 1
    return out, changed


def timing(rec: dict) -> str:
    """Scan interval and odometry speed quartiles; how the frontend's heading increments follow odometry's
    (correlation at lags of -1, 0, +1 scans, and the lag in s from a fit over the neighbouring increments)."""
    dt = np.diff(rec["stamp"])
    ok = dt > 0
    speed = np.hypot(rec["od"][1:, 0], rec["od"][1:, 1])[ok] / dt[ok]
    fe, od = rec["delta"][:, 2], rec["od"][:, 2]
    i = np.arange(1, len(fe) - 1)
    i = i[np.isfinite(fe[i])]
    corr = [np.corrcoef(fe[i], od[i + lag])[0, 1] for lag in (-1, 0, 1)]
    coef = np.linalg.lstsq(np.column_stack([od[i - 1], od[i], od[i + 1]]), fe[i], rcond=None)[0]
    lag = (coef[2] - coef[0]) / coef.sum() * np.median(dt)
    return (f"scan interval {np.median(dt):.3f} s; speed quartiles {' / '.join(f'{q:.3f}' for q in np.percentile(speed, [25, 50, 75]))} m/s; "
            f"heading increments vs odometry's: correlation {' / '.join(f'{c:.3f}' for c in corr)} at lag -1 / 0 / +1 scan, "
            f"fitted lag {lag:+.3f} s")


def scored(log: str, rec: dict, poses: np.ndarray):
    """(relations, ``poses`` in the relations' frame, errors (m), mask of the relations scored)."""
    cfg = load_config(f"experiments/{log}.yaml")
    tol = cfg.evaluation.relation_tolerance
    relations = read_relations(resolve_data_path(cfg.evaluation.relations, "evaluation.relations"))
    frame, _ = relations_frame(rec["stamp"], rec["odom"], rec["mount"], relations, tol)
    if frame == "laser":
        poses = geometry.compose(poses, rec["mount"])
    err, _, ok = relation_errors(rec["stamp"], poses, relations, tol)
    return relations, poses, err, ok


def length_ratio(log: str, rec: dict, poses: np.ndarray, lo: float = 3.0, hi: float = 10.0) -> str:
    """Chained lengths over the relations' lengths on the ``lo``-``hi`` s relations: sum ratio, and the
    median per-relation ratio over relations longer than 0.5 m."""
    relations, poses, _, ok = scored(log, rec, poses)
    cfg = load_config(f"experiments/{log}.yaml")
    i1, i2, _ = _endpoints(rec["stamp"], relations, cfg.evaluation.relation_tolerance)
    d = geometry.between(poses[i1[ok]], poses[i2[ok]])
    length, truth = np.hypot(d[:, 0], d[:, 1]), np.hypot(relations.delta[ok, 0], relations.delta[ok, 1])
    duration = np.abs(relations.t2 - relations.t1)[ok]
    m = (duration >= lo) & (duration < hi)
    long = m & (truth > 0.5)
    if not long.any():
        return "–"
    return f"{length[m].sum() / truth[m].sum():.4f} (median {np.median(length[long] / truth[long]):.4f})"


def by_duration(log: str, rec: dict, poses: np.ndarray) -> list[str]:
    """Relations error (m) of ``poses`` (one per scan): all, then per duration bin, with counts."""
    relations, poses, err, ok = scored(log, rec, poses)
    duration = np.abs(relations.t2 - relations.t1)[ok]
    cells = [f"{err.mean():.4f}"]
    for lo, hi in pairwise(BINS):
        m = (duration >= lo) & (duration < hi)
        cells.append(f"{err[m].mean():.4f} ({m.sum()})" if m.any() else "–")
    return cells


def read_tum(path: Path) -> np.ndarray:
    """Planar poses (N, 3) of a TUM trajectory file."""
    t = np.loadtxt(path, ndmin=2)
    return np.column_stack([t[:, 1], t[:, 2], 2 * np.arctan2(t[:, 6], t[:, 7])])


def audit(log: str, ratios: list[float], results: Path | None, overrides=(), range_scale: float = 1.0) -> None:
    rec = record(log, overrides, range_scale)
    info = rec["info"][np.isfinite(rec["info"][:, 0, 0])]
    inv = np.linalg.inv(np.linalg.cholesky(rec["odom_information"]))
    smallest = np.linalg.eigvalsh(inv @ info @ inv.T)[:, 0]
    shares = ", ".join(f"< {r:g}: {np.mean(smallest < r):.2%}" for r in ratios)
    print(f"\n{log}: {len(info)} registered scans; smallest generalised eigenvalue {shares}")
    print("| deltas | all | " + " | ".join(f"{lo:g}–{hi:g} s" for lo, hi in pairwise(BINS)) + " |")
    print("|---|" + "---|" * len(BINS))
    mixed = rec["od"].copy()
    mixed[:, 2] = rec["delta"][:, 2]
    rows = [("odometry", rec["od"]), ("frontend (default)", rec["delta"]),
            ("odometry x, y + frontend heading", mixed)]  # fmt: skip
    for ratio in ratios:
        deltas, changed = remapped(rec, ratio)
        rows.append((f"remapped at ratio {ratio:g} ({changed} scans)", deltas))
    for name, deltas in rows:
        print(f"| {name} | " + " | ".join(by_duration(log, rec, chain(deltas))) + " |", flush=True)
    print(timing(rec))
    print(f"3–10 s lengths / relations': odometry {length_ratio(log, rec, chain(rec['od']))}, "
          f"frontend {length_ratio(log, rec, chain(rec['delta']))}")
    if results is not None:
        poses = read_tum(results / "trajectory.tum")
        if len(poses) == len(rec["stamp"]):
            print(f"| SLAM {results.name} | " + " | ".join(by_duration(log, rec, poses)) + " |")


def main(argv: list[str]) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("logs", nargs="*", default=["intel", "aces", "fr079", "fr-clinic", "csail"])
    ap.add_argument("--ratios", type=float, nargs="+", default=[10.0, 100.0, 300.0, 1000.0])
    ap.add_argument("--results", action="append", default=[], help="LOG=FOLDER: a SLAM run of LOG to score too")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="config override")
    ap.add_argument("--range-scale", type=float, default=1.0, help="every range multiplied by this")
    args = ap.parse_args(argv)
    results = dict(r.split("=", 1) for r in args.results)
    for log in args.logs:
        audit(log, args.ratios, Path(results[log]) if log in results else None, args.set, args.range_scale)


if __name__ == "__main__":
    main(sys.argv[1:])
