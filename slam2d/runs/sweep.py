"""Sweeps over any command: read and check a sweep file, run its variants in processes or on Ray,
stop on signals, resume, and write the table of results."""

from __future__ import annotations

import copy
import glob
import io
import itertools
import json
import logging
import multiprocessing
import os
import re
import shutil
import tarfile
import tempfile
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from contextlib import nullcontext
from dataclasses import dataclass
from datetime import datetime
from pathlib import Path
from typing import Any

from rich.progress import Progress

from slam2d import config as config_mod
from slam2d.config import ExperimentConfig
from slam2d.errors import InputError
from slam2d.evaluation.report import write_report
from slam2d.evaluation.tables import (
    check_summary,
    flatten_metrics,
    summarize,
    write_table,
)
from slam2d.plugins import resolve
from slam2d.processes import reap_when_gone
from slam2d.runs import signals
from slam2d.runs.commands import command_of, resolved, run_command
from slam2d.runs.results import new_folder, output_root, progress_console, remove_stale, shows_progress, writes

log = logging.getLogger("slam2d")


@dataclass(frozen=True)
class Variant:
    """One row of an ablation: a name and the overrides applied to the base config."""

    name: str
    overrides: dict[str, Any]


@dataclass(frozen=True)
class Sweep:
    """A sweep file read and checked: the base config dict, its variants, workers, the command's
    config model, the summary spec ({"by": [columns], aggregate: [columns]}, or None) and the
    command's main metrics (the table's first columns after the variant's keys)."""

    base: dict[str, Any]
    variants: list[Variant]
    workers: int
    model: type
    summary: dict[str, list[str]] | None = None
    main_metrics: tuple[str, ...] = ()


SWEEP_KEYS = ("name", "command", "base", "config", "grid", "variants", "workers", "summary")


def read_sweep(path: str | Path, overrides: list[str] = (), grid: list[str] = ()) -> Sweep:
    """Read a sweep file and check every variant's config before any runs.

    Keys: ``command`` (a key of :data:`COMMANDS`; default run); ``base`` (config path relative to
    the sweep file) or ``config`` (inline mapping); ``variants`` ([{name, set: {dotted key:
    value}}]) and/or ``grid`` ({dotted key: [values]}, Cartesian product), both given: every
    variant with every grid point; ``workers`` (default 2); ``summary`` (rows grouped by the
    columns ``by``, with ``mean``/``median``/``sum``/``min``/``max`` of the columns listed).
    ``overrides`` (``key=value``, as ``--set``) change the base config; ``grid`` (``key=a,b,c``) adds
    a grid axis (or replaces the file's axis of that key).
    """

    path = Path(path)
    sweep = config_mod.load_dict(path)
    unknown = set(sweep) - set(SWEEP_KEYS)
    if unknown:
        raise InputError(path, f"unknown sweep key '{min(unknown)}'")
    if "base" in sweep and "config" in sweep:
        raise InputError(path, "give the base config as 'base' (a file) or 'config' (inline), not both")
    command = command_of(sweep.get("command", "run"), f"{path}: command")
    model = command.config_model()
    base = _sweep_base(sweep, path)
    for key, value in map(config_mod.parse_override, overrides):
        config_mod.set_key(base, key, value)
    if grid:
        sweep["grid"] = {**(sweep.get("grid") or {}), **dict(map(grid_axis, grid))}
    variants = _expand(sweep, path)
    if not variants:
        raise InputError(path, "a sweep needs 'grid' or 'variants'")
    names = [v.name for v in variants]
    if len(set(names)) != len(names):
        raise InputError(path, "variant names must be unique")
    for v in variants:  # validate every variant, its frontend included, before running any
        _check_variant(base, v, path, model)
    workers = check_workers(sweep.get("workers", 2), f"{path}: workers")
    summary = check_summary(sweep["summary"], f"{path}: summary") if "summary" in sweep else None
    return Sweep(base, variants, workers, model, summary, command.main_metrics)


MAX_WORKERS = 256
"""Most worker processes a sweep runs at once."""


