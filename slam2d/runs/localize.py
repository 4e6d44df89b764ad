"""``slam2d localize``: Monte Carlo localisation on a known map — a map and a scan stream in,
a results folder out.

The stream is the simulated robot wandering a world (``world``, by default the map
itself when it is the office or a floor plan; ``kidnap`` teleports it) or a log
(``--dataset EXPERIMENT.yaml``: its ``dataset`` section), whose reference is a TUM
trajectory (by default the ``trajectory.tum`` of the slam2d run that made the
map). The folder holds the resolved config, the estimate and the truth or
reference (TUM), ``error.csv`` (error, particle count, cluster share, state over time),
the figures (error and particles over time, the particle cloud at chosen
times) and ``metrics.json``.
"""

from __future__ import annotations

import logging
import math
from pathlib import Path
from typing import Any

import numpy as np

from slam2d import config as config_mod
from slam2d import geometry
from slam2d.datasets.registry import open_dataset
from slam2d.errors import InputError, check_inside
from slam2d.evaluation.trajectory import read_tum, write_tum
from slam2d.localization.config import LocalizeConfig
from slam2d.localization.maps import KnownMap
from slam2d.localization.mcl import STATES, ParticleFilter
from slam2d.localization.scenario import (
    PERIOD,
    Stream,
    Track,
    converged_at,
    false_convergence,
    final_state,
    replay,
    wander,
)
from slam2d.paths import resolve_data_path
from slam2d.runs.results import json_text, live_view, progress_bar, results_folder
from slam2d.sim.world import load_world
from slam2d.types import Trajectory

log = logging.getLogger(__name__)

__all__ = ["localize", "log_stream", "metrics_of", "run_localize"]


KNOWN_MAP_RESOLUTION = 0.05  # m per pixel of a floor-plan image unless `resolution` says otherwise


def run_localize(cfg: LocalizeConfig, quiet: bool = False, viz: str | Path | None = None) -> Path:
    """Localise on ``cfg.map`` with the scans of ``cfg.dataset`` (None: the simulated robot) into a new
    results folder under ``cfg.output.root``; return it. ``viz``: ``"viewer"`` or ``FILE.rrd``, the
    particles streamed to rerun (:class:`slam2d.viz.ParticleView`)."""
    cfg.filter_config()  # the mcl keys are checked before any work
    map_path = _map_path(cfg.map)
    known = KnownMap.load(map_path, cfg.resolution or KNOWN_MAP_RESOLUTION)
    dataset = _dataset(cfg.dataset)
    name = cfg.name or "localize"
    with results_folder(cfg.output.root, name) as (work, published), live_view(viz, name, "localize", known) as view:
        metrics = localize(known, cfg, work, map_path=map_path, dataset=dataset, view=view, quiet=quiet)
        log.info("position RMSE %.3f m, heading RMSE %.2f deg, median %d particles, %.1f ms per update, ends %s",
                 metrics["position_rmse"], metrics["heading_rmse_deg"], metrics["particles_median"],
                 metrics["update_ms_median"], metrics["final_state"])  # fmt: skip
    return published[0]


def _map_path(name: str | None) -> Path:
    """The map file ``name`` names (here or under SLAM2D_DATA), or ``office``."""

    if name is None:
        raise InputError("map", "no map given (map: FILE in the config, or slam2d localize MAP)")
    return Path(name) if name == "office" else resolve_data_path(name, key="map")


def _dataset(path: str | None):
    """The experiment config whose dataset section is the scan log, or None (the simulator)."""
    if path is None:
        return None

    return config_mod.load(resolve_data_path(path, key="dataset"))


def localize(known: KnownMap, cfg: LocalizeConfig, out: Path, map_path: Path | None = None,
             dataset=None, view=None, quiet: bool = False) -> dict[str, Any]:  # fmt: skip
    """One run into the folder ``out`` (``view``: a live view of the filter, or None; a progress bar on a
    terminal unless ``quiet``); returns the metrics."""

    loc, mcl = cfg.localization, cfg.filter_config()
    resolved = cfg.model_copy(update={"localization": loc.model_copy(update={"mcl": mcl.model_dump()})})
    (out / "config.yaml").write_text(config_mod.dump(resolved))
    stream, truth_name = (_sim_stream(known, cfg, map_path) if dataset is None
                          else log_stream(dataset, cfg, map_path))  # fmt: skip
    if not stream.scans:
        raise InputError("dataset", "no scans to localise with")
    pf = ParticleFilter(known, mcl, stream.scans[0].range_max, seed=cfg.seed)
    if loc.mode == "global":
        pf.init_global()
    else:
        start = loc.initial_pose if loc.initial_pose is not None else stream.truth[0]
        if not np.isfinite(np.asarray(start, dtype=np.float64)).all():
            raise InputError("initial_pose", "tracking needs an initial pose (no reference pose at the first scan)")
        check_inside("initial_pose", start, known.extent)
        pf.init_pose(start)
    with progress_bar("localising (scans)", len(stream.scans), quiet) as advance:
        track = replay(pf, stream, "updates" if cfg.output.figures else (), view, advance)
    metrics = metrics_of(stream, track, pf)
    metrics["reference"] = truth_name
    _write_results(out, stream, track, metrics, known, cfg)
    (out / "metrics.json").write_text(json_text(metrics) + "\n")
    return metrics


