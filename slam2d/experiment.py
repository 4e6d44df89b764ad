"""Run one experiment config into its own results folder; expand and run sweeps.

A results folder is built under a hidden temporary name and renamed into place
only when everything in it is written, so a failed run leaves no half-written
folder, and an existing folder is never overwritten.
"""

from __future__ import annotations

import copy
import glob
import importlib
import itertools
import json
import logging
import multiprocessing
import os
import re
import resource
import shutil
import signal
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from contextlib import contextmanager, nullcontext
from dataclasses import dataclass
from datetime import datetime
from pathlib import Path
from typing import Any

import numpy as np

from slam2d import config as config_mod
from slam2d.config import ExperimentConfig
from slam2d.errors import InputError

log = logging.getLogger("slam2d")


# --------------------------------------------------------------------------- one run


def run_experiment(cfg: ExperimentConfig, quiet: bool = False, viz: str | Path | None = None) -> Path:
    """Run ``cfg`` end to end; return the results folder. ``viz``: ``"viewer"`` streams the run to
    the rerun viewer, a path ``FILE.rrd`` records it there (:mod:`slam2d.viz`)."""
    with results_folder(cfg.output.root, cfg.name) as (work, published):
        log.info("slam2d run '%s' -> %s", cfg.name, cfg.output.root)
        metrics = _run_into(cfg, work, quiet, viz)
        log.info("done in %.1f s", metrics["runtime_s"])
    return published[0]


@contextmanager
def results_folder(root: str | Path, name: str, key: str = "output.root"):
    """Yield ``(work, published)``: a hidden temporary folder to fill (its log in
    ``run.log``) and a list that receives the final path once the block succeeds.
    On failure the temporary folder is removed, so no half-written folder remains.
    ``key`` names ``root`` in errors (the config key or the CLI option)."""
    root = output_root(root, key)
    work = Path(tempfile.mkdtemp(prefix=f".{name}-", dir=root))
    published: list[Path] = []
    try:
        with _log_to(work / "run.log"):
            yield work, published
        check_stop()  # a signal whose exception was swallowed still leaves no folder
        published.append(_publish(work, root, name))
    except BaseException:
        shutil.rmtree(work, ignore_errors=True)
        raise


def output_root(root: str | Path, key: str = "output.root") -> Path:
    """``root`` with ``~`` expanded, created if missing; an InputError if it is a file or cannot be made."""
    path = Path(root).expanduser()
    if path.exists() and not path.is_dir():
        raise InputError(key, f"{path} is a file, not a folder")
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise InputError(key, f"cannot create folder {path} ({err.strerror})") from None
    return path


def _run_into(cfg: ExperimentConfig, out: Path, quiet: bool, viz: str | Path | None = None) -> dict[str, Any]:
    from slam2d.datasets.registry import open_dataset
    from slam2d.mapping.occupancy import check_resolution
    from slam2d.pipeline import SlamPipeline

    t0 = time.perf_counter()
    check_resolution(cfg.mapping.resolution)
    (out / "config.yaml").write_text(config_mod.dump(resolved(cfg)))
    source = open_dataset(cfg.dataset, seed=cfg.seed)
    relations = _load_relations(cfg)
    pipeline = SlamPipeline(cfg)
    with live_view(viz, cfg.name, "run", cfg.mapping) as view, _progress(source, quiet) as advance:
        result = pipeline.run(source, on_scan=lambda: (check_stop(), advance and advance()), view=view)
    t_slam = time.perf_counter()
    log.info("%d scans processed in %.1f s", len(result.scans), t_slam - t0)
    for key, count in result.stats.items():
        log.info("%s: %d", key, count)

    metrics: dict[str, Any] = {
        "scans": len(result.scans),
        "skipped": dict(result.skipped),
        "invalid_beams": getattr(source, "invalid_beams", 0),
        "slam": result.stats,
        "frontend_fallbacks": result.fallbacks,
        "cpu_ms_per_scan": 1000.0 * result.cpu_s / len(result.scans),
    }
    metrics.update(_evaluate(cfg, result, relations))
    t_eval = time.perf_counter()
    _write_outputs(cfg, result, out)
    t_end = time.perf_counter()
    metrics["timings_s"] = {"slam": t_slam - t0, "evaluation": t_eval - t_slam, "outputs": t_end - t_eval}
    metrics["runtime_s"] = t_end - t0
    metrics["peak_rss_mb"] = _peak_rss_mb()
    (out / "metrics.json").write_text(json_text(metrics))
    _log_summary(metrics)
    return metrics


