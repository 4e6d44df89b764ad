"""The SLAM run's evaluation files beside its trajectories: ``ape.png`` (APE over time and along the path),
``relations.csv/png`` (every scored relation's error), ``loops.csv/png`` (the loop-closure timeline) and
``spans.csv`` (the map's wall-to-wall spans against the simulator's plan); ``session.npz``, what a later
run goes on from (``slam2d run --continue`` / ``--localize-in``)."""

from __future__ import annotations

import csv
import zipfile
from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from slam2d import geometry
from slam2d.backend.session import Session
from slam2d.config import ExperimentConfig
from slam2d.errors import InputError
from slam2d.evaluation.map_accuracy import measure_spans, span_summary, span_table
from slam2d.evaluation.relations import relation_errors
from slam2d.evaluation.trajectory import align_se2
from slam2d.sim.spans import spans_of

__all__ = ["SESSION_FILE", "ape_figure", "read_session", "write_loops", "write_relations", "write_session"]

SESSION_FILE = "session.npz"


def write_session(path: Path, session: Session) -> None:
    """``session`` (:class:`slam2d.backend.session.Session`) as compressed numpy arrays at ``path``."""
    np.savez_compressed(path, **session.arrays())


def read_session(folder) -> Session:
    """The session a results folder (or its ``session.npz``) holds; an InputError naming it if none."""
    path = Path(folder).expanduser()
    if path.is_dir():
        path = path / SESSION_FILE
    if not path.is_file():
        raise InputError(path, "no saved session (a results folder of 'slam2d run' with the pose_graph back end)")
    try:
        with np.load(path, allow_pickle=False) as arrays:
            return Session.from_arrays({k: arrays[k] for k in arrays.files}, where=str(path))
    except (OSError, ValueError, EOFError, zipfile.BadZipFile) as err:
        raise InputError(path, f"not a readable session ({err})") from None


def write_relations(out: Path, cfg: ExperimentConfig, result, relations, frame: str) -> None:
    """relations.csv (every scored relation: its stamps and the errors of the estimate and of odometry) and
    relations.png (their histograms), scored in ``frame`` as the metric is."""
    mounts = np.array([s.sensor_pose for s in result.scans])
    errors = {}
    for label, est in (("estimate", result.poses), ("odometry", result.odometry)):
        poses = geometry.compose(est, mounts) if frame == "laser" else est
        errors[label] = relation_errors(result.stamps, poses, relations, cfg.evaluation.relation_tolerance)
    ok = errors["estimate"][2]
    table = np.column_stack([relations.t1[ok], relations.t2[ok], *errors["estimate"][:2], *errors["odometry"][:2]])
    np.savetxt(out / "relations.csv", table, delimiter=",", fmt="%.6f", comments="",
               header="t1_s,t2_s,trans_m,rot_deg,odometry_trans_m,odometry_rot_deg")
    if not cfg.output.figures or not ok.any():
        return
    fig = Figure(figsize=(11, 4))
    FigureCanvasAgg(fig)
    for ax, k, unit in zip(fig.subplots(1, 2), (0, 1), ("translational error (m)", "rotational error (deg)")):
        top = max(1.05 * float(errors["estimate"][k].max()), 1e-9)  # odometry beyond it: the last bin
        bins = np.linspace(0.0, top, 60)
        for label, colour in (("odometry", "0.6"), ("estimate", "tab:blue")):
            ax.hist(np.clip(errors[label][k], 0, top), bins=bins, color=colour, alpha=0.7, label=label)
        ax.set_yscale("log")
        ax.set_xlabel(unit)
        ax.set_ylabel("relations")
        ax.legend(fontsize="small")
    worst = np.argsort(errors["estimate"][0])[::-1][:3]
    fig.suptitle(f"{int(ok.sum())} relations ({frame} frame); worst: " + ", ".join(
        f"{errors['estimate'][0][w]:.3f} m at {relations.t1[ok][w]:.1f}-{relations.t2[ok][w]:.1f} s" for w in worst),
        fontsize="small")  # fmt: skip
    fig.savefig(out / "relations.png", dpi=110, bbox_inches="tight")


def ape_figure(path: Path, stamps, estimate, truth, align: bool = True) -> None:
    """APE (m, position error against ground truth, after the SE(2) alignment of the ATE when ``align``) over
    time, and the trajectory coloured by it (as evo_ape's plots)."""
    if align:
        estimate = geometry.compose(align_se2(estimate, truth), estimate)
    err = np.hypot(*(estimate[:, :2] - truth[:, :2]).T)
    fig = Figure(figsize=(12, 4.8))
    FigureCanvasAgg(fig)
    over_time, along = fig.subplots(1, 2, gridspec_kw={"width_ratios": [1.2, 1]})
    t = np.asarray(stamps) - stamps[0]
    over_time.plot(t, err, lw=0.8, color="tab:blue")
    for value, style in ((np.sqrt(np.mean(err**2)), "--"), (np.median(err), ":")):
        over_time.axhline(value, color="tab:red", lw=0.8, ls=style)
    over_time.set_xlabel("time (s)")
    over_time.set_ylabel("APE (m)")
    over_time.set_title(f"APE: RMSE {np.sqrt(np.mean(err**2)):.4f} m (dashed), median {np.median(err):.4f} m (dotted)",
                        fontsize="small")
    along.plot(truth[:, 0], truth[:, 1], color="0.75", lw=2.0, zorder=1, label="ground truth")
    dots = along.scatter(estimate[:, 0], estimate[:, 1], c=err, s=3, cmap="viridis", zorder=2)
    fig.colorbar(dots, ax=along, label="APE (m)")
    along.set_aspect("equal")
    along.set_xlabel("x (m)")
    along.set_ylabel("y (m)")
    along.legend(loc="best", fontsize="small")
    fig.savefig(path, dpi=110, bbox_inches="tight")


