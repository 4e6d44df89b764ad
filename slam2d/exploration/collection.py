"""Python's garbage collector kept out of the decisions' time.

A full collection walks every tracked container of the process (~320 000 after start-up, mostly the imported
libraries' objects: 110–200 ms) and falls wherever an allocation tips its counters, a decision included. Two
measures: the objects alive once a run has started (imports, warm-up, the loop's own) are frozen for the run
(``gc.freeze``: left out of every collection, so a full one walks only what the run made since), and no collection
runs inside a decision (the collector paused, the collection it owes made by the next allocation after it, in the
drive loop).
"""

from __future__ import annotations

import gc
from contextlib import contextmanager

__all__ = ["paused", "resume", "start_up_frozen"]


def paused() -> bool:
    """Pause the collector (no garbage collection until :func:`resume`); whether it was on. Allocates nothing, nor
    does :func:`resume`: the collection owed falls on the first allocation after the caller returns, not in it."""
    on = gc.isenabled()
    gc.disable()
    return on


def resume(on: bool) -> None:
    """The collector back as :func:`paused` found it (``on``)."""
    if on:
        gc.enable()


@contextmanager
def start_up_frozen():
    """The objects alive on entry (garbage collected first) frozen for the block: no collection walks them. Unfrozen
    on exit, so that those that died meanwhile are collected as usual."""
    gc.collect()
    gc.freeze()
    try:
        yield
    finally:
        gc.unfreeze()
