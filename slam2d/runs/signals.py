"""SIGINT and SIGTERM: a command stops cleanly (half-written folders removed), a sweep worker finishes
no further variant."""

from __future__ import annotations

import os
import signal
import sys
import threading
import time
from contextlib import contextmanager

from slam2d.processes import die_with_parent, parent_gone

_STOPPED = False  # whether SIGINT or SIGTERM has arrived in this process (in a sweep worker: no new variant)


_RUNNING_VARIANT = False  # in a sweep worker: whether a variant is running
_SIGNAL = 0  # the first SIGINT or SIGTERM that arrived (0: none)


def _handler(stop):
    """A signal handler calling ``stop()`` in this process; a forked child that inherits it dies as by default."""
    pid = os.getpid()

    def handler(signum, frame):
        if os.getpid() != pid:
            signal.signal(signum, signal.SIG_DFL)
            os.kill(os.getpid(), signum)
            return
        global _SIGNAL
        _SIGNAL = _SIGNAL or signum
        stop()

    return handler


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
    previous_hook = sys.unraisablehook
    sys.unraisablehook = _quiet_interrupt(previous_hook)
    try:
        yield
    finally:
        sys.unraisablehook = previous_hook
        for sig, old in previous.items():
            signal.signal(sig, old)


def _quiet_interrupt(hook):
    """An unraisable-exception hook that drops the KeyboardInterrupt a signal raised where Python cannot
    propagate it (a ``__del__``, an at-fork callback): :func:`check_stop` raises it again later."""

    def quiet(unraisable):
        if not (_STOPPED and isinstance(unraisable.exc_value, KeyboardInterrupt)):
            hook(unraisable)

    return quiet


def stopped() -> bool:
    """Whether SIGINT or SIGTERM has arrived since :func:`stop_on_signals`."""
    return _STOPPED


def exit_code() -> int:
    """The exit status of a command the first signal stopped, as shells give it: 130 (SIGINT), 143 (SIGTERM)."""
    return 128 + (_SIGNAL or signal.SIGINT)


def check_stop() -> None:
    """KeyboardInterrupt if a signal has arrived: its own exception may have been swallowed (in a ``__del__``)."""
    if _STOPPED:
        raise KeyboardInterrupt


_PARENTS: tuple[int, int] | None = None  # in a sweep worker: (its parent, the sweep's process)


def init_sweep_worker(owner: int | None = None) -> None:
    """A sweep worker ignores SIGINT (the sweep's process stops it) and dies with its parent. The first
    SIGTERM stops it: its running variant is interrupted (its folder removed) and queued ones are not
    started; later signals are ignored so that the clean-up finishes. ``owner``: the sweep's process,
    whose end also stops the worker (see :func:`orphaned`)."""
    global _PARENTS

    def stop():
        global _STOPPED
        signal.signal(signal.SIGTERM, signal.SIG_IGN)
        _STOPPED = True
        if _RUNNING_VARIANT:
            raise KeyboardInterrupt

    _PARENTS = (os.getppid(), owner)
    die_with_parent(_PARENTS[0], signal.SIGTERM)
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, _handler(stop))
    threading.Thread(target=_watch_owner, name="slam2d-owner-watch", daemon=True).start()


WATCH_S = 0.2  # how often a sweep worker checks that the sweep's process runs
GRACE_S = 30.0  # how long an orphaned worker's running variant may take to remove its folder


def _watch_owner() -> None:
    """In a sweep worker (a thread): once the sweep's process is gone, stop the running variant as SIGTERM
    does, or exit at once when none runs; exit anyway after GRACE_S. (The forkserver the worker was made
    by lives as long as its workers do, so the parent-death signal alone would not come.)"""
    while not orphaned():
        time.sleep(WATCH_S)
    if _RUNNING_VARIANT:
        os.kill(os.getpid(), signal.SIGTERM)
        time.sleep(GRACE_S)
    os._exit(143)


def orphaned() -> bool:
    """In a sweep worker: whether the sweep's process is gone (no further variant is started)."""
    return _PARENTS is not None and parent_gone(*_PARENTS)


@contextmanager
def variant_running():
    """In the block a sweep worker's signal interrupts the running variant (see :func:`init_sweep_worker`)."""
    global _RUNNING_VARIANT
    _RUNNING_VARIANT = True
    try:
        yield
    finally:
        _RUNNING_VARIANT = False
