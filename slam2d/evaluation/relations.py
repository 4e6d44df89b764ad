"""The relations metric of Kümmerle et al. 2009, computed as Cartographer's
``compute_relations_metrics`` does.

A relations file holds one relation a line, ``t1 t2 x y z roll pitch yaw``:
the true pose of the scan at ``t2`` seen from the scan at ``t1`` (m, rad). In
2D only x, y and yaw are used. ``t1 < t2`` is not guaranteed (Intel has 6
relations with ``t1 > t2``); relations are used as written, never swapped.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from slam2d import geometry
from slam2d.errors import InputError, not_a_file, read_text
from slam2d.evaluation.trajectory import _parse_row

__all__ = ["Relations", "read_relations", "relations_metric", "relation_errors", "relations_frame", "format_relations"]


@dataclass(frozen=True, eq=False)
class Relations:
    """Relations: stamps ``t1``, ``t2`` (M,) s and ``delta`` (M, 3) = between(pose(t1), pose(t2))."""

    t1: np.ndarray
    t2: np.ndarray
    delta: np.ndarray

    def __len__(self) -> int:
        return len(self.t1)


def read_relations(path) -> Relations:
    """Read a relations file; blank lines and ``#`` comments are skipped.

    A malformed line raises InputError naming ``file:line``; so does a file
    without relations.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(path, not_a_file(path) or "relations file not found")
    rows = [
        _parse_row(text, f"{path}:{n}", 8)
        for n, line in enumerate(read_text(path).splitlines(), start=1)
        if (text := line.strip()) and not text.startswith("#")
    ]
    if not rows:
        raise InputError(path, "no relations found")
    a = np.array(rows, dtype=np.float64)
    return Relations(a[:, 0], a[:, 1], np.column_stack([a[:, 2], a[:, 3], geometry.wrap_angle(a[:, 7])]))


def _match(stamps: np.ndarray, query: np.ndarray, tolerance: float) -> tuple[np.ndarray, np.ndarray]:
    """Index of the nearest stamp (sorted ``stamps``) to each query and whether it is within ``tolerance``."""
    if len(stamps) == 1:
        k = np.zeros(len(query), dtype=np.int64)
    else:
        k = np.clip(np.searchsorted(stamps, query), 1, len(stamps) - 1)
        k = np.where(np.abs(query - stamps[k - 1]) <= np.abs(stamps[k] - query), k - 1, k)
    return k, np.abs(stamps[k] - query) <= tolerance


def _endpoints(stamps: np.ndarray, relations: Relations, tolerance: float):
    """Index into ``stamps`` (any order) of each relation's two ends, and whether both lie within ``tolerance`` s."""
    order = np.argsort(stamps, kind="stable")
    k1, ok1 = _match(stamps[order], relations.t1, tolerance)
    k2, ok2 = _match(stamps[order], relations.t2, tolerance)
    return order[k1], order[k2], ok1 & ok2


def _mean_std(values: np.ndarray) -> tuple[float, float]:
    """Mean and sample std (n - 1, as Cartographer); NaN when undefined."""
    mean = float(np.mean(values)) if len(values) else float("nan")
    std = float(np.std(values, ddof=1)) if len(values) > 1 else float("nan")
    return mean, std


