"""Trajectory files (TUM) and trajectory error metrics (ATE, RPE) in SE(2)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from slam2d import geometry
from slam2d.errors import InputError, not_a_file, read_text
from slam2d.types import Trajectory

__all__ = ["write_tum", "read_tum", "align_se2", "ate", "rpe"]

TUM_HEADER = "# timestamp x y z qx qy qz qw"
RPE_DELTA_TOLERANCE = 0.1
"""A pair of the RPE is kept when its distance travelled is within this share of ``delta_m`` (evo's default)."""


def write_tum(path, traj: Trajectory) -> Path:
    """Write ``traj`` as TUM lines ``stamp x y z qx qy qz qw`` (z = 0, yaw quaternion).

    Values are written in the shortest form that reads back exactly.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    p = traj.poses
    half = 0.5 * p[:, 2]
    zeros = np.zeros(len(p))
    rows = np.column_stack([traj.stamps, p[:, 0], p[:, 1], zeros, zeros, zeros, np.sin(half), np.cos(half)])
    body = "".join(" ".join(map(repr, row)) + "\n" for row in rows.tolist())
    path.write_text(TUM_HEADER + "\n" + body)
    return path


def read_tum(path) -> Trajectory:
    """Read a TUM file; yaw is taken from the quaternion (z, roll, pitch dropped).

    Blank lines and ``#`` comments are skipped. Stamps must not decrease.
    A malformed line raises InputError naming ``file:line``.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(path, not_a_file(path) or "trajectory file not found")
    rows, lines = [], []
    for n, line in enumerate(read_text(path).splitlines(), start=1):
        text = line.strip()
        if text and not text.startswith("#"):
            rows.append(_parse_row(text, f"{path}:{n}", 8))
            lines.append(n)
    data = np.array(rows, dtype=np.float64).reshape(-1, 8)
    _check_tum(path, data, lines)
    q = data[:, 4:8] / np.abs(data[:, 4:8]).max(axis=1, keepdims=True)  # scaled: no overflow
    qx, qy, qz, qw = q.T
    yaw = np.arctan2(2.0 * (qw * qz + qx * qy), qw * qw + qx * qx - qy * qy - qz * qz)  # any norm
    return Trajectory(data[:, 0], np.column_stack([data[:, 1], data[:, 2], yaw]))


def _parse_row(text: str, where: str, n_values: int) -> list[float]:
    """Split a line into exactly ``n_values`` finite floats, or raise InputError at ``where``."""
    parts = text.split()
    if len(parts) != n_values:
        raise InputError(where, f"expected {n_values} numbers, got {len(parts)}: {text[:80]!r}")
    try:
        values = [float(v) for v in parts]
    except ValueError:
        raise InputError(where, f"not a number in {text[:80]!r}") from None
    if not np.all(np.isfinite(values)):
        raise InputError(where, f"non-finite value in {text[:80]!r}")
    return values


def _check_tum(path: Path, data: np.ndarray, lines: list[int]) -> None:
    bad = np.flatnonzero(np.abs(data[:, 4:8]).max(axis=1) < 1e-9)
    if len(bad):
        raise InputError(f"{path}:{lines[bad[0]]}", "zero quaternion")
    back = np.flatnonzero(np.diff(data[:, 0]) < 0)
    if len(back):
        raise InputError(f"{path}:{lines[back[0] + 1]}", "timestamp earlier than the line before")


def _check_pair(est, ref) -> tuple[np.ndarray, np.ndarray]:
    est, ref = geometry.as_pose(est).reshape(-1, 3), geometry.as_pose(ref).reshape(-1, 3)
    if est.shape != ref.shape:
        raise ValueError(f"estimate has {len(est)} poses but reference {len(ref)}")
    if len(est) == 0:
        raise ValueError("empty trajectories")
    return est, ref


def align_se2(est, ref) -> np.ndarray:
    """Pose T (3,) minimising sum |T ⊕ est_i - ref_i|^2 over positions (no scale).

    Closed-form 2D Kabsch/Umeyama: rotation from the centred cross and dot sums.
    Apply it with ``geometry.compose(T, est)``.
    """
    est, ref = _check_pair(est, ref)
    e, r = est[:, :2], ref[:, :2]
    ec, rc = e - e.mean(axis=0), r - r.mean(axis=0)
    cross = np.sum(ec[:, 0] * rc[:, 1] - ec[:, 1] * rc[:, 0])
    dot = np.sum(ec[:, 0] * rc[:, 0] + ec[:, 1] * rc[:, 1])
    theta = np.arctan2(cross, dot)
    t = r.mean(axis=0) - geometry.rotation(theta) @ e.mean(axis=0)
    return np.array([t[0], t[1], theta])


def _stats(err: np.ndarray) -> dict[str, float]:
    return {
        "rmse": float(np.sqrt(np.mean(err**2))),
        "mean": float(np.mean(err)),
        "median": float(np.median(err)),
        "max": float(np.max(err)),
        "std": float(np.std(err)),
    }


def ate(est, ref, align: bool = True) -> dict[str, float]:
    """Absolute trajectory error of positions (m): rmse, mean, median, max, std.

    ``est`` and ``ref`` (N, 3) correspond row by row; with ``align`` the estimate
    is first moved by :func:`align_se2`. ``std`` is the population std (as evo).
    """
    est, ref = _check_pair(est, ref)
    if align:
        est = geometry.compose(align_se2(est, ref), est)
    return _stats(np.linalg.norm(est[:, :2] - ref[:, :2], axis=1))


def rpe(est, ref, delta_m: float = 1.0) -> dict[str, float]:
    """Relative pose error over pairs ``delta_m`` metres apart along ``ref``.

    Pairs as ``evo_rpe --delta D --delta_unit m --all_pairs --pairs_from_reference``
    picks them (:func:`_pairs_by_distance`); the error is between(between(ref_i,
    ref_j), between(est_i, est_j)), as evo's relative pose error.
    Returns trans_rmse, trans_mean (m), rot_rmse_deg, rot_mean_deg and pairs;
    the errors are NaN when no pair exists (``pairs`` = 0).
    """
    est, ref = _check_pair(est, ref)
    i, j = _pairs_by_distance(ref, delta_m)
    if len(i) == 0:
        nan = float("nan")
        return {"trans_rmse": nan, "trans_mean": nan, "rot_rmse_deg": nan, "rot_mean_deg": nan, "pairs": 0}
    err = geometry.between(geometry.between(ref[i], ref[j]), geometry.between(est[i], est[j]))
    trans = np.hypot(err[:, 0], err[:, 1])
    rot = np.rad2deg(np.abs(err[:, 2]))
    return {
        "trans_rmse": float(np.sqrt(np.mean(trans**2))),
        "trans_mean": float(np.mean(trans)),
        "rot_rmse_deg": float(np.sqrt(np.mean(rot**2))),
        "rot_mean_deg": float(np.mean(rot)),
        "pairs": int(len(i)),
    }


def _pairs_by_distance(ref: np.ndarray, delta_m: float, tolerance: float = RPE_DELTA_TOLERANCE
                       ) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """Index pairs (i, j) as evo's all-pairs mode picks them: for each i, the later pose j whose distance
    travelled along ``ref`` from i is nearest ``delta_m`` (the earlier of two as near), kept when within
    ``tolerance`` · ``delta_m`` of it."""
    if delta_m <= 0:
        raise ValueError(f"delta_m must be positive, got {delta_m}")
    steps = np.hypot(*np.diff(ref[:, :2], axis=0).T)
    dist = np.concatenate([[0.0], np.cumsum(steps)])
    i = np.arange(len(ref) - 1)
    target = dist[i] + delta_m
    above = np.searchsorted(dist, target, side="left")  # first pose at or beyond the target (> i)
    below = np.searchsorted(dist, dist[np.maximum(above - 1, 0)], side="left")  # first pose of the last value short
    below = np.maximum(below, i + 1)
    has_below = above - 1 > i
    gap_above = np.where(above < len(ref), np.abs(dist[np.minimum(above, len(ref) - 1)] - target), np.inf)
    gap_below = np.where(has_below, np.abs(dist[below] - target), np.inf)
    j = np.where(gap_below <= gap_above, below, above)
    keep = np.minimum(gap_below, gap_above) <= tolerance * delta_m
    return i[keep], j[keep]
