"""SlamPipeline: scans -> frontend -> back end -> poses for every scan.

With ``parallel`` (the default where processes can be forked) the reader and
the frontend run in a forked worker process that streams ``(scan, result)``
pairs to the back end in this process, so the two use two cores. The
worker's frontend is a copy: its ``events`` come back in ``SlamResult.stats``
and the reader's skip counts are copied back onto the source.
"""

from __future__ import annotations

import logging
import logging.handlers
import multiprocessing
import os
import pickle
import queue
import signal
import threading
import time
import traceback
from collections import Counter
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from slam2d import geometry
from slam2d.backend.base import BACKENDS
from slam2d.backend.session import Session
from slam2d.config import ExperimentConfig
from slam2d.errors import InputError
from slam2d.frontends import create_frontend
from slam2d.frontends.base import FrontendResult
from slam2d.processes import die_with_parent
from slam2d.types import Scan


@dataclass
class SlamResult:
    """Poses for every scan: ``stamps`` (N,), estimate/odometry/ground truth (N, 3)."""

    scans: list[Scan]
    stamps: np.ndarray
    poses: np.ndarray
    odometry: np.ndarray
    ground_truth: np.ndarray | None
    confidences: np.ndarray
    cpu_s: float  # CPU time (s) of the run: reading, frontend, back end, in every process
    skipped: Counter = field(default_factory=Counter)
    stats: dict[str, Any] = field(default_factory=dict)
    graph: Any = None  # the back end's pose graph (the PoseGraph of 'pose_graph'), if it has one
    keyframes: np.ndarray | None = None  # (N,) keyframe key each scan hangs off, if the back end has keyframes
    session: Session | None = None  # what a later run goes on from (back ends with sessions)

    @property
    def fallbacks(self) -> int:
        """Scans after the first answered with confidence 0 (the frontend returned odometry)."""
        return int(np.count_nonzero(self.confidences[1:] <= 0.0))


def frontend_steps(frontend, scans: Iterable[Scan], previous: Scan | None = None) -> Iterator[tuple[Scan, FrontendResult]]:
    """Each scan with ``frontend``'s result on it; the odometry delta is taken from the previous scan.
    ``previous``: the scan before the first (a saved session's last), which the frontend takes first."""
    if previous is not None:
        frontend.process(previous, np.zeros(3))
    for scan in scans:
        odom_delta = np.zeros(3) if previous is None else geometry.between(previous.odom, scan.odom)
        yield scan, frontend.process(scan, odom_delta)
        previous = scan


WORKER_BATCH = 32  # (scan, result) pairs per message from the worker
SOURCE_COUNTS = ("skipped", "invalid_beams")  # reader attributes copied back from the worker


def can_fork() -> bool:
    """Whether a frontend worker process can be forked here (POSIX, not inside a daemonic process)."""
    return "fork" in multiprocessing.get_all_start_methods() and not multiprocessing.current_process().daemon


class FrontendWorker:
    """``frontend_steps(frontend, scans)`` computed in a forked process; iterate once for the pairs.

    After the iteration ``events`` holds the worker frontend's events and
    ``cpu_s`` the worker's CPU time (s). An exception in the worker is raised
    here; leaving the ``with`` block early stops the worker.
    """

    def __init__(self, frontend, scans: Iterable[Scan], previous: Scan | None = None):
        self.scans = scans
        self.events: Counter[str] = Counter()
        self.cpu_s = 0.0
        ctx = multiprocessing.get_context("fork")
        self._queue = ctx.Queue()  # unbounded: the worker never waits for the back end
        # the parent-death signal comes when the forking thread ends: only the main thread lives as long as the process
        parent = os.getpid() if threading.current_thread() is threading.main_thread() else None
        self._process = ctx.Process(target=_work, args=(frontend, scans, previous, self._queue, parent), daemon=True,
                                    name="slam2d-frontend")
        self._process.start()

    def __enter__(self) -> FrontendWorker:
        return self

    def __exit__(self, *exc) -> None:
        if self._process.is_alive():
            self._process.terminate()
        self._process.join()
        self._queue.close()

    def __iter__(self) -> Iterator[tuple[Scan, FrontendResult]]:
        while True:
            kind, payload = self._next_message()
            if kind == "pairs":
                yield from payload
            elif kind == "log":
                logging.getLogger(payload.name).handle(payload)
            elif kind == "error":
                raise payload
            else:
                self.events, self.cpu_s = payload["events"], payload["cpu_s"]
                for name, value in payload["source"].items():
                    setattr(self.scans, name, value)
                return

    def _next_message(self):
        """The worker's next message; RuntimeError if it died without a word."""
        while True:
            try:
                return self._queue.get(timeout=1.0)
            except queue.Empty:
                if not self._process.is_alive():
                    raise RuntimeError(f"frontend worker died (exit code {self._process.exitcode})") from None


class _QueueSink:
    """The ``put_nowait`` of a queue for logging's QueueHandler: records go up as ("log", record)."""

    def __init__(self, out):
        self.out = out

    def put_nowait(self, record: logging.LogRecord) -> None:
        self.out.put(("log", record))


