"""Robust kernels and GNC choices: one vocabulary for configs.

``robust`` names an M-estimator applied to a factor's whitened residual:

- ``none``   plain Gaussian (least squares)
- ``huber``  quadratic within ``param``, linear beyond (``param`` in whitened units, i.e. sigmas)
- ``cauchy`` log(1 + (r/param)^2); heavy tails, outliers keep a small weight
- ``dcs``    dynamic covariance scaling (Agarwal et al. 2013), ``param`` = Phi

GNC (graduated non-convexity, Yang et al. 2020) replaces the kernel in batch
optimisation; ``gnc_params`` builds its parameters with the known inliers
(prior and odometry factors) fixed.

``pc_dcs`` (batch only) screens the loops by pairwise consistency through the
odometry before DCS (``batch.solve_g2o``); ``param`` is DCS's Phi.
"""

from __future__ import annotations

import numpy as np

from slam2d.errors import InputError

ROBUST_KERNELS = ("none", "huber", "cauchy", "dcs")
GNC_LOSSES = ("gm", "tls")  # Geman-McClure, truncated least squares
GNC_INLIER_PROBABILITY = 0.99  # chi-square probability mass an inlier residual stays within
GNC_OUTLIER_WEIGHT = 0.5  # a loop whose final GNC weight is below this is rejected (online and batch)
GNC_METHODS = {"gnc": "tls", "gnc_tls": "tls", "gnc_gm": "gm"}  # batch g2o method -> GNC loss
SCREENED_METHODS = {"pc_dcs": "dcs"}  # batch method -> kernel of its loops after the consistency screen
BATCH_METHODS = ROBUST_KERNELS + tuple(GNC_METHODS) + tuple(SCREENED_METHODS)  # ``solve_g2o(robust=...)``


def check_information(matrix, where: str = "information", kind: str = "information") -> np.ndarray:
    """``matrix`` as a symmetric positive-definite float64 (n, n) array, else InputError
    naming ``where`` and the ``kind`` of matrix ("information" or "covariance")."""
    m = np.asarray(matrix, dtype=np.float64)
    if m.ndim != 2 or m.shape[0] != m.shape[1] or m.size == 0:
        raise InputError(where, f"expected a square {kind} matrix, got shape {m.shape}")
    if not np.all(np.isfinite(m)):
        raise InputError(where, f"non-finite value in the {kind} matrix")
    if np.abs(m - m.T).max() > 1e-8 * max(1.0, np.abs(m).max()):
        raise InputError(where, f"{kind} matrix is not symmetric")
    if np.linalg.eigvalsh(m)[0] <= 0:
        raise InputError(where, f"{kind} matrix is not positive definite")
    return 0.5 * (m + m.T)


def check_information_stack(matrices, where) -> np.ndarray:
    """``check_information`` of a stack (M, n, n) at once; the InputError names the first bad
    matrix by ``where(k)``."""
    m = np.asarray(matrices, dtype=np.float64)
    if m.ndim != 3 or m.shape[1] != m.shape[2] or m.shape[1] == 0:
        raise InputError(where(0), f"expected a stack of square information matrices, got shape {m.shape}")
    finite = np.isfinite(m).all(axis=(1, 2))
    sym = np.abs(m - m.transpose(0, 2, 1)).max(axis=(1, 2), initial=0.0) <= 1e-8 * np.maximum(
        1.0, np.abs(m).max(axis=(1, 2), initial=0.0))
    ok = finite & sym
    ok[ok] = np.linalg.eigvalsh(m[ok])[:, 0] > 0
    if not ok.all():
        k = int(np.argmin(ok))
        check_information(m[k], where(k))  # raises with the reason
    return 0.5 * (m + m.transpose(0, 2, 1))


def m_estimator(robust: str, param: float):
    """The gtsam mEstimator for ``robust`` with width ``param`` (whitened units); None for "none"."""
    import gtsam

    name = str(robust).lower()
    if name not in ROBUST_KERNELS:
        choices = ", ".join(ROBUST_KERNELS)
        raise InputError("backend.robust", f"unknown robust kernel {robust!r} (choose from {choices})")
    if name == "none":
        return None
    if not np.isfinite(param) or param <= 0:
        raise InputError("backend.robust_param", f"must be positive, got {param!r}")
    est = gtsam.noiseModel.mEstimator
    return {"huber": est.Huber, "cauchy": est.Cauchy, "dcs": est.DCS}[name](float(param))


def noise_model(information, robust: str = "none", param: float = 1.0):
    """Gaussian noise model from an (n, n) ``information`` matrix (inverse covariance),
    wrapped in the ``robust`` kernel of width ``param`` unless ``robust == "none"``."""
    import gtsam

    return wrap(gtsam.noiseModel.Gaussian.Information(check_information(information)), m_estimator(robust, param))


def wrap(gaussian, kernel):
    """``gaussian`` under the mEstimator ``kernel`` (None: unchanged)."""
    import gtsam

    return gaussian if kernel is None else gtsam.noiseModel.Robust.Create(kernel, gaussian)


def gnc_params(known_inliers, loss: str = "gm", lm_params=None):
    """gtsam.GncLMParams with ``known_inliers`` (factor indices) fixed as inliers.

    ``loss`` is "gm" (Geman-McClure) or "tls" (truncated least squares).
    """
    import gtsam

    name = str(loss).lower()
    if name not in GNC_LOSSES:
        raise InputError("gnc loss", f"unknown GNC loss {loss!r} (choose from {', '.join(GNC_LOSSES)})")
    params = gtsam.GncLMParams(lm_params) if lm_params is not None else gtsam.GncLMParams()
    params.setLossType(gtsam.GncLossType.GM if name == "gm" else gtsam.GncLossType.TLS)
    params.setKnownInliers([int(k) for k in known_inliers])
    return params


def screened_kernel(method: str) -> str | None:
    """The loop kernel of a screened batch method ("pc_dcs" -> "dcs"), else None."""
    return SCREENED_METHODS.get(str(method).lower())


def gnc_loss(method: str) -> str | None:
    """The GNC loss of a batch method ("gnc" = TLS), None for an M-estimator; InputError if unknown."""
    name = str(method).lower()
    if name not in BATCH_METHODS:
        raise InputError("robust", f"unknown robust method {method!r} (choose from {', '.join(BATCH_METHODS)})")
    return GNC_METHODS.get(name)