@contextmanager
def live_view(viz: str | Path | None, name: str, kind: str, *args):
    """Yield None when ``viz`` is None (nothing of rerun is imported), else the view of
    :func:`slam2d.viz.open_view` for a ``kind`` of run (run, localize, explore) made with ``args``,
    streaming to ``viz`` (``"viewer"`` or ``FILE.rrd``) and closed after the block."""
    if viz is None:
        yield None
        return
    from slam2d.viz import open_view

    view = open_view(viz, name, kind, *args)
    try:
        yield view
    finally:
        view.close()


def resolved(cfg):
    """``cfg`` with the frontend's options completed by its defaults (its plugins imported first);
    the config of another command as it is."""
    from slam2d.frontends.base import resolve_options

    if not isinstance(cfg, ExperimentConfig):
        return cfg
    from slam2d.plugins import load_plugins

    load_plugins(cfg.plugins)
    params = resolve_options(cfg.frontend.name, cfg.frontend.options)
    if params is None:
        return cfg
    return cfg.model_copy(update={"frontend": cfg.frontend.model_copy(update={"options": params.model_dump()})})


COMMANDS = {
    "run": ("slam2d.config:ExperimentConfig", "slam2d.experiment:run_experiment"),
    "segment": ("slam2d.segmentation.config:SegmentConfig", "slam2d.segmentation.run:run_segment"),
    "plan": ("slam2d.planning.config:PlanConfig", "slam2d.planning.run:run_plan"),
    "navigate": ("slam2d.navigation.run:NavigateConfig", "slam2d.navigation.run:run_navigate"),
    "explore": ("slam2d.exploration.config:ExploreConfig", "slam2d.exploration.run:run_explore"),
    "localize": ("slam2d.localization.config:LocalizeConfig", "slam2d.localization.run:run_localize"),
}
"""Commands whose configs ``slam2d ablate`` sweeps: (config model, runner taking the config)."""


def _named(target: str):
    module, name = target.split(":")
    return getattr(importlib.import_module(module), name)


def command_model(command: str, key: str = "command"):
    """The config model of ``command`` (a key of :data:`COMMANDS`); InputError naming ``key`` otherwise."""
    if command not in COMMANDS:
        raise InputError(key, f"unknown command {config_mod.short_repr(command)} ({', '.join(COMMANDS)})")
    return _named(COMMANDS[command][0])


def run_command(cfg, quiet: bool = False) -> Path:
    """Run the config of any command of :data:`COMMANDS` into its results folder; return the folder."""
    if type(cfg) is ExperimentConfig:
        return run_experiment(cfg, quiet=quiet)
    for model, runner in COMMANDS.values():
        if type(cfg) is _named(model):
            return _named(runner)(cfg)
    raise TypeError(f"not a command config: {type(cfg).__name__}")


def _load_relations(cfg: ExperimentConfig):
    if not cfg.evaluation.relations:
        return None
    from slam2d.datasets.registry import resolve_data_path
    from slam2d.evaluation.relations import read_relations

    return read_relations(resolve_data_path(cfg.evaluation.relations, key="evaluation.relations"))


