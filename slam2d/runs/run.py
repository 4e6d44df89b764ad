"""``slam2d run``: one SLAM experiment config end to end into its results folder."""

from __future__ import annotations

import logging
import time
from pathlib import Path
from typing import Any

import numpy as np

from slam2d import config as config_mod
from slam2d import geometry
from slam2d.config import ExperimentConfig
from slam2d.datasets.registry import open_dataset
from slam2d.evaluation.relations import (
    read_relations,
    relations_frame,
    relations_metric,
)
from slam2d.evaluation.trajectory import align_se2, ate, rpe, write_tum
from slam2d.mapping.export import save_map_png, save_map_server
from slam2d.mapping.layers import write_layers
from slam2d.mapping.occupancy import build_grid, check_resolution
from slam2d.paths import resolve_data_path
from slam2d.pipeline import SlamPipeline
from slam2d.runs.commands import resolved
from slam2d.runs.results import (
    json_text,
    live_view,
    peak_rss_mb,
    progress,
    results_folder,
    snake_keys,
)
from slam2d.runs.signals import check_stop
from slam2d.runs.slam_outputs import (
    SESSION_FILE,
    ape_figure,
    read_session,
    write_loops,
    write_map_accuracy,
    write_relations,
    write_session,
)
from slam2d.sim.world import load_world
from slam2d.types import Trajectory

log = logging.getLogger("slam2d")


def run_experiment(cfg: ExperimentConfig, quiet: bool = False, viz: str | Path | None = None) -> Path:
    """Run ``cfg`` end to end; return the results folder. ``viz``: ``"viewer"`` streams the run to
    the rerun viewer, a path ``FILE.rrd`` records it there (:mod:`slam2d.viz`)."""
    with results_folder(cfg.output.root, cfg.name) as (work, published):
        log.info("slam2d run '%s' -> %s", cfg.name, cfg.output.root)
        metrics = _run_into(cfg, work, quiet, viz)
        log.info("done in %.1f s", metrics["runtime_s"])
    return published[0]


def _run_into(cfg: ExperimentConfig, out: Path, quiet: bool, viz: str | Path | None = None) -> dict[str, Any]:

    t0 = time.perf_counter()
    check_resolution(cfg.mapping.resolution)
    (out / "config.yaml").write_text(config_mod.dump(resolved(cfg)))
    source = open_dataset(cfg.dataset, seed=cfg.seed)
    relations = _load_relations(cfg)
    saved = cfg.session.continue_from or cfg.session.localize_in
    session = None if saved is None else read_session(saved)
    pipeline = SlamPipeline(cfg)
    with live_view(viz, cfg.name, "run", cfg.mapping) as view, progress(source, quiet) as advance:
        result = pipeline.run(source, on_scan=lambda: (check_stop(), advance and advance()), view=view,
                              session=session, localize=cfg.session.localize_in is not None)
    t_slam = time.perf_counter()
    log.info("%d scans processed in %.1f s", len(result.scans), t_slam - t0)
    for key, count in result.stats.items():
        log.info("%s: %d", key, count)

    metrics: dict[str, Any] = {
        "scans": len(result.scans),
        "skipped": snake_keys(result.skipped),
        "invalid_beams": getattr(source, "invalid_beams", 0),
        "slam": snake_keys(result.stats),
        "frontend_fallbacks": result.fallbacks,
        "cpu_ms_per_scan": 1000.0 * result.cpu_s / max(len(result.scans) - (len(session) if session else 0), 1),
    }
    if session is not None:
        metrics["saved_scans"] = len(session)  # of the scans, those of the saved session (not in cpu_ms_per_scan)
    metrics.update(_evaluate(cfg, result, relations))
    t_eval = time.perf_counter()
    grid = _write_outputs(cfg, result, out)
    if cfg.dataset.kind == "simulator" and result.ground_truth is not None:
        metrics["map_accuracy"] = _map_accuracy(out, cfg, result, grid)
    if relations is not None:
        write_relations(out, cfg, result, relations, metrics["relations"]["frame"])
    t_end = time.perf_counter()
    metrics["timings_s"] = {"slam": t_slam - t0, "evaluation": t_eval - t_slam, "outputs": t_end - t_eval}
    metrics["runtime_s"] = t_end - t0
    metrics["peak_rss_mb"] = peak_rss_mb()
    (out / "metrics.json").write_text(json_text(metrics))
    _log_summary(metrics)
    return metrics


