"""The garbage collector kept out of the decisions' time (``exploration/collection.py``)."""

from __future__ import annotations

import gc
import sys

import numpy as np
from test_exploration_paths import random_map, random_start

from slam2d.exploration.config import ExplorationConfig
from slam2d.exploration.explorer import Explorer
from slam2d.exploration.gridops import GridView


def test_no_garbage_collection_runs_inside_a_decision():
    """With the collector's thresholds at their lowest (a collection at every allocation of a container), collections
    run between the decisions but none inside one (no frame of ``Explorer.decide`` on the stack), and the decisions are
    those of an explorer deciding with the collector off."""
    rng = np.random.default_rng(2400)
    cfg = ExplorationConfig(strategy="utility")
    explorer, quiet = Explorer(cfg, 0.2, 0.05, 12.0), Explorer(cfg, 0.2, 0.05, 12.0)
    state = random_map(rng, (120, 150))
    poses = [random_start(rng, GridView(state.copy(), 0.05, (0.0, 0.0))) for _ in range(3)]
    inside = []

    def watch(phase, info):
        if phase == "start":
            frame = sys._getframe(1)
            while frame is not None and frame.f_code is not Explorer.decide.__code__:
                frame = frame.f_back
            inside.append(frame is not None)

    thresholds = gc.get_threshold()
    gc.set_threshold(1, 10**6, 10**6)  # a young collection at every allocation of a container
    gc.callbacks.append(watch)
    try:
        goals = [explorer.decide(pose, GridView(state.copy(), 0.05, (0.0, 0.0))) for pose in poses]
    finally:
        gc.callbacks.remove(watch)
        gc.set_threshold(*thresholds)
    assert len(inside) > 0 and not any(inside)
    gc.disable()
    try:
        again = [quiet.decide(pose, GridView(state.copy(), 0.05, (0.0, 0.0))) for pose in poses]
    finally:
        gc.enable()
    assert gc.isenabled()
    for a, b in zip(goals, again):
        assert (a is None) == (b is None)
        assert a is None or (np.array_equal(a.position, b.position) and a.score == b.score)


def test_a_run_keeps_its_start_up_objects_frozen_and_frees_them_at_its_end(tmp_path):
    """During an exploration run the objects alive at its start are frozen (no collection walks them); after it
    none is."""
    from test_exploration import two_rooms_png

    from slam2d.exploration import config
    from slam2d.exploration.loop import explore

    cfg = config.load(None, {"dataset.simulator.world": str(two_rooms_png(tmp_path)), "seed": 1,
                             "exploration.start": [1.5, 2.0, 0.0], "exploration.max_time": 3,
                             "exploration.animation": False})  # fmt: skip
    frozen = []
    explore(cfg, progress=lambda now, coverage: frozen.append(gc.get_freeze_count()))
    assert frozen and min(frozen) > 10_000
    assert gc.get_freeze_count() == 0
