"""How well a line map fits the walls: precision and recall of wall length, and the Chamfer distance."""

from __future__ import annotations

import numpy as np

from slam2d.mapping.geometric import (
    nearest_segment,
    point_segment_distance,
    segment_frame,
)

__all__ = ["line_scores", "chamfer"]


def _samples(seg: np.ndarray, step: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Points (S, 2) every ``step`` m along segments (K, 2, 2) (at piece centres), their segment (S,) and weight m."""
    _, length, _ = segment_frame(seg)
    n = np.maximum(1, np.ceil(length / step).astype(int))
    owner = np.repeat(np.arange(len(seg)), n)
    t = (np.arange(n.sum()) - np.repeat(np.cumsum(n) - n, n) + 0.5) / np.repeat(n, n)
    return seg[owner, 0] + t[:, None] * (seg[owner, 1] - seg[owner, 0]), owner, (length / n)[owner]


def _matched(points, owner, seg_p, seg_q, tol, angle_tol) -> np.ndarray:
    """Whether each sample point (of seg_p[owner]) lies within ``tol`` m of a seg_q segment at most ``angle_tol``
    rad off."""
    u_p, _, _ = segment_frame(seg_p)
    u_q, _, _ = segment_frame(seg_q)
    ok = np.zeros(len(points), bool)
    for lo in range(0, len(points), 2048):
        d = point_segment_distance(points[lo : lo + 2048], seg_q)
        along = np.abs(u_p[owner[lo : lo + 2048]] @ u_q.T) >= np.cos(angle_tol)
        ok[lo : lo + 2048] = ((d <= tol) & along).any(axis=1)
    return ok


def line_scores(found, truth, *, tol: float = 0.05, angle_tol_deg: float = 1.0, step: float = 0.01,
                occupied=None) -> dict:
    """Precision and recall of wall length of segments ``found`` against ``truth`` (each (K, 2, 2) m).

    A piece of a segment counts when it lies within ``tol`` m of a segment of the
    other set whose direction is within ``angle_tol_deg``. ``occupied`` (points
    (M, 2) -> bool, e.g. ``World.occupied``) keeps only the true pieces that bound
    free space (occupied on one side, free on the other).
    """
    found, truth = (np.asarray(s, float).reshape(-1, 2, 2) for s in (found, truth))
    angle_tol = np.deg2rad(angle_tol_deg)
    pt, ot, wt = _samples(truth, step)
    if occupied is not None:
        u, _, _ = segment_frame(truth)
        n = np.column_stack([-u[ot, 1], u[ot, 0]]) * (tol / 2)
        keep = occupied(pt + n) != occupied(pt - n)
        pt, ot, wt = pt[keep], ot[keep], wt[keep]
    pf, of, wf = _samples(found, step)
    rec = _matched(pt, ot, truth, found, tol, angle_tol) if len(found) else np.zeros(len(pt), bool)
    pre = _matched(pf, of, found, truth, tol, angle_tol) if len(truth) else np.zeros(len(pf), bool)
    return {"precision": float(wf[pre].sum() / max(wf.sum(), 1e-12)),
            "recall": float(wt[rec].sum() / max(wt.sum(), 1e-12)),
            "found_m": float(wf.sum()), "truth_m": float(wt.sum())}


def chamfer(segments, occupied, resolution: float, origin=(0.0, 0.0)) -> float:
    """Symmetric mean distance (m) between points along ``segments`` (K, 2, 2) m and the centres of the
    boundary cells of ``occupied`` (H, W) bool (occupied cells with a non-occupied 4-neighbour); NaN if
    either is empty."""
    from scipy.ndimage import binary_erosion
    from scipy.spatial import cKDTree

    occupied = np.asarray(occupied, bool)
    rows, cols = np.nonzero(occupied & ~binary_erosion(occupied))
    cells = (np.column_stack([cols, rows]) + 0.5) * resolution + np.asarray(origin, float)
    segments = np.asarray(segments, float).reshape(-1, 2, 2)
    if len(segments) == 0 or len(cells) == 0:
        return float("nan")
    pts, _, _ = _samples(segments, resolution / 2)
    return float((cKDTree(cells).query(pts)[0].mean() + nearest_segment(cells, segments)[1].mean()) / 2)
