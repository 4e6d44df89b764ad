"""``slam2d optimize``: one batch optimisation of a pose graph file (g2o or TORO), written as a results
folder: ``config.yaml``, the optimised ``graph.g2o``, ``edges.csv`` (each edge: loop, injected, kept as
an inlier), ``overlay.png`` and ``metrics.json``."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Literal

import numpy as np
from pydantic import Field, field_validator

from slam2d import config as config_mod
from slam2d.backend import batch
from slam2d.backend.consistency import edge_rows
from slam2d.config import OutputConfig, Section, folder_name
from slam2d.datasets import g2o
from slam2d.errors import InputError
from slam2d.paths import resolve_data_path
from slam2d.runs.results import json_text, results_folder

__all__ = ["OptimizeConfig", "run_optimize"]


class OptimizeConfig(Section):
    """``slam2d optimize``: the graph file, the robust cost and start, false loops to inject, a reference."""

    name: str | None = Field(None, description="results folder name (default: optimize-<graph stem>)")
    seed: int = Field(0, ge=0, lt=2**63, description="seed of the outlier injection")
    graph: str | None = Field(None, description="2D pose graph, g2o or TORO (relative: here, then SLAM2D_DATA)")
    init: str | None = Field(None, description="chordal, spanning_tree or file (default: chordal; spanning_tree "
                             "under an M-estimator; pc_dcs: the spanning tree and the screened chordal start, the "
                             "lower DCS cost kept; GNC: warm-started from pc_dcs's solution)")
    robust: str = Field("none", description="none, huber, cauchy, dcs, gnc (TLS), gnc_tls, gnc_gm or pc_dcs "
                        "(pairwise-consistency screen, then DCS: for false loop closures)")
    robust_param: float = Field(1.0, description="M-estimator width, whitened units (sigmas); Phi of dcs, pc_dcs")
    outliers: int = Field(0, ge=0, le=1_000_000, description="false loop closures to inject before optimising")
    outlier_kind: Literal["random", "local", "group"] = Field("random", description="group: clusters of 10")
    reference: str | None = Field(None, description="g2o whose poses are the reference for the RMSE")
    verify: bool = Field(True, description="also optimise from two other starts and check they agree")
    output: OutputConfig = OutputConfig()

    @field_validator("name")
    @classmethod
    def _folder_name(cls, name: str | None) -> str | None:
        return None if name is None else folder_name(name)


def run_optimize(cfg: OptimizeConfig, quiet: bool = False) -> Path:
    """Optimise ``cfg.graph`` into a new results folder under ``cfg.output.root``; return the folder."""
    if cfg.graph is None:
        raise InputError("graph", "no pose graph given (graph: FILE in the config, or slam2d optimize GRAPH)")
    graph_path = resolve_data_path(cfg.graph, key="graph")
    reference = resolve_data_path(cfg.reference, key="reference") if cfg.reference else None
    with results_folder(cfg.output.root, cfg.name or f"optimize-{graph_path.stem}") as (work, published):
        _optimize_into(work, cfg, graph_path, reference)
    return published[0]


def _optimize_into(work: Path, cfg: OptimizeConfig, graph_path: Path, reference: Path | None) -> dict:
    """Read, inject, solve and write config.yaml, graph.g2o, edges.csv, overlay.png, metrics.json to ``work``;
    metrics.json's ``timings`` add the wall time (s) of reading (and injecting), writing and the figure to the
    solve's steps. The files but metrics.json are written while the solution is certified (``solve_g2o``'s
    ``meanwhile``), again after it only if the verification changed the solution."""
    t0 = time.perf_counter()
    graph = g2o.read_g2o(graph_path)
    injected = np.zeros(len(graph.i), bool)
    if cfg.outliers:
        graph, injected = g2o.inject_outliers(graph, cfg.outliers, cfg.outlier_kind, cfg.seed)
    ref = batch.reference_poses(graph, g2o.read_g2o(reference)) if reference else None
    read_s = time.perf_counter() - t0
    written: dict = {}

    def files(result) -> None:
        written.update(_write_files(work, cfg, graph, injected, result, ref), result=result)

    result = batch.solve_g2o(graph, cfg.robust, cfg.robust_param, cfg.init, cfg.verify, meanwhile=files)
    if not _same_solution(written.get("result"), result):
        files(result)
    t0 = time.perf_counter()
    metrics = batch.g2o_metrics(graph, result, injected if cfg.outliers else None, ref)
    steps = {"read": read_s, **metrics["timings"], "write": written["write"] + time.perf_counter() - t0,
             "figure": written["figure"]}
    metrics["timings"] = {k: round(v, 6) for k, v in steps.items()}
    (work / "metrics.json").write_text(json_text(metrics) + "\n")
    return metrics


def _write_files(work: Path, cfg: OptimizeConfig, graph, injected, result, ref) -> dict:
    """Write config.yaml, graph.g2o, edges.csv and overlay.png of ``result``; wall times (s) of the files
    (``write``) and of the figure."""
    t0 = time.perf_counter()
    (work / "config.yaml").write_text(config_mod.dump(cfg.model_copy(update={"init": result.init})))
    g2o.write_g2o(work / "graph.g2o", g2o.PoseGraphFile(graph.ids, result.poses, graph.i, graph.j,
                                                         graph.measurements, graph.information))
    rows = ["i,j,loop,injected,inlier"] + [
        f"{a},{b},{int(lp)},{int(x)},{int(k)}" for a, b, lp, x, k in
        zip(graph.i.tolist(), graph.j.tolist(), (~g2o.odometry_mask(graph)).tolist(), injected.tolist(),
            result.inlier.tolist())]
    (work / "edges.csv").write_text("\n".join(rows) + "\n")
    t1 = time.perf_counter()
    _overlay_figure(work / "overlay.png", graph, result, ref)
    return {"write": t1 - t0, "figure": time.perf_counter() - t1}


def _same_solution(a, b) -> bool:
    """Whether BatchResults ``a`` (None: none) and ``b`` have the same start, poses and inliers (the same files)."""
    return (a is not None and a.init == b.init and np.array_equal(a.poses, b.poses)
            and np.array_equal(a.inlier, b.inlier))


FIGURE_PX = 960  # overlay.png: the longer side of the drawing (px)


def _overlay_figure(path: Path, graph, result, reference) -> None:
    """Start (grey), optimised (blue), reference (green) trajectories and rejected loops (red), north up,
    with a scale bar and a legend. Drawn with PIL: no plotting library is loaded."""
    from PIL import Image, ImageDraw, ImageFont

    tracks = [graph.poses[:, :2], result.poses[:, :2]] + ([] if reference is None else [reference[:, :2]])
    every = np.vstack(tracks)
    low, high = every.min(0), every.max(0)
    margin, band = 20, 40  # px around the drawing, px below it for the legend
    scale = (FIGURE_PX - 2 * margin) / max(float((high - low).max()), 1e-9)  # px per m
    w, h = (np.ceil((high - low) * scale).astype(int) + 2 * margin).tolist()
    image = Image.new("RGB", (w, h + band), "white")
    draw, font = ImageDraw.Draw(image), ImageFont.load_default(size=12)

    def px(xy: np.ndarray) -> np.ndarray:
        return np.column_stack([margin + (xy[:, 0] - low[0]) * scale, h - margin - (xy[:, 1] - low[1]) * scale])

    a, b = edge_rows(graph)
    rejected = ~result.inlier
    for x0, y0, x1, y1 in np.hstack([px(result.poses[a[rejected]]), px(result.poses[b[rejected]])]).tolist():
        draw.line([(x0, y0), (x1, y1)], fill=(214, 39, 40), width=1)
    legend = [("file start", (179, 179, 179), graph.poses)]
    if reference is not None:
        legend.append(("reference", (44, 160, 44), reference))
    legend.append((f"optimised ({result.init})", (31, 119, 180), result.poses))
    for _, colour, poses in legend:
        draw.line(px(poses).ravel().tolist(), fill=colour, width=2 if colour == (44, 160, 44) else 1)
    if rejected.any():
        legend.append((f"rejected loops ({int(rejected.sum())})", (214, 39, 40), None))
    x = margin
    for label, colour, _ in legend:
        draw.line([(x, h + band // 2), (x + 20, h + band // 2)], fill=colour, width=3)
        draw.text((x + 25, h + band // 2 - 7), label, fill="black", font=font)
        x += 35 + int(draw.textlength(label, font=font))
    metres = 10.0 ** np.floor(np.log10(max((high - low).max() / 5, 1e-9)))
    y = h - 8
    draw.line([(margin, y), (margin + metres * scale, y)], fill="black", width=3)
    draw.text((margin, y - 16), f"{metres:g} m", fill="black", font=font)
    image.save(path, compress_level=1)
