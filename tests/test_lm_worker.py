"""GTSAM's LM in a forked worker process: the same values, bit for bit, as in this process; errors come back;
a signal ends the wait at once and leaves no worker behind."""

from __future__ import annotations

import os
import signal
import threading
import time

import gtsam
import numpy as np
import psutil
import pytest
from test_pose_graph_global import manhattan

from slam2d import processes
from slam2d.backend import admission, batch, consistency, lm, outliers
from slam2d.backend import initialization as ini
from slam2d.backend.factors import g2o_factor_list, g2o_factors, g2o_values
from slam2d.backend.initialization import spanning_tree
from slam2d.backend.replay import replay_g2o
from slam2d.config import BackendConfig
from slam2d.datasets.g2o import inject_outliers
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

    previous = signal.signal(signal.SIGINT, signal.default_int_handler)  # a background job starts with it ignored
    try:
        threading.Thread(target=interrupt).start()
        t0 = time.monotonic()
        with pytest.raises(KeyboardInterrupt):
            call_forked(time.sleep, 30)
    finally:
        signal.signal(signal.SIGINT, previous)
    assert time.monotonic() - t0 < 5
    assert _children() == before  # killed and reaped


def _pid_and_scipy() -> tuple[int, bool]:
    import sys

    return os.getpid(), "scipy.sparse.linalg" in sys.modules


def test_a_worker_prepares_while_this_process_goes_on_then_computes_each_call():
    """``Worker``: its ``prepare`` (scipy's import for ``lm.sparse_worker``) runs in the child, calls run there one
    after another, an error comes back as here, and closing it kills and reaps the child."""
    before = _children()
    with lm.sparse_worker() as worker:
        assert worker.pid in _children()
        pid, has_scipy = worker.call(_pid_and_scipy)
        assert pid == worker.pid != os.getpid() and has_scipy
        with pytest.raises(ValueError, match="bad graph"):
            worker.call(_fails)
        assert worker.call(sum, [1, 2, 3]) == 6 and worker.call(_pid_and_scipy)[0] == pid  # the same child
        pending = worker.submit(sum, [4, 5])  # this process goes on until it asks for the result
        assert pending() == 9
    assert _children() == before and worker.call(sum, [1, 2]) == 3  # closed: a call runs here


@pytest.mark.skipif(not hasattr(signal, "pthread_kill"), reason="needs pthread_kill")
def test_an_interrupt_while_waiting_for_a_worker_kills_it_at_once():
    before = _children()

    def interrupt():
        time.sleep(0.5)
        signal.pthread_kill(threading.main_thread().ident, signal.SIGINT)

    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        threading.Thread(target=interrupt).start()
        t0 = time.monotonic()
        with pytest.raises(KeyboardInterrupt), processes.Worker() as worker:
            worker.call(time.sleep, 30)
    finally:
        signal.signal(signal.SIGINT, previous)
    assert time.monotonic() - t0 < 5
    assert _children() == before


def test_meanwhile_runs_while_the_certificate_is_computed_with_the_result_returned():
    """``solve_g2o``'s ``meanwhile`` (the results folder's files) runs once, while the worker process computes the
    certificate, with the poses, inliers and start of the result returned (not yet certified)."""
    graph = manhattan(300, seed=3)
    seen = []
    out = batch.solve_g2o(graph, verify=True, meanwhile=lambda result: seen.append((result, _children())))
    ((shown, workers),) = seen
    assert workers and shown.certified is None and shown.verified is None and out.certified and out.verified
    assert np.array_equal(shown.poses, out.poses) and np.array_equal(shown.inlier, out.inlier)
    assert shown.init == out.init and shown.final_error == out.final_error


def _in_this_process(fn, *args):
    return fn(*args)


@pytest.mark.parametrize("gnc", [False, True], ids=["LM", "GNC"])
def test_the_slam_back_ends_batch_runs_in_a_worker_with_the_same_values(monkeypatch, gnc):
    """``PoseGraph.optimize_batch`` (``slam2d run``'s final batch) solves in a worker process, and its values
    come back bit for bit as a solve in this process gives them (the pickled gtsam.Values included)."""
    graph, _ = inject_outliers(manhattan(300, seed=3), 10, "random", seed=1)
    cfg = BackendConfig(name="pose_graph", gnc=gnc)
    forks = []
    real = lm.call_forked
    monkeypatch.setattr(lm, "call_forked", lambda fn, *args: forks.append(fn) or real(fn, *args))
    there = replay_g2o(graph, cfg)
    there_poses = there.optimize_batch()
    assert forks, "no worker process"
    monkeypatch.setattr(lm, "call_forked", _in_this_process)
    here = replay_g2o(graph, cfg)
    assert np.array_equal(here.optimize_batch(), there_poses)
    assert here.rejected_inconsistent == there.rejected_inconsistent > 0  # the false loops' removal as well


def _not_in(parent: int, fn):
    def wrapped(*args, **kwargs):
        assert os.getpid() != parent, f"{fn.__name__} ran in the command's process"
        return fn(*args, **kwargs)

    return wrapped


def test_every_step_of_pc_dcs_runs_in_a_worker(monkeypatch):
    """pc_dcs's pairwise screen, its starts and the admission's factorisations run in a worker process, as the
    solves do, so that a signal in any phase ends the command at once; the result is unchanged."""
    graph, injected = inject_outliers(manhattan(300, seed=3), 100, "random", seed=1)
    here = outliers.pc_dcs(graph, g2o_factor_list(graph), init="spanning_tree,chordal_screened")
    parent = os.getpid()
    monkeypatch.setattr(consistency, "pairwise_support", _not_in(parent, consistency.pairwise_support))
    monkeypatch.setattr(ini, "chordal", _not_in(parent, ini.chordal))
    monkeypatch.setattr(ini, "spanning_tree", _not_in(parent, ini.spanning_tree))
    monkeypatch.setattr(admission, "admit_linearised", _not_in(parent, admission.admit_linearised))
    there = outliers.pc_dcs(graph, g2o_factor_list(graph), init="spanning_tree,chordal_screened")
    assert np.array_equal(there.poses, here.poses) and np.array_equal(there.inlier, here.inlier)
    assert not there.inlier[injected].any()
