"""Batch pose-graph optimisation of the real g2o files: slam2d beside GTSAM's own reader.

For each file: GTSAM's ``readG2o`` + Levenberg-Marquardt, and slam2d's
``read_g2o`` + ``solve_g2o`` (same LM defaults, first vertex held by a tight
prior); they should agree, which checks the reader and the factor building.
Then (unless ``--no-replay``) the graph is fed to ``PoseGraph`` keyframe by
keyframe with one iSAM2 update each, as a SLAM run would, and finished with
``optimize_batch``. Errors are GTSAM's: 0.5 * sum of squared whitened residuals
over all edges (the prior excluded).

Starts (``--inits``): the error reached by ``solve_g2o`` from the file's poses, the
odometry spanning tree and the chordal initialisation against the best-known minimum,
with the time of the start and of LM beside SE-Sync's published times and as a multiple
of them; from the chordal start also "verified" (two other starts agree) and "certified"
(SE-Sync's certificate, ``backend/certificate.py``).

Outliers (``--outliers``): false loops injected the Vertigo way (random, local, group;
seeded) into ``--outlier-graphs``; per robust method (from its default start, the
odometry spanning tree) the position RMSE (m) to the outlier-free optimum, false loops
rejected, true loops kept, precision of the rejections, the CPU and wall time of the
whole ``solve_g2o`` call (factors, start, optimisation, classification) and the CPU
time's ratio to the same call on the outlier-free graph ("x clean": plain LM from the
chordal start; CPU time, because the machine may be shared); then the optimisation's own
wall time ("opt s": start, factor building and classification excluded; the screen of
pc_dcs included) and its ratio to the outlier-free LM's ("x clean LM").

    .venv/bin/python benchmarks/posegraph_g2o.py [--data DIR] [--datasets intel MIT CSAIL M3500] [--no-replay]
        [--no-inits] [--outliers 10 100 1000] [--outlier-graphs M3500 intel]
        [--methods none huber cauchy dcs gnc pc_dcs] [--info-scales 0.1 1 10]
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

import gtsam
import numpy as np

from slam2d import geometry
from slam2d.backend import initialization as ini
from slam2d.backend.batch import g2o_error, loop_metrics, solve_g2o
from slam2d.backend.factors import PRIOR_SIGMAS
from slam2d.backend.replay import replay_g2o
from slam2d.config import BackendConfig
from slam2d.datasets.g2o import (
    OUTLIER_KINDS,
    PoseGraphFile,
    inject_outliers,
    odometry_mask,
    read_g2o,
)

DEFAULT_DATA = Path(os.environ.get("SLAM2D_DATA", Path(__file__).resolve().parents[1] / ".." / "shared" / "datasets"))
DATASETS = ("intel", "MIT", "CSAIL", "M3500")
BEST_KNOWN = {"intel": 22.502117, "CSAIL": 20.275442, "M3500": 68.957439, "MIT": 20.603474}  # GTSAM error
SE_SYNC_S = {"intel": 0.071, "CSAIL": 0.010, "M3500": 0.080}  # published SE-Sync times (s); M3500 = manhattan
METHODS = ("none", "huber", "cauchy", "dcs", "gnc", "pc_dcs")


def gtsam_direct(path: Path):
    """GTSAM alone: readG2o, a prior on vertex 0, LM with default parameters."""
    t0 = time.perf_counter()
    graph, initial = gtsam.readG2o(str(path), False)
    read_s = time.perf_counter() - t0
    error0 = graph.error(initial)
    graph.add(gtsam.PriorFactorPose2(0, initial.atPose2(0), gtsam.noiseModel.Diagonal.Sigmas(PRIOR_SIGMAS)))
    t0 = time.perf_counter()
    opt = gtsam.LevenbergMarquardtOptimizer(graph, initial, gtsam.LevenbergMarquardtParams())
    result = opt.optimize()
    seconds = time.perf_counter() - t0
    graph.remove(graph.size() - 1)  # the error without the prior
    return gtsam.utilities.extractPose2(result), error0, graph.error(result), opt.iterations(), read_s, seconds


def max_pose_difference(a, b) -> tuple[float, float]:
    """Largest translation (m) and heading (rad) difference between two (N, 3) trajectories."""
    d = np.asarray(a) - np.asarray(b)
    return float(np.hypot(d[:, 0], d[:, 1]).max()), float(np.abs(geometry.wrap_angle(d[:, 2])).max())


def starts_table(data: Path, names, repeats: int = 3) -> None:
    """Error from each start vs the best-known minimum; start and LM wall time (the fastest of
    ``repeats`` runs) and their sum as a multiple of SE-Sync's published time."""
    print("\n| graph | start | start error | final error | best known | rel. gap | iters | start s | LM s "
          "| total s | SE-Sync s | x SE-Sync | verified | certified |")
    print("|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|---|")
    ini.spanning_tree(read_g2o(data / "posegraphs" / f"{names[0]}.g2o"))  # scipy imported before timing
    for name in names:
        g = read_g2o(data / "posegraphs" / f"{name}.g2o")
        for init in ("file", "spanning_tree", "chordal"):
            start_s, lm_s = float("inf"), float("inf")
            for _ in range(repeats):
                t0 = time.perf_counter()
                ini.initial_poses(g, init)
                start_s = min(start_s, time.perf_counter() - t0)
                r = solve_g2o(g, init=init, verify=init == "chordal")
                lm_s = min(lm_s, r.seconds)
            best = BEST_KNOWN.get(name, float("nan"))
            total = start_s + lm_s
            sesync = SE_SYNC_S.get(name)
            ratio = f"{total / sesync:.2f}" if sesync else "-"
            verified = "-" if r.verified is None else ("yes" if r.verified else "no")
            certified = "-" if r.certified is None else ("yes" if r.certified else "no")
            print(f"| {name} | {init} | {r.start_error:.6g} | {r.final_error:.6f} | {best} | "
                  f"{(r.final_error - best) / best:+.1e} | {r.iterations} | {start_s:.3f} | {lm_s:.3f} | "
                  f"{total:.3f} | {sesync or '-'} | {ratio} | {verified} | {certified} |", flush=True)