def check_workers(workers, key: str) -> int:
    """``workers`` if it is an integer from 1 to MAX_WORKERS, else an InputError naming ``key``."""
    if isinstance(workers, bool) or not isinstance(workers, int) or not 1 <= workers <= MAX_WORKERS:
        raise InputError(key, f"expected a positive integer up to {MAX_WORKERS}, got {config_mod.short_repr(workers)}")
    return workers


def grid_axis(text: str) -> tuple[str, list[Any]]:
    """``'key=a,b,c'`` as the key and its YAML-parsed values (``--grid``)."""
    key, _ = config_mod.parse_override(text)
    raw = text.split("=", 1)[1]
    values = [config_mod.parse_override(f"{key}={v}")[1] for v in raw.split(",")]
    if not raw.strip() or not values:
        raise InputError(f"--grid {text}", "expected KEY=A,B,..., e.g. frontend.name=icp,lines")
    return key, values


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
    if signals.orphaned():  # the sweep's process is gone: start nothing, write nothing
        os._exit(143)
    if signals.stopped():
        raise KeyboardInterrupt
    try:
        with signals.variant_running():
            try:
                folder = run_command(cfg, quiet=True)
                return str(folder), json.loads((folder / "metrics.json").read_text()), None
            except Exception as err:  # reported in the table, the sweep goes on
                if signals.stopped():  # a signal can surface as another error (an interrupted import: ImportError)
                    raise KeyboardInterrupt from err
                return "", None, f"{type(err).__name__}: {err}"
    except KeyboardInterrupt:
        if signals.orphaned():  # its folder is removed; nobody is left to tell
            os._exit(143)
        raise


class SweepStopped(KeyboardInterrupt):
    """A sweep stopped by SIGINT or SIGTERM; ``folder`` keeps its finished variants and a table of them."""

    def __init__(self, folder: Path, finished: int, total: int):
        super().__init__(f"{folder}: stopped with {finished} of {total} variants finished")
        self.folder, self.finished, self.total = folder, finished, total


EXECUTORS = ("local", "ray")
WAIT_S = 0.5  # how often a sweep waiting for its variants checks for a signal (s)


def run_sweep(path: str | Path, workers: int | None = None, executor: str = "local", quiet: bool = False,
              resume: str | Path | None = None, overrides: list[str] = (), grid: list[str] = ()):
    """Run every variant of a sweep file; write table.md/.csv; return (folder, rows).

    ``resume``: the folder of a stopped sweep of the same file; only variants
    without a finished results folder there are run. A SIGINT (or SIGTERM,
    see :func:`stop_on_signals`) stops the running variants, writes the
    table of the finished ones and raises :class:`SweepStopped`.
    """
    if executor not in EXECUTORS:
        raise InputError("--executor", f"unknown executor '{executor}' ({', '.join(EXECUTORS)})")
    if workers is not None:
        check_workers(workers, "--workers")
    sweep = read_sweep(path, overrides, grid)
    base, variants = sweep.base, sweep.variants
    if executor == "ray":
        _connect_ray()  # before the sweep folder: an unreachable cluster leaves none
    with writes("output.root" if resume is None else resume):
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
        if not (isinstance(err, KeyboardInterrupt) or signals.stopped()):
            raise
        with writes(root):
            _write_sweep_table(root, variants, outcomes, sweep.summary, sweep.main_metrics)
        raise SweepStopped(root, sum(o is not None and not o[2] for o in outcomes), len(variants)) from None
    with writes(root):
        return root, _write_sweep_table(root, variants, outcomes, sweep.summary, sweep.main_metrics)


