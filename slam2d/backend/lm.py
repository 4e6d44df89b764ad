"""Levenberg-Marquardt (and any other long step of a solve) in a worker process, so that a signal stops it at once.

GTSAM's solve runs in C++, where Python's signal handlers do not run: a SIGTERM would wait for
the solve to end (M3500 with 1000 false loops: one iteration takes 1-4 s). ``levenberg_marquardt``
runs it in a forked child (``processes.call_forked``) that the command kills as soon as SIGINT or
SIGTERM arrives, and returns a summary of the result computed there. The child iterates with
GTSAM's own stopping rule (``checkConvergence`` on the relative and absolute error decrease, the
iteration limit): the same values, bit for bit, as GTSAM's ``optimize()`` and as a solve in this
process. ``in_worker`` runs any other step there (starts, the pairwise screen, the admission's
factorisations, the certificate): a sparse factorisation over false loops' fill-in, or numpy over a
million loop pairs, holds the interpreter for seconds too.
"""

from __future__ import annotations

import math

from slam2d.backend.factors import lm_params
from slam2d.processes import Worker, call_forked


def levenberg_marquardt(fg, initial, summary, params=None):
    """``summary(values, iterations)`` (picklable) of LM over the gtsam graph ``fg`` from gtsam.Values
    ``initial`` (``params``: GTSAM's LevenbergMarquardtParams, default ``factors.lm_params()``), computed
    in a worker process."""
    return call_forked(_solve, fg, initial, summary, params)


def in_worker(fn, *args):
    """``fn(*args)`` (picklable result) in a worker process that SIGINT / SIGTERM kills at once
    (``processes.call_forked``). scipy's sparse solvers are imported here first, so that no worker imports
    them anew."""
    import scipy.sparse.linalg  # noqa: F401

    return call_forked(fn, *args)


def sparse_worker() -> Worker:
    """A worker process (``processes.Worker``) that imports scipy's sparse solvers while this process goes on
    (gtsam's import, the factors; 0.2-0.3 s each): a clean graph's starts and certificate run there
    (``worker.call`` in place of ``in_worker``), and this process does not import scipy."""
    return Worker(_import_sparse)


def _import_sparse() -> None:
    import scipy.sparse.linalg  # noqa: F401


def _solve(fg, initial, summary, params):
    """LM in this process, iteration by iteration with GTSAM's stopping rule; ``summary(values, iterations)``."""
    import gtsam

    params = params or lm_params()
    opt = gtsam.LevenbergMarquardtOptimizer(fg, initial, params)
    limit = params.getMaxIterations()
    current = opt.error()
    if limit == 0 or current <= params.getErrorTol():
        return summary(opt.values(), 0)
    while True:
        opt.iterate()
        new = opt.error()
        if (opt.iterations() >= limit or not math.isfinite(new)
                or gtsam.checkConvergence(params.getRelativeErrorTol(), params.getAbsoluteErrorTol(),
                                          params.getErrorTol(), current, new)):
            return summary(opt.values(), opt.iterations())
        current = new