def _evaluate(cfg: ExperimentConfig, result, relations) -> dict[str, Any]:
    """ATE/RPE against ground truth, relations metric; each also for raw odometry."""
    from slam2d.evaluation.trajectory import ate, rpe

    ev = cfg.evaluation
    out: dict[str, Any] = {}
    if result.ground_truth is not None:
        for label, est in (("", result.poses), ("odometry_", result.odometry)):
            out[f"{label}ate"] = ate(est, result.ground_truth, align=ev.align)
            out[f"{label}rpe"] = rpe(est, result.ground_truth, delta_m=ev.rpe_delta)
    if relations is not None:
        from slam2d import geometry
        from slam2d.evaluation.relations import relations_frame, relations_metric

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


def _write_outputs(cfg: ExperimentConfig, result, out: Path) -> None:
    from slam2d.evaluation.trajectory import write_tum
    from slam2d.mapping.export import save_map_png, save_map_server
    from slam2d.mapping.occupancy import build_grid
    from slam2d.types import Trajectory

    write_tum(out / "trajectory.tum", Trajectory(result.stamps, result.poses))
    write_tum(out / "odometry.tum", Trajectory(result.stamps, result.odometry))
    if result.ground_truth is not None:
        write_tum(out / "ground_truth.tum", Trajectory(result.stamps, result.ground_truth))
    if result.graph is not None:
        result.graph.write_g2o(out / "graph.g2o")
    grid = build_grid(result.poses, result.scans, cfg.mapping)
    save_map_server(grid, out / "map", cfg.mapping)
    if set(cfg.mapping.layers) - {"grid"}:
        from slam2d.mapping.layers import write_layers

        write_layers(grid, out, cfg.mapping, cfg.output.figures)
    if cfg.output.figures:
        trajectories = {"estimate": result.poses, "odometry": result.odometry}
        if result.ground_truth is not None:
            trajectories["ground truth"] = result.ground_truth
        save_map_png(grid, out / "map.png", trajectories, title=cfg.name)


def _publish(work: Path, root: Path, name: str) -> Path:
    """Rename the finished temporary folder to ``root/name-YYYYmmdd-HHMMSS[-k]``."""
    stem = f"{name}-{datetime.now():%Y%m%d-%H%M%S}"
    for k in itertools.count(1):
        target = root / (stem if k == 1 else f"{stem}-{k}")
        try:
            work.rename(target)  # fails if target exists and is not empty
            return target
        except OSError:
            if not target.exists():
                raise
    raise AssertionError("unreachable")


def _peak_rss_mb() -> float:
    """Peak resident memory (MB) of this process plus its largest finished child (the frontend worker)."""
    kb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss + resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    return kb / 1024.0


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


def json_text(obj) -> str:
    """``obj`` as indented JSON: numpy values as numbers, NaN and infinities as null (JSON has neither)."""
    return json.dumps(_jsonable(obj), indent=2, allow_nan=False)