def _log_through(out) -> None:
    """In the worker: every record propagates to one handler at the root that sends it to the parent,
    where its logger handles it with the parent's handlers; the inherited handlers are removed."""
    for logger in [lg for lg in logging.root.manager.loggerDict.values() if isinstance(lg, logging.Logger)]:
        logger.handlers.clear()
        logger.propagate = True
    logging.root.handlers.clear()
    logging.root.addHandler(logging.handlers.QueueHandler(_QueueSink(out)))


def _work(frontend, scans, previous, out, parent: int | None) -> None:
    """Worker body: send batches of pairs, then the frontend's events and the reader's counts. It dies
    with ``parent`` and leaves SIGINT to it (the parent stops it)."""
    if parent is not None:
        die_with_parent(parent)
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        _log_through(out)
        batch = []
        for pair in frontend_steps(frontend, scans, previous):
            batch.append(pair)
            if len(batch) == WORKER_BATCH:
                out.put(("pairs", batch))
                batch = []
        out.put(("pairs", batch))
        out.put(("done", {
            "events": Counter(getattr(frontend, "events", {})),
            "cpu_s": time.process_time(),
            "source": {name: getattr(scans, name) for name in SOURCE_COUNTS if hasattr(scans, name)},
        }))
    except BaseException as err:  # noqa: BLE001 - every failure is reported to the parent
        try:
            pickle.dumps(err)
        except Exception:  # noqa: BLE001
            err = RuntimeError(f"frontend worker failed:\n{traceback.format_exc()}")
        out.put(("error", err))


class SlamPipeline:
    """Runs the configured frontend and back end over a scan stream.

    Each ``run`` builds a fresh back end, after the frontend worker has
    started (its set-up, gtsam's import included, overlaps the worker's start).
    """

    def __init__(self, cfg: ExperimentConfig):
        from slam2d.plugins import load_plugins

        self.cfg = cfg
        load_plugins(cfg.plugins)
        self.frontend = create_frontend(cfg.frontend.name, cfg.frontend.options)

    def _new_backend(self):
        """The back end ``backend.name`` names, built from the ``backend`` section."""
        return BACKENDS.create(self.cfg.backend.name, None, self.cfg.backend)

    def run(self, scans: Iterable[Scan], on_scan: Callable[[], None] | None = None, view=None,
            session: Session | None = None, localize: bool = False) -> SlamResult:
        """Process every scan; ``on_scan`` is called after each one (progress); ``view``
        (a :class:`slam2d.viz.LiveView`) logs each scan, the pose, loops and map as they come.

        ``session``: a saved session the scans go on from (its last scan precedes the first);
        with ``localize``, a session the scans start somewhere in, unknown where. The result
        holds both sessions' scans, the saved ones first."""
        t0 = time.process_time()
        previous = None if session is None or localize else session.scans()[-1]
        if self.cfg.parallel and can_fork():
            with FrontendWorker(self.frontend, scans, previous) as worker:
                result = self._consume(worker, scans, on_scan, view, session, localize)
            events, worker_cpu_s = worker.events, worker.cpu_s
        else:
            steps = frontend_steps(self.frontend, scans, previous)
            result = self._consume(steps, scans, on_scan, view, session, localize)
            events, worker_cpu_s = getattr(self.frontend, "events", {}), 0.0
        result.stats.update({f"frontend {k}": v for k, v in events.items()})
        result.cpu_s = time.process_time() - t0 + worker_cpu_s
        return result

    def _consume(self, steps, scans, on_scan, view=None, session=None, localize=False) -> SlamResult:
        """Feed the (scan, result) pairs to a new back end (resumed from ``session``); the result
        without the frontend's events."""
        backend = self._new_backend()
        kept: list[Scan] = []
        confidences = []
        if session is not None:
            if not hasattr(backend, "resume"):
                raise InputError("backend.name", f"'{self.cfg.backend.name}' cannot go on from a saved session")
            backend.resume(session, localize)
            kept = session.scans()
            confidences = [np.nan] * len(kept)
        n_saved = len(kept)
        for scan, result in steps:
            backend.add(scan, result)
            confidences.append(result.confidence)
            kept.append(scan)
            if view is not None:
                view.step(scan, backend)
            if on_scan:
                on_scan()
        if len(kept) == n_saved:
            skipped = dict(getattr(scans, "skipped", {}))
            raise InputError(getattr(scans, "name", "dataset"), f"no usable scan (skipped: {skipped})")
        poses = backend.finish()
        if view is not None:
            view.finish(poses, backend)
        gts = [s.ground_truth for s in kept]
        return SlamResult(
            scans=kept,
            stamps=np.array([s.stamp for s in kept]),
            poses=poses,
            odometry=np.array([s.odom for s in kept]),
            ground_truth=None if any(g is None for g in gts) else np.array(gts),
            confidences=np.array(confidences),
            cpu_s=0.0,
            skipped=Counter(getattr(scans, "skipped", {})),
            stats=dict(backend.summary()),
            graph=backend.graph,
            keyframes=backend.scan_anchors()[0] if hasattr(backend, "scan_anchors") else None,
            session=backend.session(kept) if hasattr(backend, "session") else None,
        )
