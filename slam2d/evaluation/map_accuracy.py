"""Map accuracy as wall-to-wall distances (the 2018 thesis' Table 5-1): spans across rooms measured in a map
and compared with the true plan.

A :class:`Span` is a line across a room, from a free ``origin`` along a unit ``axis`` both ways to the
first wall faces of the true plan (``near``, ``far``: distances in m from the origin, ``-near`` and
``+far`` along the axis). In a map, given as points in the plan's frame (registered scan endpoints,
or the occupied cells' centres), each face is the first surface the points within ``band`` m of the
line show going out from the origin, from ``inside`` m in front of the true face to ``reach`` m past
it (so the wall's far face, seen from the next room, is left out). The span's error is the measured face-to-face
distance minus the true one; it equals the error of the distance between the walls' mid-planes
(the thesis' measure), whose thickness is the same in both.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Span", "free_space_iou", "measure_spans", "span_summary", "span_table"]

SURFACE = 0.04  # m, half the depth of one wall surface's points (range noise, the map's cells)


@dataclass(frozen=True)
class Span:
    """A span across a room: ``origin`` (2,) m, unit ``axis`` (2,), true face distances ``near``/``far`` (m)."""

    name: str
    origin: tuple[float, float]
    axis: tuple[float, float]
    near: float
    far: float

    @property
    def length(self) -> float:
        """True face-to-face distance (m)."""
        return self.near + self.far


def _face(along: np.ndarray, expected: float, sign: float, inside: float, reach: float, min_points: int) -> float:
    """Along-axis position (m) of the first wall surface met going out from the origin toward ``sign`` between
    ``inside`` m before the true face at ``expected`` m and ``reach`` m past it: found from the
    ``min_points``-th nearest point (so a stray point does not count), then the median of the points within
    ``SURFACE`` m of it, twice (the wall's far face lies beyond); NaN with fewer points."""
    depth = np.sort(sign * along[(sign * along >= expected - inside) & (sign * along <= expected + reach)])
    if len(depth) < min_points:
        return np.nan
    face = float(np.median(depth[depth <= depth[min_points - 1] + SURFACE]))
    for _ in range(2):
        face = float(np.median(depth[np.abs(depth - face) <= SURFACE]))
    return sign * face


def measure_spans(points, spans, viewpoints=None, band: float = 0.15, inside: float = 0.25, reach: float = 0.5,
                  min_points: int = 3) -> np.ndarray:
    """Measured face-to-face length (m) of each span in the map ``points`` (M, 2), in the spans' frame;
    NaN where a face has fewer than ``min_points`` points (not seen in the map). With ``viewpoints``
    (M, 2), where each point was seen from, a face counts only the points seen from the span's side."""
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    views = pts if viewpoints is None else np.asarray(viewpoints, dtype=np.float64).reshape(-1, 2)
    out = np.full(len(spans), np.nan)
    for k, span in enumerate(spans):
        axis = np.asarray(span.axis, float) / np.hypot(*span.axis)
        rel = pts - np.asarray(span.origin, float)
        along = rel @ axis
        band_mask = np.abs(rel @ np.array([-axis[1], axis[0]])) <= band
        side = np.sign(along - (views - np.asarray(span.origin, float)) @ axis)  # +1: seen from nearer the
        # origin going +axis, -1 going -axis; 0 without viewpoints
        lo = _face(along[band_mask & (side <= 0)], span.near, -1.0, inside, reach, min_points)
        hi = _face(along[band_mask & (side >= 0)], span.far, 1.0, inside, reach, min_points)
        out[k] = hi - lo
    return out


def span_summary(spans, measured) -> dict:
    """Counts and errors (m) of ``measured`` lengths against the spans': how many were seen (both faces in
    the map), the mean, median and largest absolute error and the mean signed one (a scale error shows)."""
    err = np.asarray(measured, float) - np.array([s.length for s in spans])
    seen = err[np.isfinite(err)]
    stats = ({"mean_abs_error_m": float(np.mean(np.abs(seen))), "median_abs_error_m": float(np.median(np.abs(seen))),
              "max_abs_error_m": float(np.max(np.abs(seen))), "mean_error_m": float(np.mean(seen))}
             if len(seen) else {})  # fmt: skip
    return {"spans": len(spans), "seen": len(seen), **stats}


def span_table(spans, measured: dict[str, np.ndarray]) -> list[dict]:
    """Rows per span: its name, true length (m) and, per map in ``measured``, the measured length and its
    error (m, measured - true)."""
    rows = []
    for k, span in enumerate(spans):
        row = {"span": span.name, "true_m": round(span.length, 4)}
        for label, values in measured.items():
            row[f"{label}_m"] = float(values[k])
            row[f"{label}_error_m"] = float(values[k] - span.length)
        rows.append(row)
    return rows


def free_space_iou(a, b, free_thresh: float = 0.196) -> float:
    """IoU of the free cells (probability below ``free_thresh``) of two occupancy grids in one world frame:
    how far two maps of one place agree. Counted on each grid's cells (a cell is looked up in the other
    at its centre; outside it is not free); the lower of the two."""
    return min(_free_iou_on(a, b, free_thresh), _free_iou_on(b, a, free_thresh))


def _free_iou_on(a, b, free_thresh: float) -> float:
    rows, cols = np.indices(a.shape)
    centres = a.cell_to_world(np.column_stack([rows.ravel(), cols.ravel()]))
    in_a = a.free_mask(free_thresh).ravel()
    cells = b.world_to_cell(centres)
    ok = b.in_bounds(cells)
    in_b = np.zeros(len(centres), dtype=bool)
    in_b[ok] = b.free_mask(free_thresh)[cells[ok, 0], cells[ok, 1]]
    union = int(np.count_nonzero(in_a | in_b))
    return float(np.count_nonzero(in_a & in_b) / union) if union else 1.0