def _cpu() -> float:
    """CPU time (s) of this process and of its finished children (the solves' worker processes)."""
    t = os.times()
    return t.user + t.system + t.children_user + t.children_system


def _timed_solve(graph, method: str = "none"):
    """``solve_g2o`` from the method's default start; returns (result, CPU s, wall s), factor
    building, start, optimisation and classification included, the worker processes' CPU too."""
    cpu, wall = _cpu(), time.perf_counter()
    result = solve_g2o(graph, robust=method)
    return result, _cpu() - cpu, time.perf_counter() - wall


def scaled_information(graph: PoseGraphFile, factor: float) -> PoseGraphFile:
    """``graph`` with every information matrix multiplied by ``factor``."""
    return PoseGraphFile(graph.ids, graph.poses, graph.i, graph.j, graph.measurements, graph.information * factor)


def outlier_table(data: Path, names, counts, kinds, methods, seed: int = 1, scales=(1.0,)) -> None:
    """Per graph, information scale, outlier count and kind, robust method: RMSE to the outlier-free
    optimum (m), false loops rejected, true loops kept, CPU and wall time (s) and the CPU time's ratio
    to the outlier-free solve (plain LM from the chordal start, measured the same way), the
    optimisation's wall time alone and its ratio to the outlier-free LM's. A count of 0: the method on
    the clean graph."""
    print("\n| graph | info x | outliers | kind | method | RMSE m | false rejected | true kept | precision | CPU s "
          "| x clean | wall s | opt s | x clean LM |")
    print("|---|---:|---:|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    for name, factor in ((n, f) for n in names for f in scales):
        clean = scaled_information(read_g2o(data / "posegraphs" / f"{name}.g2o"), factor)
        _timed_solve(clean)  # imports and caches warm
        ref, clean_cpu, clean_wall = _timed_solve(clean)
        print(f"| {name} | {factor:g} | 0 | - | none (chordal) | 0 | - | - | - | {clean_cpu:.3f} | 1 | "
              f"{clean_wall:.3f} | {ref.seconds:.3f} | 1 |")
        for count in counts:
            for kind in kinds[:1] if count == 0 else kinds:
                g, injected = inject_outliers(clean, count, kind, seed)
                true_loops = ~odometry_mask(g) & ~injected
                for method in methods:
                    r, cpu, wall = _timed_solve(g, method)
                    m = loop_metrics(r.inlier, injected)
                    rmse = float(np.sqrt(np.mean(np.sum((r.poses[:, :2] - ref.poses[:, :2]) ** 2, 1))))
                    kept = np.sum(r.inlier & true_loops) / max(1, true_loops.sum())
                    print(f"| {name} | {factor:g} | {count} | {kind if count else '-'} | {method} | {rmse:.3g} | "
                          f"{m['outliers_rejected']}/{count} ({100 * m['recall']:.1f} %) | {100 * kept:.2f} % | "
                          f"{100 * m['precision']:.1f} % | {cpu:.2f} | {cpu / clean_cpu:.1f} | {wall:.2f} | "
                          f"{r.seconds:.2f} | {r.seconds / ref.seconds:.1f} |", flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=DEFAULT_DATA, help="dataset root holding posegraphs/")
    ap.add_argument("--datasets", nargs="+", default=list(DATASETS))
    ap.add_argument("--no-replay", action="store_true", help="skip the incremental iSAM2 replay")
    ap.add_argument("--no-inits", action="store_true", help="skip the table of starts")
    ap.add_argument("--outliers", nargs="*", type=int, default=[10, 100, 1000], help="outlier counts (none: skip)")
    ap.add_argument("--outlier-graphs", nargs="+", default=["M3500", "intel"])
    ap.add_argument("--outlier-kinds", nargs="+", default=list(OUTLIER_KINDS))
    ap.add_argument("--methods", nargs="+", default=list(METHODS), help="robust methods of solve_g2o")
    ap.add_argument("--info-scales", nargs="+", type=float, default=[1.0],
                    help="factors on every information matrix of the outlier graphs (the gates must follow)")
    ap.add_argument("--only-tables", action="store_true", help="skip the GTSAM / replay comparison")
    args = ap.parse_args()
    if not args.only_tables:
        compare(args)
    if not args.no_inits:
        starts_table(args.data, args.datasets)
    if args.outliers:
        outlier_table(args.data, args.outlier_graphs, args.outliers, args.outlier_kinds, args.methods,
                      scales=args.info_scales)


def compare(args) -> None:
    """slam2d's reader and batch LM (file start) beside GTSAM's, and the iSAM2 replay."""

    header = (f"{'dataset':8} {'N':>5} {'M':>5}  {'method':22} {'initial':>12} {'final':>10} {'iters':>5} "
              f"{'read s':>7} {'opt s':>7}")
    print(header)
    print("-" * len(header))
    for name in args.datasets:
        path = args.data / "posegraphs" / f"{name}.g2o"
        ref_poses, e0, e1, iters, read_s, opt_s = gtsam_direct(path)
        t0 = time.perf_counter()
        g = read_g2o(path)
        ours_read_s = time.perf_counter() - t0
        ours = solve_g2o(g, init="file")
        n, m = len(g.ids), len(g.i)
        print(f"{name:8} {n:5d} {m:5d}  {'gtsam readG2o + LM':22} {e0:12.6g} {e1:10.6f} {iters:5d} "
              f"{read_s:7.3f} {opt_s:7.3f}")
        print(f"{'':20}  {'slam2d optimize_g2o':22} {ours.initial_error:12.6g} {ours.final_error:10.6f} "
              f"{ours.iterations:5d} {ours_read_s:7.3f} {ours.seconds:7.3f}")
        dxy, dth = max_pose_difference(ours.poses, ref_poses)
        print(f"{'':20}  max |difference|: {dxy:.2e} m, {dth:.2e} rad")
        if not args.no_replay:
            t0 = time.perf_counter()
            pg = replay_g2o(g, BackendConfig(name="pose_graph", robust="none"))
            replay_s = time.perf_counter() - t0
            inc = g2o_error(g, pg.estimate())
            t0 = time.perf_counter()
            final = g2o_error(g, pg.optimize_batch())
            batch_s = time.perf_counter() - t0
            print(f"{'':20}  {'PoseGraph iSAM2 replay':22} {ours.initial_error:12.6g} {inc:10.6f} {'-':>5} "
                  f"{'':7} {replay_s:7.3f}   ({n} keyframes, {pg.num_loops} loops, {pg.factorization})")
            print(f"{'':20}  {'  + optimize_batch':22} {'':12} {final:10.6f} {'':5} {'':7} {batch_s:7.3f}")


if __name__ == "__main__":
    main()