def _map_accuracy(out: Path, cfg: ExperimentConfig, result, grid) -> dict[str, Any]:
    """The simulator world's spans in the map: its grid and the scan endpoints at the estimate."""
    sim = cfg.dataset.simulator
    summary = write_map_accuracy(out, load_world(sim.world, sim.resolution), cfg.seed,
                                 align_se2(result.poses, result.ground_truth), grid, (result.scans, result.poses))
    log.info("map accuracy: %d of %d spans seen; mean |error| %.1f mm at the scan endpoints, %.1f mm in the grid",
             summary["points"]["seen"], summary["points"]["spans"],
             1000 * summary["points"].get("mean_abs_error_m", np.nan),
             1000 * summary["grid"].get("mean_abs_error_m", np.nan))  # fmt: skip
    return summary


def _load_relations(cfg: ExperimentConfig):
    if not cfg.evaluation.relations:
        return None

    return read_relations(resolve_data_path(cfg.evaluation.relations, key="evaluation.relations"))


def _evaluate(cfg: ExperimentConfig, result, relations) -> dict[str, Any]:
    """ATE/RPE against ground truth, relations metric; each also for raw odometry."""
    ev = cfg.evaluation
    out: dict[str, Any] = {}
    if result.ground_truth is not None:
        for label, est in (("", result.poses), ("odometry_", result.odometry)):
            out[f"{label}ate"] = ate(est, result.ground_truth, align=ev.align)
            out[f"{label}rpe"] = rpe(est, result.ground_truth, delta_m=ev.rpe_delta)
    if relations is not None:
        mounts = np.array([s.sensor_pose for s in result.scans])
        frame, evidence = relations_frame(result.stamps, result.odometry, mounts, relations, ev.relation_tolerance)
        log.info("relations scored in the %s frame (odometry on short turns: %s)", frame, evidence)
        for label, est in (("", result.poses), ("odometry_", result.odometry)):
            poses = geometry.compose(est, mounts) if frame == "laser" else est
            m = relations_metric(result.stamps, poses, relations, tolerance=ev.relation_tolerance)
            out[f"{label}relations"] = m | {"frame": frame, "frame_test": evidence}
        if out["relations"]["unmatched"]:
            log.warning(
                "%d of %d relations match no scan stamp within %g s and are not scored",
                out["relations"]["unmatched"],
                out["relations"]["unmatched"] + out["relations"]["matched"],
                ev.relation_tolerance,
            )
    return out


def _write_outputs(cfg: ExperimentConfig, result, out: Path):
    """The trajectories, graph, map and figures; returns the map (OccupancyGrid)."""
    write_tum(out / "trajectory.tum", Trajectory(result.stamps, result.poses))
    write_tum(out / "odometry.tum", Trajectory(result.stamps, result.odometry))
    if result.ground_truth is not None:
        write_tum(out / "ground_truth.tum", Trajectory(result.stamps, result.ground_truth))
    if result.graph is not None:
        result.graph.write_g2o(out / "graph.g2o")
    if result.session is not None:
        write_session(out / SESSION_FILE, result.session)
    grid = build_grid(result.poses, result.scans, cfg.mapping)
    save_map_server(grid, out / "map", cfg.mapping)
    if set(cfg.mapping.layers) - {"grid"}:
        write_layers(grid, out, cfg.mapping, cfg.output.figures)
    if cfg.output.figures:
        trajectories = {"estimate": result.poses, "odometry": result.odometry}  # the estimate drawn on top
        if result.ground_truth is not None:
            trajectories["ground truth"] = result.ground_truth
        save_map_png(grid, out / "map.png", trajectories, title=cfg.name)
        if result.ground_truth is not None:
            ape_figure(out / "ape.png", result.stamps, result.poses, result.ground_truth, cfg.evaluation.align)
    write_loops(out, result, cfg.output.figures)
    return grid


def _log_summary(metrics: dict[str, Any]) -> None:
    for key in ("ate", "odometry_ate"):
        if key in metrics:
            log.info("%s: RMSE %.3f m", key.replace("_", " "), metrics[key]["rmse"])
    for key in ("relations", "odometry_relations"):
        if key in metrics:
            m = metrics[key]
            log.info(
                "%s: translational %.4f ± %.4f m, rotational %.3f ± %.3f deg (%d relations)",
                key.replace("_", " "),
                m["trans_abs_mean"],
                m["trans_abs_std"],
                m["rot_abs_mean"],
                m["rot_abs_std"],
                m["matched"],
            )