# --------------------------------------------------------------------------- streams


def _sim_stream(known: KnownMap, cfg: LocalizeConfig, map_path: Path | None) -> tuple[Stream, str]:

    world_name = cfg.localization.world
    if world_name is None:
        if map_path is not None and (str(map_path) == "office" or map_path.suffix.lower() == ".png"):
            world_name = str(map_path)
        else:
            raise InputError("world", "a simulated run on a map.yaml needs a world: --set world=office (or a PNG), "
                             "or a log: --dataset EXPERIMENT.yaml")
    world = load_world(world_name)
    loc = cfg.localization
    return wander(world, known, loc.seconds, cfg.seed, kidnap_at=loc.kidnap, min_jump=loc.min_jump), "truth"


def log_stream(dataset, cfg: LocalizeConfig, map_path: Path | None) -> tuple[Stream, str]:
    """The scans of ``dataset`` (an ExperimentConfig), the reference interpolated at their stamps
    (NaN outside it or without one) and the odometry's travelled distance."""

    loc = cfg.localization
    source = open_dataset(dataset.dataset.model_copy(update={"max_scans": loc.max_scans or
                                                             dataset.dataset.max_scans}), seed=cfg.seed)
    scans = list(source)
    ref_path = Path(loc.reference) if loc.reference else (map_path.parent / "trajectory.tum" if map_path else None)
    stamps = np.array([s.stamp for s in scans])
    truth = np.full((len(scans), 3), np.nan)
    name = "none"
    if ref_path is not None and ref_path.is_file():
        ref = read_tum(ref_path)
        inside = (stamps >= ref.stamps[0]) & (stamps <= ref.stamps[-1])
        if inside.any():
            truth[inside] = geometry.interpolate(ref.stamps, ref.poses, stamps[inside])
        name = str(ref_path)
    elif loc.reference:
        raise InputError("reference", f"{loc.reference}: trajectory file not found")
    odom = np.array([s.odom for s in scans]).reshape(-1, 3)
    moved = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(odom[:, :2], axis=0).T))])
    return Stream(scans, truth, moved, []), name


# --------------------------------------------------------------------------- metrics


def metrics_of(stream: Stream, track: Track, pf) -> dict[str, Any]:
    """Errors (over the run and after convergence), convergence and recovery, particles and timing."""

    stamps = stream.stamps - stream.stamps[0]
    ok = np.isfinite(track.position_error)
    conv = converged_at(track)
    after = np.zeros(len(ok), bool)
    if conv is not None:
        after[conv:] = True
        for k in stream.kidnaps:  # a kidnapping is not tracking
            after[k:] = False
    m: dict[str, Any] = {
        "scans": len(stream.scans),
        "updates": pf.updates,
        "resamples": pf.resamples,
        "position_rmse": _rms(track.position_error[ok]),
        "heading_rmse_deg": math.degrees(_rms(track.heading_error[ok])),
        "position_rmse_converged": _rms(track.position_error[ok & after]),
        "heading_rmse_converged_deg": math.degrees(_rms(track.heading_error[ok & after])),
        "converged_s": float(stamps[conv]) if conv is not None else None,
        "converged_travel_m": float(stream.travelled[conv]) if conv is not None else None,
        "false_convergence": bool(false_convergence(track)),
        "states": {name: int(np.sum(track.state == name)) for name in STATES} if track.state is not None else None,
        "final_state": final_state(track),
        "particles_median": float(np.median(track.particles)),
        "particles_median_converged": float(np.median(track.particles[after])) if after.any() else None,
        "update_ms_median": float(np.median(track.update_ms)) if len(track.update_ms) else None,
        "beams_skipped_share": float(pf.sharp_beams[1] / pf.sharp_beams[0]) if pf.sharp_beams[0] else 0.0,
        "travelled_m": float(stream.travelled[-1]),
        "kidnaps": [],
    }
    for k in stream.kidnaps:
        back = converged_at(track, k)
        m["kidnaps"].append({"at_s": float(stamps[k]), "recovered_s": None if back is None else (back - k) * PERIOD})
    return m


