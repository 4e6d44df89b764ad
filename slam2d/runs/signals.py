"""SIGINT and SIGTERM: a command stops cleanly (half-written folders removed), a sweep worker finishes
no further variant."""

from __future__ import annotations

import os
import signal
from contextlib import contextmanager

_STOPPED = False  # whether SIGINT or SIGTERM has arrived in this process (in a sweep worker: no new variant)
_SIGNAL: int | None = None  # the first of them to arrive


_RUNNING_VARIANT = False  # in a sweep worker: whether a variant is running


def _handler(stop):
    """A signal handler calling ``stop()`` in this process; a forked child that inherits it dies as by default."""
    pid = os.getpid()

    def handler(signum, frame):
        global _SIGNAL
        if os.getpid() != pid:
            signal.signal(signum, signal.SIG_DFL)
            os.kill(os.getpid(), signum)
            return
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
    try:
        yield
    finally:
        for sig, old in previous.items():
            signal.signal(sig, old)


def stopped() -> bool:
    """Whether SIGINT or SIGTERM has arrived since :func:`stop_on_signals`."""
    return _STOPPED


def exit_code() -> int:
    """The shell's exit status for the signal that stopped the process: 128 + its number (SIGINT 130,
    SIGTERM 143; 130 when none is known)."""
    return 128 + int(_SIGNAL or signal.SIGINT)


def check_stop() -> None:
    """KeyboardInterrupt if a signal has arrived: its own exception may have been swallowed (in a ``__del__``)."""
    if _STOPPED:
        raise KeyboardInterrupt


def init_sweep_worker() -> None:
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


@contextmanager
def variant_running():
    """In the block a sweep worker's signal interrupts the running variant (see :func:`init_sweep_worker`)."""
    global _RUNNING_VARIANT
    _RUNNING_VARIANT = True
    try:
        yield
    finally:
        _RUNNING_VARIANT = False