def relation_errors(stamps, poses, relations: Relations, tolerance: float = 1e-3
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:  # fmt: skip
    """Errors of the relations scored on the trajectory ``(stamps (N,) s, poses (N, 3))``: translation (m) and
    |angle| (deg) of ``compose(between(p1, p2), inverse(delta))``, and which relations (a mask (M,): both ends
    within ``tolerance`` s of a stamp, each matched to the nearest)."""
    stamps = np.asarray(stamps, dtype=np.float64).reshape(-1)
    poses = geometry.as_pose(poses).reshape(-1, 3)
    if len(stamps) != len(poses):
        raise ValueError(f"{len(stamps)} stamps but {len(poses)} poses")
    if len(stamps) == 0:
        raise ValueError("empty trajectory")
    i1, i2, ok = _endpoints(stamps, relations, tolerance)
    p1, p2 = poses[i1[ok]], poses[i2[ok]]
    err = geometry.compose(geometry.between(p1, p2), geometry.inverse(relations.delta[ok]))
    return np.hypot(err[:, 0], err[:, 1]), np.rad2deg(np.abs(err[:, 2])), ok


def relations_metric(stamps, poses, relations: Relations, tolerance: float = 1e-3) -> dict:
    """Relations metric of the trajectory ``(stamps (N,) s, poses (N, 3))``.

    Each relation endpoint is matched to the nearest trajectory stamp; a
    relation with an endpoint farther than ``tolerance`` s from every stamp is
    not scored and counted in ``unmatched``. For the others the error
    (:func:`relation_errors`): its translation norm (m) and |angle| (deg) are
    summarised as mean and sample std (n - 1) of the absolute and squared
    values: ``trans_abs_*`` (m), ``trans_sq_*`` (m^2), ``rot_abs_*`` (deg),
    ``rot_sq_*`` (deg^2), plus ``matched``, ``unmatched``.
    """
    trans, rot, ok = relation_errors(stamps, poses, relations, tolerance)
    out: dict = {}
    for name, values in (("trans_abs", trans), ("trans_sq", trans**2), ("rot_abs", rot), ("rot_sq", rot**2)):
        out[f"{name}_mean"], out[f"{name}_std"] = _mean_std(values)
    out["matched"], out["unmatched"] = int(ok.sum()), int((~ok).sum())
    return out


#: Relations that tell the robot's frame from the laser's: short (odometry is
#: still accurate) and turning (a mounting offset then moves the laser sideways).
FRAME_TEST_MAX_S = 3.0
FRAME_TEST_MIN_TURN = np.radians(20.0)


def relations_frame(stamps, odometry, mounts, relations: Relations, tolerance: float = 1e-3) -> tuple[str, dict]:
    """The frame the relations were measured in: ``"laser"`` or ``"base"`` (the robot's).

    Relation files do not say which. Decided from the odometry alone, not the
    estimate being scored: on relations at most ``FRAME_TEST_MAX_S`` s long that
    turn at least ``FRAME_TEST_MIN_TURN``, the frame whose odometry poses
    (``odometry`` (N, 3) robot poses, ``mounts`` (N, 3) laser mounting poses)
    agree better with the relations (median translational error). ``"laser"``
    when the frames coincide or no relation qualifies. Returns the frame and the
    evidence (relations tested, median error in each frame, m).
    """
    odometry = geometry.as_pose(odometry).reshape(-1, 3)
    mounts = geometry.as_pose(mounts).reshape(-1, 3)
    stamps = np.asarray(stamps, dtype=np.float64).reshape(-1)
    i1, i2, test = _endpoints(stamps, relations, tolerance)
    test &= np.abs(relations.t2 - relations.t1) <= FRAME_TEST_MAX_S
    test &= np.abs(relations.delta[:, 2]) >= FRAME_TEST_MIN_TURN
    evidence: dict = {"tested": int(test.sum())}
    if not test.any() or not np.abs(mounts[:, :2]).any():
        return "laser", evidence
    i1, i2 = i1[test], i2[test]
    for frame, poses in (("base", odometry), ("laser", geometry.compose(odometry, mounts))):
        d = geometry.between(poses[i1], poses[i2])
        evidence[f"{frame}_median_m"] = float(np.median(np.hypot(*(d[:, :2] - relations.delta[test, :2]).T)))
    return ("base" if evidence["base_median_m"] < evidence["laser_median_m"] else "laser"), evidence


def format_relations(metrics: dict) -> str:
    """The metric as Cartographer prints it (mean +/- std, 5 decimals), plus the match counts."""
    lines = [
        f"Abs translational error {metrics['trans_abs_mean']:.5f} +/- {metrics['trans_abs_std']:.5f} m",
        f"Sqr translational error {metrics['trans_sq_mean']:.5f} +/- {metrics['trans_sq_std']:.5f} m^2",
        f"Abs rotational error {metrics['rot_abs_mean']:.5f} +/- {metrics['rot_abs_std']:.5f} deg",
        f"Sqr rotational error {metrics['rot_sq_mean']:.5f} +/- {metrics['rot_sq_std']:.5f} deg^2",
        f"Relations scored {metrics['matched']}, unmatched {metrics['unmatched']}",
    ]
    return "\n".join(lines)
