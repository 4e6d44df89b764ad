"""GTSAM's LM in a forked worker process: the same values, bit for bit, as in this process; errors come back;
a signal ends the wait at once and leaves no worker behind."""

from __future__ import annotations

import signal
import threading
import time

import gtsam
import numpy as np
import psutil
import pytest
from test_pose_graph_global import manhattan

from slam2d.backend import batch, lm
from slam2d.backend.factors import g2o_factors, g2o_values
from slam2d.backend.initialization import spanning_tree
from slam2d.processes import call_forked


def _summary(values, iterations):
    return gtsam.utilities.extractPose2(values), iterations


def test_the_worker_returns_the_values_of_a_solve_here_bit_for_bit():
    graph = manhattan(300, seed=3)
    fg = g2o_factors(graph)
    start = g2o_values(graph.ids, spanning_tree(graph))
    fg.add(batch._anchor_prior(graph, start))
    here = lm._solve(fg, start, _summary, None)
    there = lm.levenberg_marquardt(fg, start, _summary)
    assert there[1] == here[1] > 0
    assert np.array_equal(there[0], here[0])
    optimized = gtsam.LevenbergMarquardtOptimizer(fg, start, lm.lm_params()).optimize()  # GTSAM's own loop
    assert np.array_equal(gtsam.utilities.extractPose2(optimized), here[0])


def _fails():
    raise ValueError("bad graph")


def test_an_error_in_the_worker_is_raised_here():
    with pytest.raises(ValueError, match="bad graph"):
        call_forked(_fails)
    assert call_forked(sum, [1, 2, 3]) == 6


def _children() -> set[int]:
    return {child.pid for child in psutil.Process().children()}


@pytest.mark.skipif(not hasattr(signal, "pthread_kill"), reason="needs pthread_kill")
def test_an_interrupt_while_waiting_kills_the_worker_at_once():
    before = _children()

    def interrupt():
        time.sleep(0.5)
        signal.pthread_kill(threading.main_thread().ident, signal.SIGINT)  # KeyboardInterrupt in the wait

    threading.Thread(target=interrupt).start()
    t0 = time.monotonic()
    with pytest.raises(KeyboardInterrupt):
        call_forked(time.sleep, 30)
    assert time.monotonic() - t0 < 5
    assert _children() == before  # killed and reaped
