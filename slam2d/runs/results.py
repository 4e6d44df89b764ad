"""The results folder: the one place that creates, names, fills and publishes run folders.

A results folder is built under a hidden temporary name and renamed into place
only when everything in it is written, so a failed run leaves no half-written
folder, and an existing folder is never overwritten. JSON is strict here: NaN
and infinities are written as null.
"""

from __future__ import annotations

import errno
import itertools
import json
import logging
import re
import resource
import shutil
import sys
import tempfile
from contextlib import contextmanager
from datetime import datetime
from pathlib import Path

import numpy as np

from slam2d.config import MAX_NAME_BYTES
from slam2d.errors import InputError
from slam2d.processes import claim, release, stale
from slam2d.runs.report import write_run_report
from slam2d.runs.signals import check_stop

log = logging.getLogger("slam2d")


@contextmanager
def results_folder(root: str | Path, name: str, key: str = "output.root"):
    """Yield ``(work, published)``: a hidden temporary folder to fill (its log in
    ``run.log``) and a list that receives the final path once the block succeeds.
    On failure the temporary folder is removed, so no half-written folder remains.
    ``key`` names ``root`` in errors (the config key or the CLI option)."""
    root, name = output_root(root, key), fit_name(name)
    remove_stale(root)
    try:
        work = Path(tempfile.mkdtemp(prefix=f".{name}-", dir=root))
    except OSError as err:
        raise InputError(key, f"cannot write in {root} ({err.strerror})") from None
    published: list[Path] = []
    try:
        claim(work)
        with log_to(work / "run.log"):
            yield work, published
        check_stop()  # a signal whose exception was swallowed still leaves no folder
        write_run_report(work, name)
        release(work)
        published.append(_publish(work, root, name))
    except BaseException as err:
        shutil.rmtree(work, ignore_errors=True)
        if isinstance(err, OSError) and err.errno in WRITE_ERRORS:
            raise write_error(err, work) from None
        raise


WRITE_ERRORS = {errno.ENOSPC, errno.EDQUOT, errno.EROFS, errno.EFBIG, errno.EACCES, errno.EPERM, errno.ENAMETOOLONG}
"""OSErrors that filling a results folder turns into an InputError naming the path: the disk is full,
read-only or refuses (a name too long, no permission)."""


def write_error(err: OSError, where) -> InputError:
    """The InputError of a write that failed with ``err`` (one of WRITE_ERRORS): its file (else ``where``)
    and the reason."""
    return InputError(err.filename or where, f"cannot write ({err.strerror or err})")


@contextmanager
def writes(where):
    """In the block an OSError of WRITE_ERRORS becomes an InputError (:func:`write_error`)."""
    try:
        yield
    except OSError as err:
        if err.errno in WRITE_ERRORS:
            raise write_error(err, where) from None
        raise


def fit_name(name: str) -> str:
    """``name`` cut to MAX_NAME_BYTES bytes of UTF-8 (at a character boundary), so that the folder's name
    with its date stays within a file system's 255 bytes (a default name holds a map file's name)."""
    data = name.encode("utf-8", "surrogatepass")
    return name if len(data) <= MAX_NAME_BYTES else data[:MAX_NAME_BYTES].decode("utf-8", "ignore")


def remove_stale(root: Path, ownerless: bool = False) -> int:
    """Remove the hidden work folders under ``root`` whose process was killed outright (see
    :func:`slam2d.processes.stale`; ``ownerless``: those without an owner record too); log and return their count."""
    removed = 0
    for folder in root.glob(".?*-*"):
        if folder.is_dir() and stale(folder, ownerless):
            shutil.rmtree(folder, ignore_errors=True)
            removed += not folder.exists()
    if removed:
        log.info("%s: removed %d hidden folder%s left by killed runs", root, removed, "s" * (removed != 1))
    return removed


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


def new_folder(parent: Path, stem: str) -> Path:
    """Create and return ``parent/stem``, or ``stem-2``, ``stem-3``... if taken (atomic: mkdir)."""
    for k in itertools.count(1):
        folder = parent / (stem if k == 1 else f"{stem}-{k}")
        try:
            folder.mkdir()
            return folder
        except FileExistsError:
            continue
    raise AssertionError("unreachable")


def snake_keys(counts) -> dict:
    """``counts`` (a mapping of free-text reasons, e.g. ``"loop closures kept"``) with keys in snake_case
    (``loop_closures_kept``): every run of characters other than letters, digits and ``_`` becomes one ``_``."""
    return {re.sub(r"[^0-9A-Za-z_]+", "_", str(k)).strip("_"): v for k, v in dict(counts).items()}


def json_text(obj) -> str:
    """``obj`` as indented JSON: numpy values as numbers, NaN and infinities as null (JSON has neither)."""
    return json.dumps(jsonable(obj), indent=2, allow_nan=False)


def jsonable(obj):
    if isinstance(obj, dict):
        return {str(k): jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return jsonable(obj.tolist())
    if isinstance(obj, np.generic):
        obj = obj.item()
    if isinstance(obj, float) and not np.isfinite(obj):
        return None  # JSON has no NaN or infinity
    return obj


@contextmanager
def log_to(path: Path):
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
def live_view(viz: str | Path | None, name: str, kind: str, *args):
    """Yield None when ``viz`` is None (nothing of rerun is imported), else the view of
    :func:`slam2d.viz.open_view` for a ``kind`` of run (run, localize, explore) made with ``args``,
    streaming to ``viz`` (``"viewer"`` or ``FILE.rrd``) and closed after the block."""
    if viz is None:
        yield None
        return
    from slam2d.viz import open_view  # rerun: an optional extra

    view = open_view(viz, name, kind, *args)
    try:
        yield view
    finally:
        view.close()


def progress_console():
    """rich's Console where progress bars are drawn: stderr (stdout carries the results only). rich is
    imported here, not by commands that draw no bar."""
    from rich.console import Console

    return Console(stderr=True)


def shows_progress(quiet: bool) -> bool:
    """Progress bars are drawn on a terminal only (stderr), and never when ``quiet``."""
    return not quiet and sys.stderr.isatty()


@contextmanager
def progress(source, quiet: bool):
    """Yield a callable that advances a progress bar by one scan (None: no bar, see :func:`shows_progress`)."""
    if not shows_progress(quiet):
        yield None
        return
    try:
        total = source.expected() if hasattr(source, "expected") else len(source)
    except (TypeError, NotImplementedError):
        total = None
    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        Progress,
        TimeRemainingColumn,
    )

    with Progress(
        "[progress.description]{task.description}", BarColumn(), MofNCompleteColumn(), TimeRemainingColumn(),
        console=progress_console(),
    ) as bar:
        task = bar.add_task(getattr(source, "name", "scans"), total=total)
        yield lambda: bar.advance(task)


@contextmanager
def progress_bar(description: str, total: float | None, quiet: bool):
    """Yield ``update(done, note="")``: the bar at ``done`` of ``total`` (None: unknown), ``note`` beside its
    description; a no-op when ``quiet`` or stderr is not a terminal."""
    if not shows_progress(quiet):
        yield lambda done, note="": None
        return
    from rich.progress import BarColumn, Progress, TimeRemainingColumn

    with Progress("[progress.description]{task.description}", BarColumn(), TimeRemainingColumn(),
                  console=progress_console()) as bar:
        task = bar.add_task(description, total=total)
        yield lambda done, note="": bar.update(task, completed=done, description=f"{description} {note}".strip())


def peak_rss_mb() -> float:
    """Peak resident memory (MB) of this process plus its largest finished child (the frontend worker)."""
    kb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss + resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    return kb / 1024.0