def write_loops(out: Path, result, figures: bool = True) -> None:
    """``loops.csv``: every loop closure the graph took (keyframes, their first scans' times, kept or removed
    by the final check) and ``loops.png``: when each closed, against the time it closed to, with the count
    over time. Nothing without a pose graph with keyframes."""
    if result.graph is None or result.keyframes is None or not hasattr(result.graph, "loop_edges"):
        return
    edges = result.graph.loop_edges()
    t = np.asarray(result.stamps, float) - result.stamps[0]
    first = np.full(int(result.keyframes.max()) + 1, np.nan)
    first[result.keyframes[::-1]] = t[::-1]  # time (s) of each keyframe's first scan
    ti, tj = first[edges[:, 0]], first[edges[:, 1]]
    table = np.column_stack([edges[:, :2], ti, tj, edges[:, 2]])
    np.savetxt(out / "loops.csv", table, delimiter=",", fmt=["%d", "%d", "%.6f", "%.6f", "%d"], comments="",
               header="keyframe_i,keyframe_j,t_i_s,t_j_s,kept")
    if not figures or not len(edges):
        return
    later, earlier = np.maximum(ti, tj), np.minimum(ti, tj)
    kept = edges[:, 2] == 1
    fig = Figure(figsize=(11, 4.5))
    FigureCanvasAgg(fig)
    pairs, count = fig.subplots(1, 2, gridspec_kw={"width_ratios": [1, 1.2]})
    pairs.plot([0, t[-1]], [0, t[-1]], color="0.8", lw=0.8)
    pairs.scatter(later[kept], earlier[kept], s=6, color="tab:blue", label=f"kept ({int(kept.sum())})")
    pairs.scatter(later[~kept], earlier[~kept], s=14, color="tab:red", marker="x",
                  label=f"removed by the final check ({int((~kept).sum())})")  # fmt: skip
    pairs.set_xlabel("closed at (s)")
    pairs.set_ylabel("closed to (s)")
    pairs.set_aspect("equal")
    pairs.legend(loc="upper left", fontsize="small")
    order = np.argsort(later, kind="stable")
    count.step(later[order], np.cumsum(kept[order]), where="post", color="tab:blue", label="kept")
    count.step(later[order], np.cumsum(~kept[order]), where="post", color="tab:red", label="removed")
    count.set_xlim(0, t[-1])
    count.set_xlabel("time (s)")
    count.set_ylabel("loop closures so far")
    count.legend(loc="upper left", fontsize="small")
    fig.suptitle("loop-closure timeline (loops rejected by the matcher are counted in metrics.json only)",
                 fontsize="small")
    fig.savefig(out / "loops.png", dpi=110, bbox_inches="tight")


def grid_points(grid) -> tuple[np.ndarray, np.ndarray]:
    """The grid's wall surfaces as points and viewpoints (M, 2) m in the grid's frame: the centre of each
    occupied cell beside a rather free one (seen, occupancy below one half), and that cell's centre (once per
    such 4-neighbour)."""
    occupied, free = grid.occupied_mask(), np.pad(grid.log_odds < 0, 1)
    cells = np.argwhere(occupied)
    points, views = [], []
    for step in ((0, 1), (0, -1), (1, 0), (-1, 0)):
        beside = cells + step
        seen = free[beside[:, 0] + 1, beside[:, 1] + 1]
        points.append(cells[seen])
        views.append(beside[seen])
    return grid.cell_to_world(np.concatenate(points)), grid.cell_to_world(np.concatenate(views))


def write_map_accuracy(out: Path, world, seed: int, to_truth, grid, scans=None) -> dict:
    """``spans.csv``: ``world``'s wall-to-wall spans (:func:`slam2d.sim.spans.spans_of`) measured in the map,
    from the grid's wall cells and, with ``scans`` (scans and their base poses), from the registered scan
    endpoints; both in the map frame that the pose ``to_truth`` carries onto the world's. Returns their
    summaries (``grid``, ``points``)."""
    spans = spans_of(world, seed)
    maps = {"grid": grid_points(grid)} | ({} if scans is None else {"points": scan_points(*scans)})
    measured = {label: measure_spans(geometry.transform_points(to_truth, points), spans,
                                     geometry.transform_points(to_truth, views))
                for label, (points, views) in maps.items()}  # fmt: skip
    rows = span_table(spans, measured)
    with (out / "spans.csv").open("w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    return {label: span_summary(spans, values) for label, values in measured.items()}


def scan_points(scans, poses) -> tuple[np.ndarray, np.ndarray]:
    """Every scan's endpoints at its base pose (M, 2) m and the laser's position each was seen from."""
    points, views = [], []
    for scan, pose in zip(scans, poses):
        hits = geometry.transform_points(pose, scan.points_in_base())
        points.append(hits)
        views.append(np.broadcast_to(geometry.compose(pose, scan.sensor_pose)[:2], hits.shape))
    return np.concatenate(points), np.concatenate(views)