def _sweep_folder(path, base: dict[str, Any], resume, model=None) -> Path:
    """``resume`` (checked), else a new folder ``ablate-NAME-YYYYmmdd-HHMMSS[-k]`` holding a copy of the sweep file."""
    if resume is not None:
        root = Path(resume).expanduser()
        if not (root / "sweep.yaml").is_file():
            raise InputError(root, "not a sweep folder (no sweep.yaml): give the folder 'slam2d ablate' printed")
        if config_mod.load_dict(root / "sweep.yaml") != config_mod.load_dict(path):
            raise InputError(f"--resume {root}", f"its sweep.yaml differs from {path}: resume with the sweep file it "
                             "was started with (or start a new sweep)")
        if (root / "runs").is_dir():
            remove_stale(root / "runs", ownerless=True)  # left by a process killed outright
        return root
    name = str(config_mod.load_dict(path).get("name") or Path(path).stem)
    config_mod.validate({"name": name}, f"{path}: name")  # a folder name
    parent = output_root(config_mod.validate(base, str(path), model).output.root)
    root = new_folder(parent, f"ablate-{name}-{datetime.now():%Y%m%d-%H%M%S}")
    shutil.copyfile(path, root / "sweep.yaml")
    return root


def _finished(runs: Path, name: str) -> tuple[str, dict[str, Any], None] | None:
    """(folder, metrics, None) of a finished run of variant ``name`` under ``runs``; None if there is none."""
    pattern = re.compile(re.escape(name) + r"-\d{8}-\d{6}(-\d+)?")
    for folder in sorted(runs.glob(f"{glob.escape(name)}-*")):
        if pattern.fullmatch(folder.name) and (folder / "metrics.json").is_file():
            return str(folder), json.loads((folder / "metrics.json").read_text()), None
    return None


def _write_sweep_table(root: Path, variants: list[Variant], outcomes: list, summary=None,
                       main_metrics: tuple[str, ...] = ()) -> list[dict[str, Any]]:
    """Write table.md/.csv/.tex, summary.md/.csv/.tex (with a summary spec) and report.html: one row
    per variant (unfinished ones say so); return the rows."""
    rows = []
    for v, outcome in zip(variants, outcomes):
        folder, metrics, error = outcome or ("", None, "not run (sweep stopped)")
        row: dict[str, Any] = {"variant": v.name, **v.overrides}
        if metrics is not None:
            row.update((k, v) for k, v in flatten_metrics(metrics).items() if k not in row)  # a key set wins
        row["error"] = error or ""
        row["folder"] = str(Path(folder).relative_to(root)) if folder else ""
        rows.append(row)
    leading = list(dict.fromkeys(["variant", *(k for v in variants for k in v.overrides), *main_metrics]))
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
    if shows_progress(quiet):
        bar = Progress(console=progress_console())
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
            done, _ = ray.wait(list(pending), num_returns=1, timeout=WAIT_S)
            signals.check_stop()  # a signal whose KeyboardInterrupt was swallowed
            for ref in done:
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
    reap_when_gone()  # a local instance's processes end with this one, however it ends
    try:
        context = ray.init(ignore_reinit_error=True, log_to_driver=False)
    except ConnectionError as err:
        raise InputError("RAY_ADDRESS", f"cannot reach the Ray cluster ({err})") from None
    reap_when_gone(context.address_info.get("session_dir") or "")  # also those that left the process tree
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

    buffer = io.BytesIO()
    with tarfile.open(fileobj=buffer, mode="w:gz") as tar:
        tar.add(folder, arcname=".")
    return buffer.getvalue()


def _collect(runs: Path, outcome, model=None) -> tuple[str, dict[str, Any] | None, str | None]:
    """A Ray task's outcome as (folder under ``runs``, metrics, error); a packed folder is unpacked there.
    ``model``: the variants' config model (default ExperimentConfig)."""

    folder, metrics, error, packed = outcome
    if not folder:
        return "", metrics, error
    if packed is None:
        return str(runs / Path(folder).name), metrics, error
    dest = new_folder(runs, Path(folder).name)
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
                               initializer=signals.init_sweep_worker, initargs=(os.getpid(),))
    try:
        futures = {pool.submit(_run_variant, c): i for i, c in enumerate(cfgs)}
        pending = set(futures)
        while pending:
            done, pending = wait(pending, timeout=WAIT_S, return_when=FIRST_COMPLETED)
            signals.check_stop()  # a signal whose KeyboardInterrupt was swallowed (in an at-fork callback)
            for fut in done:
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
