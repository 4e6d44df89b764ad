"""Levenberg-Marquardt one iteration at a time, so that a signal stops a long solve promptly.

GTSAM's ``optimize()`` runs its whole loop in C++, where Python's signal handlers do not run:
a SIGTERM waits for the solve to end. ``levenberg_marquardt`` calls ``iterate()`` from Python
with GTSAM's own stopping rule (``checkConvergence`` on the relative and absolute error
decrease, the iteration limit), so it reaches the same values and a KeyboardInterrupt raised by
a signal handler surfaces between two iterations (one linear solve: well under a second on the
benchmark graphs).
"""

from __future__ import annotations

import math

from slam2d.backend.factors import lm_params


def levenberg_marquardt(fg, initial, params=None):
    """Optimise the gtsam graph ``fg`` from gtsam.Values ``initial`` (``params``: GTSAM's
    LevenbergMarquardtParams, default ``factors.lm_params()``); returns (values, iterations)."""
    import gtsam

    params = params or lm_params()
    opt = gtsam.LevenbergMarquardtOptimizer(fg, initial, params)
    limit = params.getMaxIterations()
    current = opt.error()
    if limit == 0 or current <= params.getErrorTol():
        return opt.values(), 0
    while True:
        opt.iterate()
        new = opt.error()
        if (opt.iterations() >= limit or not math.isfinite(new)
                or gtsam.checkConvergence(params.getRelativeErrorTol(), params.getAbsoluteErrorTol(),
                                          params.getErrorTol(), current, new)):
            return opt.values(), opt.iterations()
        current = new