def _jsonable(obj):
    if isinstance(obj, dict):
        return {str(k): _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return _jsonable(obj.tolist())
    if isinstance(obj, np.generic):
        obj = obj.item()
    if isinstance(obj, float) and not np.isfinite(obj):
        return None  # JSON has no NaN or infinity
    return obj


@contextmanager
def _log_to(path: Path):
    handler = logging.FileHandler(path)
    handler.setFormatter(logging.Formatter("%(asctime)s %(levelname)s %(name)s: %(message)s"))
    logger = logging.getLogger("slam2d")
    logger.addHandler(handler)
    if logger.level == logging.NOTSET or logger.level > logging.INFO:
        logger.setLevel(logging.INFO)
    try:
        yield
    finally:
        logger.removeHandler(handler)
        handler.close()


@contextmanager
def _progress(source, quiet: bool):
    """Yield a callable that advances a progress bar by one scan."""
    if quiet:
        yield None
        return
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TimeRemainingColumn

    try:
        total = len(source)
    except (TypeError, NotImplementedError):
        total = None
    with Progress(
        "[progress.description]{task.description}", BarColumn(), MofNCompleteColumn(), TimeRemainingColumn()
    ) as bar:
        task = bar.add_task(getattr(source, "name", "scans"), total=total)
        yield lambda: bar.advance(task)


# --------------------------------------------------------------------------- sweeps


@dataclass(frozen=True)
class Variant:
    """One row of an ablation: a name and the overrides applied to the base config."""

    name: str
    overrides: dict[str, Any]


@dataclass(frozen=True)
class Sweep:
    """A sweep file read and checked: the base config dict, its variants, workers, the command's
    config model, and the summary spec ({"by": [columns], aggregate: [columns]}, or None)."""

    base: dict[str, Any]
    variants: list[Variant]
    workers: int
    model: type
    summary: dict[str, list[str]] | None = None


SWEEP_KEYS = ("name", "command", "base", "config", "grid", "variants", "workers", "summary")


def read_sweep(path: str | Path) -> Sweep:
    """Read a sweep file and check every variant's config before any runs.

    Keys: ``command`` (a key of :data:`COMMANDS`; default run); ``base`` (config path relative to
    the sweep file) or ``config`` (inline mapping); ``variants`` ([{name, set: {dotted key:
    value}}]) and/or ``grid`` ({dotted key: [values]}, Cartesian product), both given: every
    variant with every grid point; ``workers`` (default 2); ``summary`` (rows grouped by the
    columns ``by``, with ``mean``/``median``/``sum``/``min``/``max`` of the columns listed).
    """
    from slam2d.evaluation.tables import check_summary

    path = Path(path)
    sweep = config_mod.load_dict(path)
    unknown = set(sweep) - set(SWEEP_KEYS)
    if unknown:
        raise InputError(path, f"unknown sweep key '{sorted(unknown)[0]}'")
    model = command_model(sweep.get("command", "run"), f"{path}: command")
    base = _sweep_base(sweep, path)
    variants = _expand(sweep, path)
    if not variants:
        raise InputError(path, "a sweep needs 'grid' or 'variants'")
    names = [v.name for v in variants]
    if len(set(names)) != len(names):
        raise InputError(path, "variant names must be unique")
    for v in variants:  # validate every variant, its frontend included, before running any
        _check_variant(base, v, path, model)
    workers = sweep.get("workers", 2)
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        raise InputError(f"{path}: workers", f"expected a positive integer, got {config_mod.short_repr(workers)}")
    summary = check_summary(sweep["summary"], f"{path}: summary") if "summary" in sweep else None
    return Sweep(base, variants, workers, model, summary)


def load_sweep(path: str | Path) -> tuple[dict[str, Any], list[Variant], int]:
    """(base config dict, variants, workers) of :func:`read_sweep`."""
    sweep = read_sweep(path)
    return sweep.base, sweep.variants, sweep.workers


def _check_variant(base: dict[str, Any], variant: Variant, path: Path, model=None) -> None:
    """Validate ``variant``'s config and frontend options; an InputError names the sweep file and variant."""
    source = f"{path} (variant '{variant.name}')"
    try:
        resolved(variant_config(base, variant, Path("runs"), source, model))
    except InputError as err:
        if err.where.startswith(source):
            raise
        raise InputError(f"{source}: {err.where}", err.what) from None


def _sweep_base(sweep: dict[str, Any], path: Path) -> dict[str, Any]:
    """The base config dict: the file ``base`` names, or the inline ``config`` mapping."""
    if "base" in sweep:
        if not isinstance(sweep["base"], str):
            got = config_mod.short_repr(sweep["base"])
            raise InputError(f"{path}: base", f"expected a config file name, got {got}")
        base_path = path.parent / sweep["base"]
        return _plugins_from(config_mod.load_dict(base_path), base_path.parent)
    base = sweep.get("config") or {}
    if not isinstance(base, dict):
        raise InputError(f"{path}: config", f"expected a mapping of config keys, got {config_mod.short_repr(base)}")
    return _plugins_from(dict(base), path.parent)


def _plugins_from(data: dict[str, Any], folder: Path) -> dict[str, Any]:
    """``data`` with its relative plugin files resolved against ``folder`` (the file that names them)."""
    from slam2d.plugins import resolve

    if isinstance(data.get("plugins"), list):
        data["plugins"] = [resolve(p, folder) if isinstance(p, str) else p for p in data["plugins"]]
    return data


def _expand(sweep: dict[str, Any], path: Path) -> list[Variant]:
    """The variants: the listed ones, the grid points, or each listed one with each grid point."""
    variants = []
    for key, kind in (("variants", list), ("grid", dict)):
        if not isinstance(sweep.get(key) or kind(), kind):
            raise InputError(f"{path}: {key}", f"expected a {kind.__name__}, got {config_mod.short_repr(sweep[key])}")
    for i, item in enumerate(sweep.get("variants") or []):
        if not isinstance(item, dict) or not isinstance(item.get("set"), dict):
            raise InputError(f"{path}: variants[{i}]", "each variant needs 'set', a mapping (and optionally 'name')")
        variants.append(Variant(str(item.get("name", f"v{i}")), dict(item["set"])))
    grid = sweep.get("grid") or {}
    if grid:
        keys = list(grid)
        for key in keys:
            if not isinstance(grid[key], list):
                raise InputError(f"{path}: grid.{key}", "grid values must be lists")
        points = [Variant(",".join(f"{k.split('.')[-1]}={v}" for k, v in zip(keys, combo)), dict(zip(keys, combo)))
                  for combo in itertools.product(*(grid[k] for k in keys))]  # fmt: skip
        variants = [Variant(f"{v.name},{p.name}", {**v.overrides, **p.overrides}) for v in variants for p in points
                    ] if variants else points  # fmt: skip
    return variants


def _apply(data: dict[str, Any], overrides: dict[str, Any]) -> dict[str, Any]:
    """A deep copy of ``data`` with the dotted-key ``overrides`` set."""
    data = copy.deepcopy(data)
    for key, value in overrides.items():
        config_mod.set_key(data, key, value)
    return data


def variant_config(base: dict[str, Any], variant: Variant, root: Path, source: str | None = None, model=None):
    """The config (a ``model``, default ExperimentConfig) of ``variant``: named after it (``/``
    replaced by ``_``), results under ``root``."""
    data = _apply(base, {**variant.overrides, "name": variant.name.replace("/", "_"), "output.root": str(root)})
    return config_mod.validate(data, source or f"variant '{variant.name}'", model)


def _run_variant(cfg: ExperimentConfig) -> tuple[str, dict[str, Any] | None, str | None]:
    """Worker: (folder, metrics, error)."""
    global _RUNNING_VARIANT
    if _STOPPED:
        raise KeyboardInterrupt
    _RUNNING_VARIANT = True
    try:
        folder = run_command(cfg, quiet=True)
        return str(folder), json.loads((folder / "metrics.json").read_text()), None
    except Exception as err:  # reported in the table, the sweep goes on
        if _STOPPED:  # a signal can surface as another error (an interrupted import raises ImportError)
            raise KeyboardInterrupt from err
        return "", None, f"{type(err).__name__}: {err}"
    finally:
        _RUNNING_VARIANT = False


class SweepStopped(KeyboardInterrupt):
    """A sweep stopped by SIGINT or SIGTERM; ``folder`` keeps its finished variants and a table of them."""

    def __init__(self, folder: Path, finished: int, total: int):
        super().__init__(f"{folder}: stopped with {finished} of {total} variants finished")
        self.folder, self.finished, self.total = folder, finished, total


EXECUTORS = ("local", "ray")


def run_sweep(path: str | Path, workers: int | None = None, executor: str = "local", quiet: bool = False,
              resume: str | Path | None = None):
    """Run every variant of a sweep file; write table.md/.csv; return (folder, rows).

    ``resume``: the folder of a stopped sweep of the same file; only variants
    without a finished results folder there are run. A SIGINT (or SIGTERM,
    see :func:`stop_on_signals`) stops the running variants, writes the
    table of the finished ones and raises :class:`SweepStopped`.
    """
    if executor not in EXECUTORS:
        raise InputError("--executor", f"unknown executor '{executor}' ({', '.join(EXECUTORS)})")
    sweep = read_sweep(path)
    base, variants = sweep.base, sweep.variants
    if executor == "ray":
        _connect_ray()  # before the sweep folder: an unreachable cluster leaves none
    root = _sweep_folder(path, base, resume, sweep.model)
    cfgs = [variant_config(base, v, root / "runs", model=sweep.model) for v in variants]
    outcomes = [_finished(root / "runs", c.name) for c in cfgs]
    todo = [i for i, o in enumerate(outcomes) if o is None]
    if resume is not None:
        log.info("%s: %d of %d variants already finished", root, len(variants) - len(todo), len(variants))
    try:
        for i, outcome in _execute([cfgs[i] for i in todo], workers or sweep.workers, executor, quiet):
            outcomes[todo[i]] = outcome
    except BaseException as err:
        if not (isinstance(err, KeyboardInterrupt) or _STOPPED):
            raise
        _write_sweep_table(root, variants, outcomes, sweep.summary)
        raise SweepStopped(root, sum(o is not None and not o[2] for o in outcomes), len(variants)) from None
    return root, _write_sweep_table(root, variants, outcomes, sweep.summary)


def _sweep_folder(path, base: dict[str, Any], resume, model=None) -> Path:
    """``resume`` (checked), else a new folder ``ablate-NAME-YYYYmmdd-HHMMSS[-k]`` holding a copy of the sweep file."""
    if resume is not None:
        root = Path(resume).expanduser()
        if not (root / "sweep.yaml").is_file():
            raise InputError(root, "not a sweep folder (no sweep.yaml): give the folder 'slam2d ablate' printed")
        if (root / "sweep.yaml").read_bytes() != Path(path).read_bytes():
            log.warning("%s differs from the sweep %s was started with; variants are matched by name", path, root)
        for stale in (root / "runs").glob(".*"):  # left by a process killed outright
            shutil.rmtree(stale, ignore_errors=True)
        return root
    name = str(config_mod.load_dict(path).get("name") or Path(path).stem)
    config_mod.validate({"name": name}, f"{path}: name")  # a folder name
    parent = output_root(config_mod.validate(base, str(path), model).output.root)
    root = _new_folder(parent, f"ablate-{name}-{datetime.now():%Y%m%d-%H%M%S}")
    shutil.copyfile(path, root / "sweep.yaml")
    return root


def _new_folder(parent: Path, stem: str) -> Path:
    """Create and return ``parent/stem``, or ``stem-2``, ``stem-3``... if taken (atomic: mkdir)."""
    for k in itertools.count(1):
        folder = parent / (stem if k == 1 else f"{stem}-{k}")
        try:
            folder.mkdir()
            return folder
        except FileExistsError:
            continue
    raise AssertionError("unreachable")


def _finished(runs: Path, name: str) -> tuple[str, dict[str, Any], None] | None:
    """(folder, metrics, None) of a finished run of variant ``name`` under ``runs``; None if there is none."""
    pattern = re.compile(re.escape(name) + r"-\d{8}-\d{6}(-\d+)?")
    for folder in sorted(runs.glob(f"{glob.escape(name)}-*")):
        if pattern.fullmatch(folder.name) and (folder / "metrics.json").is_file():
            return str(folder), json.loads((folder / "metrics.json").read_text()), None
    return None


def _write_sweep_table(root: Path, variants: list[Variant], outcomes: list, summary=None) -> list[dict[str, Any]]:
    """Write table.md/.csv/.tex, summary.md/.csv/.tex (with a summary spec) and report.html: one row
    per variant (unfinished ones say so); return the rows."""
    from slam2d.evaluation.report import write_report
    from slam2d.evaluation.tables import flatten_metrics, summarize, write_table

    rows = []
    for v, outcome in zip(variants, outcomes):
        folder, metrics, error = outcome or ("", None, "not run (sweep stopped)")
        row: dict[str, Any] = {"variant": v.name, **v.overrides}
        if metrics is not None:
            row.update((k, v) for k, v in flatten_metrics(metrics).items() if k not in row)  # a key set wins
        row["error"] = error or ""
        row["folder"] = str(Path(folder).relative_to(root)) if folder else ""
        rows.append(row)
    leading = ["variant", *dict.fromkeys(k for v in variants for k in v.overrides)]
    write_table(rows, root / "table", leading=leading)
    grouped = None
    if summary:
        grouped = summarize(rows, summary)
        write_table(grouped, root / "summary", leading=list(grouped[0]) if grouped else summary["by"], full=True)
    write_report(root, rows, leading, (grouped, summary["by"]) if summary else None)
    return rows


def _execute(cfgs: list[ExperimentConfig], workers: int, executor: str, quiet: bool):
    """Yield (index, (folder, metrics, error)) as variants finish, with a progress bar unless ``quiet``."""
    outcomes = _execute_ray(cfgs) if executor == "ray" else _execute_local(cfgs, workers)
    bar = nullcontext(None)
    if not quiet:
        from rich.progress import Progress

        bar = Progress()
    with bar as progress:
        task = progress.add_task("variants", total=len(cfgs)) if progress else None
        for item in outcomes:
            yield item
            if progress:
                progress.advance(task)


def _execute_ray(cfgs: list[ExperimentConfig]):
    """Variants as Ray tasks on the cluster ``RAY_ADDRESS`` names (else on a new local Ray instance).

    Every run folder ends up in the sweep's ``runs`` folder: a task writes it
    there when that folder is reachable from its machine, else sends it back packed.
    """
    if not cfgs:
        return
    ray = _connect_ray()
    runs = Path(cfgs[0].output.root)
    runs.mkdir(parents=True, exist_ok=True)
    task = ray.remote(_run_variant_anywhere)
    pending = {task.remote(_with_root(c, str(runs.resolve()))): i for i, c in enumerate(cfgs)}
    try:
        while pending:
            (ref,), _ = ray.wait(list(pending), num_returns=1)
            yield pending.pop(ref), _collect(runs, ray.get(ref), type(cfgs[0]))
    except BaseException:
        for ref in pending:
            ray.cancel(ref)
        raise


def _connect_ray():
    """The ``ray`` module, connected to the cluster ``RAY_ADDRESS`` names or to a new local instance."""
    try:
        import ray
    except ImportError:
        raise InputError("--executor ray", "ray is not installed: pip install 'slam2d[ray]'") from None
    try:
        ray.init(ignore_reinit_error=True, log_to_driver=False)
    except ConnectionError as err:
        raise InputError("RAY_ADDRESS", f"cannot reach the Ray cluster ({err})") from None
    return ray


def _with_root(cfg: ExperimentConfig, root: str) -> ExperimentConfig:
    return cfg.model_copy(update={"output": cfg.output.model_copy(update={"root": root})})


def _run_variant_anywhere(cfg: ExperimentConfig) -> tuple[str, dict[str, Any] | None, str | None, bytes | None]:
    """Ray task: (folder, metrics, error, packed). Run in place if ``cfg.output.root`` exists on this
    machine (packed is None), else in a temporary folder sent back as a tar archive."""
    if Path(cfg.output.root).is_dir():
        return (*_run_variant(cfg), None)
    with tempfile.TemporaryDirectory(prefix="slam2d-variant-") as tmp:
        folder, metrics, error = _run_variant(_with_root(cfg, tmp))
        return folder, metrics, error, (_pack(Path(folder)) if folder else None)


def _pack(folder: Path) -> bytes:
    """The contents of ``folder`` as a gzipped tar archive."""
    import io
    import tarfile

    buffer = io.BytesIO()
    with tarfile.open(fileobj=buffer, mode="w:gz") as tar:
        tar.add(folder, arcname=".")
    return buffer.getvalue()


def _collect(runs: Path, outcome, model=None) -> tuple[str, dict[str, Any] | None, str | None]:
    """A Ray task's outcome as (folder under ``runs``, metrics, error); a packed folder is unpacked there.
    ``model``: the variants' config model (default ExperimentConfig)."""
    import io
    import tarfile

    folder, metrics, error, packed = outcome
    if not folder:
        return "", metrics, error
    if packed is None:
        return str(runs / Path(folder).name), metrics, error
    dest = _new_folder(runs, Path(folder).name)
    with tarfile.open(fileobj=io.BytesIO(packed), mode="r:gz") as tar:
        tar.extractall(dest, filter="data")
    config = dest / "config.yaml"  # names the task's temporary folder: name the runs folder instead
    cfg = config_mod.validate(config_mod.load_dict(config), str(config), model)
    config.write_text(config_mod.dump(_with_root(cfg, str(runs))))
    return str(dest), metrics, error


def _execute_local(cfgs: list[ExperimentConfig], workers: int):
    """Variants in worker processes; on an interrupt the queued ones are dropped and the running ones stopped."""
    if not cfgs:
        return
    # forkserver, not fork: a worker forked from a process that has run numba's parallel kernels (GNU
    # OpenMP) aborts as soon as it runs them itself (a localize sweep started after a localisation)
    pool = ProcessPoolExecutor(max_workers=max(1, workers), mp_context=multiprocessing.get_context("forkserver"),
                               initializer=_init_sweep_worker)
    try:
        futures = {pool.submit(_run_variant, c): i for i, c in enumerate(cfgs)}
        for fut in as_completed(futures):
            yield futures[fut], fut.result()
    except BaseException:
        _stop_pool(pool)
        raise
    pool.shutdown()


def _stop_pool(pool: ProcessPoolExecutor) -> None:
    """Cancel queued work, send SIGTERM to the workers (each removes its half-written folder), wait for them."""
    processes = list((getattr(pool, "_processes", None) or {}).values())
    pool.shutdown(wait=False, cancel_futures=True)
    for process in processes:
        if process.is_alive():
            process.terminate()
    for process in processes:
        process.join(30)
        if process.is_alive():
            process.kill()
            process.join()


def _handler(stop):
    """A signal handler calling ``stop()`` in this process; a forked child that inherits it dies as by default."""
    pid = os.getpid()

    def handler(signum, frame):
        if os.getpid() != pid:
            signal.signal(signum, signal.SIG_DFL)
            os.kill(os.getpid(), signum)
            return
        stop()

    return handler


_STOPPED = False  # whether SIGINT or SIGTERM has arrived in this process (in a sweep worker: no new variant)
_RUNNING_VARIANT = False  # in a sweep worker: whether a variant is running


@contextmanager
def stop_on_signals():
    """In the block SIGINT and SIGTERM raise KeyboardInterrupt (half-written folders are removed) and are
    remembered: :func:`stopped` tells an error the signal caused (an interrupted import raises ImportError)."""

    def stop():
        global _STOPPED
        _STOPPED = True
        raise KeyboardInterrupt

    handler = _handler(stop)
    previous = {sig: signal.signal(sig, handler) for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield
    finally:
        for sig, old in previous.items():
            signal.signal(sig, old)


def stopped() -> bool:
    """Whether SIGINT or SIGTERM has arrived since :func:`stop_on_signals`."""
    return _STOPPED


def check_stop() -> None:
    """KeyboardInterrupt if a signal has arrived: its own exception may have been swallowed (in a ``__del__``)."""
    if _STOPPED:
        raise KeyboardInterrupt


def _init_sweep_worker() -> None:
    """The first SIGINT or SIGTERM stops a sweep worker: its running variant is interrupted (its folder
    removed) and queued ones are not started; later signals are ignored so that the clean-up finishes."""

    def stop():
        global _STOPPED
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        signal.signal(signal.SIGTERM, signal.SIG_IGN)
        _STOPPED = True
        if _RUNNING_VARIANT:
            raise KeyboardInterrupt

    handler = _handler(stop)
    signal.signal(signal.SIGINT, handler)
    signal.signal(signal.SIGTERM, handler)