def _rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(x**2))) if len(x) else float("nan")


# --------------------------------------------------------------------------- files and figures


def _write_results(out: Path, stream: Stream, track: Track, metrics: dict, known: KnownMap, cfg) -> None:

    stamps = stream.stamps
    write_tum(out / "trajectory.tum", Trajectory(stamps, track.estimates))
    has = np.isfinite(stream.truth).all(axis=1)
    if has.any():
        write_tum(out / ("ground_truth.tum" if metrics["reference"] == "truth" else "reference.tum"),
                  Trajectory(stamps[has], stream.truth[has]))  # fmt: skip
    rows = np.column_stack([stamps - stamps[0], track.position_error, np.degrees(track.heading_error),
                            track.particles, track.share])  # fmt: skip
    states = track.state if track.state is not None else np.full(len(rows), "tracking")
    with open(out / "error.csv", "w") as f:
        f.write("t_s,position_error_m,heading_error_deg,particles,cluster_share,state\n")
        f.writelines(",".join(f"{v:.6g}" for v in row) + f",{state}\n" for row, state in zip(rows, states))
    if cfg.output.figures:
        _figures(out, stream, track, known, cfg)


def _snapshot_choice(stream: Stream, track: Track, cfg) -> dict[str, int]:
    """Scan index of each particle-cloud figure: the config's times, or the first update, converging,
    converged and after each kidnap (the nearest kept snapshot)."""

    kept = np.array(sorted(track.snapshots))
    if len(kept) == 0:
        return {}
    t = stream.stamps - stream.stamps[0]
    if cfg.localization.snapshots:
        wanted = {f"t{s:g}s": int(np.searchsorted(t, s)) for s in cfg.localization.snapshots}
    else:
        conv = converged_at(track)
        wanted = {"first_update": int(kept[0])}
        if conv is not None:
            wanted["converging"] = int(kept[0] + (conv - kept[0]) // 2)
            wanted["converged"] = conv
        for n, k in enumerate(stream.kidnaps):
            wanted[f"kidnap{n + 1}_after_1s"] = k + 10
            back = converged_at(track, k)
            if back is not None:
                wanted[f"kidnap{n + 1}_recovered"] = back
    return {name: int(kept[min(np.searchsorted(kept, i), len(kept) - 1)]) for name, i in wanted.items()}


def _figures(out: Path, stream: Stream, track: Track, known: KnownMap, cfg) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t = stream.stamps - stream.stamps[0]
    fig, (a1, a2) = plt.subplots(2, 1, figsize=(8, 5), sharex=True)
    a1.semilogy(t, np.maximum(track.position_error, 1e-3), lw=0.8)
    a1.set_ylabel("position error (m)")
    for k in stream.kidnaps:
        a1.axvline(t[k], color="tab:red", ls="--", lw=0.8)
    a2.semilogy(t, track.particles, lw=0.8)
    a2.set_ylabel("particles")
    a2.set_xlabel("t (s)")
    fig.savefig(out / "error_particles.png", dpi=110, bbox_inches="tight")
    plt.close(fig)
    for name, i in _snapshot_choice(stream, track, cfg).items():
        _cloud_figure(out / f"cloud_{name}.png", known, stream, track, i, plt)


def _cloud_figure(path: Path, known: KnownMap, stream: Stream, track: Track, i: int, plt) -> None:
    particles, weights, estimate = track.snapshots[i]
    fig, ax = plt.subplots(figsize=(8, 6))
    x0, x1, y0, y1 = known.extent
    ax.imshow(np.where(known.occupied, 0.0, np.where(known.free, 1.0, 0.8)), cmap="gray", origin="lower",
              extent=(x0, x1, y0, y1), vmin=0, vmax=1, interpolation="nearest")  # fmt: skip
    ax.quiver(particles[:, 0], particles[:, 1], np.cos(particles[:, 2]), np.sin(particles[:, 2]),
              weights, cmap="viridis", scale=40, width=0.002)  # fmt: skip
    truth = stream.truth[i]
    if np.isfinite(truth).all():
        ax.plot(*truth[:2], "o", mfc="none", mec="tab:green", ms=12, label="true")
    ax.plot(*estimate[:2], "x", color="tab:red", ms=10, label="estimate")
    ax.set_title(f"t = {stream.stamps[i] - stream.stamps[0]:.1f} s, {track.particles[i]} particles, "
                 f"error {track.position_error[i]:.2f} m")  # fmt: skip
    ax.legend(loc="upper right", fontsize=8)
    ax.set_aspect("equal")
    fig.savefig(path, dpi=110, bbox_inches="tight")
    plt.close(fig)
