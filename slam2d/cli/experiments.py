"""The commands that run an experiment into a results folder: run, ablate, dump-config, segment, plan,
map, optimize, navigate, explore, localize."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Optional

import typer

from slam2d.cli.common import (
    CONFIG_ARG,
    CONFIG_OPT,
    JSON_OPT,
    NOT_REACHED,
    OUT_SET_OPT,
    PLUGIN_OPT,
    QUIET_OPT,
    SET_OPT,
    VIZ_OPT,
    VIZ_SAVE_OPT,
    _command,
    _command_config,
    _config_file,
    _echo_metrics,
    _fail,
    _layer_names,
    _results,
    _stopped,
    _viz_target,
    _xy,
    app,
)
from slam2d.errors import InputError


@app.command()
def run(
    config: Optional[Path] = CONFIG_ARG, config_opt: Optional[Path] = CONFIG_OPT, set_: list[str] = SET_OPT,
    root: Optional[Path] = OUT_SET_OPT, plugin: list[str] = PLUGIN_OPT, quiet: bool = QUIET_OPT,
    viz: bool = VIZ_OPT, viz_save: Optional[Path] = VIZ_SAVE_OPT, as_json: bool = JSON_OPT,
    continue_from: Optional[Path] = typer.Option(
        None, "--continue", help="results folder whose session this run continues (session.continue_from)"),
    localize_in: Optional[Path] = typer.Option(
        None, "--localize-in", help="results folder whose map this run starts in, pose unknown, and merges with "
        "(session.localize_in)"),
) -> None:
    """Run one experiment; print the results folder."""
    from slam2d.runs.run import run_experiment

    with _command(quiet):
        target = _viz_target(viz, viz_save)
        flags = {"output.root": root, "session.continue_from": continue_from and continue_from.resolve(),
                 "session.localize_in": localize_in and localize_in.resolve()}
        cfg = _command_config("run", _config_file(config, config_opt), set_, flags, plugin)
        folder = run_experiment(cfg, quiet=quiet, viz=target)
    _results("run", folder, as_json)


@app.command()
def ablate(
    sweep: Path = typer.Argument(..., help="sweep YAML: base config + grid or list of overrides"),
    workers: Optional[int] = typer.Option(None, "--workers", "-j", help="parallel processes (default: sweep's)"),
    executor: str = typer.Option("local", help="local (processes) or ray"),
    resume: Optional[Path] = typer.Option(None, help="folder of a stopped sweep: run only its missing variants"),
    set_: list[str] = typer.Option([], "--set", "-s", help="override a key of the base config, e.g. --set seed=1"),
    grid: list[str] = typer.Option([], "--grid", "-g", help="a grid axis, e.g. --grid frontend.name=icp,lines"),
    dry_run: bool = typer.Option(False, "--dry-run", help="check every variant and list them; run nothing"),
    root: Optional[Path] = typer.Option(None, "--out", "-o", help="the sweep folder is created under this "
                                        "(the base config's output.root)"),
    quiet: bool = QUIET_OPT,
    as_json: bool = typer.Option(False, "--json", help="print one JSON object on stdout: the sweep folder, its "
                                 "tables and failed variants (with --dry-run: the variants)"),
) -> None:
    """Run every variant of a sweep in parallel; write one table (Markdown + CSV)."""
    from slam2d.runs.results import output_root
    from slam2d.runs.sweep import SweepStopped, read_sweep, run_sweep

    with _command(quiet, "no sweep folder written"):
        if root is not None:
            output_root(root, "--out")  # its error names the option
            set_ = [*set_, f"output.root={root}"]
        if dry_run:
            checked = read_sweep(sweep, set_, grid)
            if as_json:
                typer.echo(json.dumps({"variants": [{"name": v.name, "overrides": v.overrides}
                                                    for v in checked.variants]}, default=str))
                return
            for v in checked.variants:
                typer.echo(f"{v.name}: " + ", ".join(f"{k}={val}" for k, val in v.overrides.items()))
            typer.echo(f"{len(checked.variants)} variants checked; nothing run")
            return
        try:
            folder, rows = run_sweep(sweep, workers=workers, executor=executor, quiet=quiet, resume=resume,
                                     overrides=set_, grid=grid)
        except SweepStopped as stop:
            _stopped(f"{stop.finished} of {stop.total} variants finished in {stop.folder}; "
                     f"resume with: slam2d ablate {sweep} --resume {stop.folder}")
    if not quiet:
        typer.echo((folder / "table.md").read_text(), err=as_json)
    failed = [r["variant"] for r in rows if r["error"]]
    if as_json:
        typer.echo(json.dumps({"folder": str(folder), "table_md": str(folder / "table.md"),
                               "table_csv": str(folder / "table.csv"), "report": str(folder / "report.html"),
                               "failed": failed}))
    else:
        typer.echo(f"table: {folder / 'table.md'} and {folder / 'table.csv'}; report: {folder / 'report.html'}")
    if failed:
        typer.secho(f"{len(failed)} of {len(rows)} variants failed: {', '.join(failed)}", fg="red", err=True)
        raise typer.Exit(1)


@app.command("dump-config")
def dump_config(
    config: Optional[Path] = CONFIG_ARG, config_opt: Optional[Path] = CONFIG_OPT, set_: list[str] = SET_OPT,
    plugin: list[str] = PLUGIN_OPT,
    command: str = typer.Option("run", "--command", help="whose config: run, segment, plan, map, optimize, "
                                "navigate, explore or localize"),
    describe: bool = typer.Option(False, "--describe", help="each key's description as a comment"),
) -> None:
    """Print the fully resolved config (defaults included) as YAML."""
    from slam2d import config as config_mod
    from slam2d.runs.commands import command_model, resolved

    try:
        command_model(command, "--command")
        cfg = _command_config(command, _config_file(config, config_opt), set_, {}, plugin)
        typer.echo(config_mod.dump(resolved(cfg), describe), nl=False)
    except InputError as err:
        _fail(err)


@app.command()
def segment(
    map_path: Optional[Path] = typer.Argument(None, help="floor-plan PNG (free = white, 0.05 m/px) or a map.yaml "
                                              "(the config's map)"),
    config: Optional[Path] = CONFIG_OPT,
    method: Optional[str] = typer.Option(None, help="spectral, morphological, distance or voronoi "
                                         "(segmentation.method; default spectral)"),
    similarity: Optional[str] = typer.Option(None, help="hausdorff, nearest_neighbour, feature_points or "
                                             "visibility (segmentation.similarity; default visibility)"),
    ground_truth: Optional[Path] = typer.Option(None, help="GT room image (default: <stem>_gt_segmentation.png)"),
    set_: list[str] = SET_OPT,
    root: Optional[Path] = OUT_SET_OPT,
    quiet: bool = QUIET_OPT,
    as_json: bool = JSON_OPT,
) -> None:
    """Split a map into rooms: colour image, topological graph, metrics (a config, or the map and flags)."""
    from slam2d.runs.segment import run_segment

    with _command(quiet):
        cfg = _command_config("segment", config, set_, {
            "map": map_path, "segmentation.method": method, "segmentation.similarity": similarity,
            "ground_truth": ground_truth, "output.root": root})
        folder = run_segment(cfg)
    if not as_json:
        _echo_metrics(folder, ("rooms", "k", "recall", "precision", "seconds"))
    _results("segment", folder, as_json)


@app.command()
def plan(
    map_path: Optional[Path] = typer.Argument(None, help="map.yaml, Moving AI .map, or floor-plan PNG (0.05 m/px) "
                                              "(the config's map)"),
    config: Optional[Path] = CONFIG_OPT,
    start: Optional[str] = typer.Option(None, help="x,y in metres (planning.start)"),
    goal: Optional[str] = typer.Option(None, help="x,y in metres (planning.goal)"),
    hierarchical: Optional[str] = typer.Option(None, help="jps, jps_plus, subgoal (exact, faster than A*), hpa (square "
                                               "clusters) or rooms (planning.hierarchy)"),
    labels: Optional[Path] = typer.Option(None, help="room label image (labels.png of slam2d segment); default: "
                                          "the map's segmentation (segmentation.*, morphological)"),
    robot_radius: Optional[float] = typer.Option(None, help="obstacle inflation, m (planning.robot_radius, 0.2)"),
    set_: list[str] = SET_OPT,
    root: Optional[Path] = OUT_SET_OPT,
    quiet: bool = QUIET_OPT,
    as_json: bool = JSON_OPT,
) -> None:
    """Plan a path (A* or hierarchical), smooth it, time it with toppra; write figures. With
    planning.queries > 0: many seeded queries against A* (suboptimality, speed-up)."""
    from slam2d.planning.query import NoPathError
    from slam2d.runs.plan import run_plan

    with _command(quiet):
        try:
            cfg = _command_config("plan", config, set_, {
                "map": map_path, "planning.start": _xy(start, "start"), "planning.goal": _xy(goal, "goal"),
                "planning.hierarchy": hierarchical, "planning.labels": labels,
                "planning.robot_radius": robot_radius, "output.root": root})
            folder = run_plan(cfg)
        except NoPathError as err:
            typer.secho(f"no path: {err}", fg="red", err=True)
            raise typer.Exit(1) from None
    if not as_json:
        _echo_metrics(folder, ("length_m", "duration_s", "nodes_expanded", "plan_ms", "queries", "failures",
                               "mean_subopt_pct", "median_speedup"))
    _results("plan", folder, as_json)


@app.command("map")
def map_layers(
    map_path: Optional[Path] = typer.Argument(None, help="map.yaml (map_server), or a floor-plan image (0.05 m/px) "
                                              "(the config's map)"),
    config: Optional[Path] = CONFIG_OPT,
    layers: Optional[str] = typer.Option(None, help="comma-separated: sparse, quadtree, lines, mesh (default: all)"),
    wall_height: Optional[float] = typer.Option(None, help="wall height of the mesh, m (default 2.5)"),
    set_: list[str] = SET_OPT,
    root: Optional[Path] = OUT_SET_OPT,
    quiet: bool = QUIET_OPT,
    as_json: bool = JSON_OPT,
) -> None:
    """Make mapping layers (sparse, quadtree, line map, wall mesh) of an existing map."""
    from slam2d.runs.map import run_map

    with _command(quiet):
        if wall_height is not None and not wall_height > 0:
            raise InputError("--wall-height", f"must be > 0 m, got {wall_height}")
        cfg = _command_config("map", config, set_, {
            "map": map_path, "layers": _layer_names(layers), "wall_height": wall_height, "output.root": root})
        folder = run_map(cfg)
    if not as_json:
        stats = json.loads((folder / "metrics.json").read_text())
        typer.echo(" ".join(f"{k}={v['bytes']}B" for k, v in stats.items() if "bytes" in v), err=True)
    _results("map", folder, as_json)


@app.command()
def optimize(
    graph_path: Optional[Path] = typer.Argument(None, help="2D pose graph, g2o or TORO (the config's graph)"),
    config: Optional[Path] = CONFIG_OPT,
    init: Optional[str] = typer.Option(None, help="chordal, spanning_tree or file (default: chordal; "
                                       "spanning_tree under an M-estimator; pc_dcs: spanning tree and screened "
                                       "chordal, the lower DCS cost kept; GNC: from pc_dcs's solution)"),
    robust: Optional[str] = typer.Option(None, help="none, huber, cauchy, dcs, gnc (TLS), gnc_tls, gnc_gm or "
                                         "pc_dcs (pairwise-consistency screen, then DCS: for false loop closures)"),
    robust_param: Optional[float] = typer.Option(None, help="M-estimator width, whitened units (sigmas); Phi of "
                                                 "dcs, pc_dcs (default 1)"),
    outliers: Optional[int] = typer.Option(None, help="false loop closures to inject before optimising"),
    outlier_kind: Optional[str] = typer.Option(None, help="random, local or group (clusters of 10)"),
    seed: Optional[int] = typer.Option(None, help="seed of the outlier injection"),
    reference: Optional[Path] = typer.Option(None, help="g2o whose poses are the reference for the RMSE"),
    verify: Optional[bool] = typer.Option(None, "--verify/--no-verify",
                                          help="also optimise from two other starts and check they agree (default)"),
    set_: list[str] = SET_OPT,
    root: Optional[Path] = OUT_SET_OPT,
    quiet: bool = QUIET_OPT,
    as_json: bool = JSON_OPT,
) -> None:
    """Optimise a pose graph in one batch: optimised g2o, overlay figure, metrics."""
    from slam2d.runs.optimize import run_optimize

    with _command(quiet):
        cfg = _command_config("optimize", config, set_, {
            "graph": graph_path, "init": init, "robust": robust, "robust_param": robust_param,
            "outliers": outliers, "outlier_kind": outlier_kind, "seed": seed, "reference": reference,
            "verify": verify, "output.root": root})
        folder = run_optimize(cfg)
    if not as_json:
        _echo_metrics(folder, ("kept_edges_error", "robust_cost", "iterations", "gnc_steps", "seconds", "verified",
                               "certified", "loops_rejected", "precision", "recall", "rmse_to_reference"), digits=6)
    _results("optimize", folder, as_json)


@app.command()
def navigate(
    config: Optional[Path] = CONFIG_ARG, config_opt: Optional[Path] = CONFIG_OPT,
    goal: Optional[str] = typer.Option(None, help="x,y[,heading] in m (rad); overrides navigation.goal"),
    set_: list[str] = SET_OPT, root: Optional[Path] = OUT_SET_OPT, plugin: list[str] = PLUGIN_OPT,
    quiet: bool = QUIET_OPT, as_json: bool = JSON_OPT,
) -> None:
    """Drive the simulated robot to a goal (online SLAM on by default); print the results folder. Exit 3 when
    the goal was not reached (unreachable, blocked, out of time): the results are written all the same."""
    from slam2d.runs.navigate import run_navigate

    with _command(quiet):
        extra = [f"navigation.goal=[{goal}]"] if goal else []
        cfg = _command_config("navigate", _config_file(config, config_opt), [*set_, *extra], {"output.root": root},
                              plugin)
        folder = run_navigate(cfg, quiet)
    _results("navigate", folder, as_json)
    metrics = json.loads((folder / "metrics.json").read_text())
    if not metrics.get("success"):
        typer.secho(f"goal not reached: {metrics.get('status')} ({metrics.get('reason')}); results written",
                    fg="red", err=True)
        raise typer.Exit(NOT_REACHED)


@app.command()
def explore(
    config: Optional[Path] = CONFIG_ARG, config_opt: Optional[Path] = CONFIG_OPT,
    strategy: Optional[str] = typer.Option(
        None, help="nearest_frontier, explore_lite, nearest_candidate, farthest_candidate or utility"
    ),
    set_: list[str] = SET_OPT, root: Optional[Path] = OUT_SET_OPT,
    quiet: bool = QUIET_OPT, viz: bool = VIZ_OPT, viz_save: Optional[Path] = VIZ_SAVE_OPT,
    as_json: bool = JSON_OPT,
) -> None:
    """Explore the simulated world with SLAM in the loop until no goal is left; print the results folder."""
    from slam2d.runs.explore import run_explore

    with _command(quiet):
        target = _viz_target(viz, viz_save)
        cfg = _command_config("explore", _config_file(config, config_opt), set_, {
            "exploration.strategy": strategy, "output.root": root})
        folder = run_explore(cfg, quiet, target)
    _results("explore", folder, as_json)


@app.command()
def localize(
    map_path: Optional[str] = typer.Argument(None, help="map.yaml (a slam2d run or map_server), floor-plan PNG, "
                                             "or 'office' (the config's map)"),
    dataset: Optional[Path] = typer.Option(None, help="experiment YAML whose dataset is the scan log "
                                           "(default: the simulated robot wandering the map's world)"),
    config: Optional[Path] = CONFIG_OPT,
    set_: list[str] = SET_OPT,
    root: Optional[Path] = OUT_SET_OPT,
    quiet: bool = QUIET_OPT, viz: bool = VIZ_OPT, viz_save: Optional[Path] = VIZ_SAVE_OPT,
    as_json: bool = JSON_OPT,
) -> None:
    """Monte Carlo localisation on a known map: estimate vs truth, errors, particle clouds, metrics."""
    from slam2d.runs.localize import run_localize

    with _command(quiet):
        target = _viz_target(viz, viz_save)
        cfg = _command_config("localize", config, set_, {"map": map_path, "dataset": dataset, "output.root": root})
        folder = run_localize(cfg, quiet, target)
    _results("localize", folder, as_json)
