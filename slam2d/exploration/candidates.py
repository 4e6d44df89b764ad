"""Li et al.'s candidate goals from the current scan (``hybrid-map-autonomous-exploration``, §2).

A-type: a run of beams at the range limit whose arc (beams × Δθ × range) is longer
than the robot's width; the initial goal lies on the line to the arc's middle beam,
``delta`` (0.1 m) short of the range limit. B-type: an occlusion gap, two neighbouring
beams whose ranges differ by more than the robot's width; with N the near end, L the
far end, M on NL with MN = safe_d, Q on the perpendicular to NL at N with NQ = safe_d
on the gap's side, the initial goal is where the ray from the sensor through Q meets
the circle through M.

Adjustment (eq. 2–3): a ``section = {r, start_idx, end_idx}`` is the run of beams
longer than r + safe_dis (free a little beyond the arc) that contains the goal's beam; with β = (end − start)·Δθ and
θ = (idx − start)·Δθ the arcs are HJ = (β − θ)·r and JG = θ·r. A goal at (|OP|, idx)
stands when HJ > safe_dis and JG > safe_dis on every section that OP crosses (radii
every grid cell up to |OP|), and, for A-type, |OP| > d_tho. The goal's beam is moved
within the sections (both types) and A-type goals are also brought closer; a goal
no adjustment makes stand is discarded.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from slam2d import geometry


@dataclass(eq=False)
class Candidate:
    """A candidate goal ``P = {position, d, idx, type, utility}``: ``position`` (x, y) m in the map,
    ``d`` m from the sensor, ``idx`` the beam, ``type`` "A" or "B"; ``node`` the topological node
    that holds it."""

    position: np.ndarray
    d: float
    idx: int
    type: str
    node: int = -1
    utility: float = float("nan")
    gain: float = float("nan")
    alive: bool = True
    extra: dict = field(default_factory=dict)


@dataclass
class CandidateParams:
    """Geometry of the candidate rules (m): robot ``width``, ``delta`` short of the range limit,
    ``safe_d`` (a little over half the width), ``safe_dis`` (arc clearance), ``d_tho`` (nearest A-type
    goal), ``step`` between section radii."""

    width: float = 0.4
    delta: float = 0.1
    safe_d: float = 0.25
    safe_dis: float = 0.25
    d_tho: float = 0.5
    step: float = 0.05


def scan_candidates(ranges, angles, range_max: float, sensor_pose, params: CandidateParams) -> list[Candidate]:
    """A- and B-type candidates of one scan: ``ranges`` (n,) m (NaN: no reading), beam ``angles`` (n,)
    rad in the sensor frame (even spacing), ``sensor_pose`` (3,) in the map."""
    r = _filled(np.asarray(ranges, dtype=np.float64), range_max)
    angles = np.asarray(angles, dtype=np.float64)
    if len(r) < 3:
        return []
    dtheta = float(np.median(np.diff(angles)))
    circular = abs(dtheta * len(r) - 2 * np.pi) < 1.5 * dtheta
    raw = _a_type(r, range_max, dtheta, circular, params) + _b_type(r, angles, dtheta, circular, params)
    out = []
    for d, idx, kind in raw:
        fixed = adjust(r, dtheta, circular, d, idx, kind, params)
        if fixed is None:
            continue
        d2, idx2 = fixed
        local = d2 * np.array([np.cos(angles[idx2]), np.sin(angles[idx2])])
        out.append(Candidate(geometry.transform_points(sensor_pose, local[None])[0], d2, idx2, kind))
    return out


def _filled(r: np.ndarray, range_max: float) -> np.ndarray:
    """Ranges with a missing reading (NaN, dropout) taken from the nearer neighbour; at most ``range_max``."""
    r = np.minimum(r, range_max)
    bad = ~np.isfinite(r)
    if bad.all():
        return np.full_like(r, range_max)
    if bad.any():
        idx = np.arange(len(r))
        good = idx[~bad]
        r[bad] = np.interp(idx[bad], good, r[good])
    return r


def _runs(mask: np.ndarray, circular: bool) -> list[tuple[int, int]]:
    """(start, end) inclusive of the runs of True in ``mask``; a run may wrap (end < start) when circular."""
    n = len(mask)
    if mask.all():
        return [(0, n - 1)]
    edges = np.diff(np.concatenate([[0], mask.astype(np.int8), [0]]))
    starts, ends = np.nonzero(edges == 1)[0], np.nonzero(edges == -1)[0] - 1
    runs = list(zip(starts.tolist(), ends.tolist()))
    if circular and len(runs) > 1 and runs[0][0] == 0 and runs[-1][1] == n - 1:
        runs = [(runs[-1][0], runs[0][1])] + runs[1:-1]
    return runs


def _a_type(r, range_max, dtheta, circular, params) -> list[tuple[float, int, str]]:
    n = len(r)
    out = []
    for s, e in _runs(r >= range_max - 1e-6, circular):
        count = (e - s) % n + 1
        if count * dtheta * range_max > params.width:
            out.append((range_max - params.delta, int((s + (count - 1) // 2) % n), "A"))
    return out


def _b_type(r, angles, dtheta, circular, params) -> list[tuple[float, int, str]]:
    n = len(r)
    nxt = np.arange(n) + 1
    if circular:
        nxt %= n
    else:
        nxt = nxt[:-1]
    i = np.arange(len(nxt))
    jump = r[nxt] - r[i]
    out = []
    xy = r[:, None] * np.column_stack([np.cos(angles), np.sin(angles)])
    for k in np.nonzero(np.abs(jump) > params.width)[0]:
        near, far = (k, nxt[k]) if jump[k] > 0 else (nxt[k], k)
        pn, pl = xy[near], xy[far]
        if _same_surface(xy, near, far, n, circular, params.width / 4):
            continue
        u = (pl - pn) / np.linalg.norm(pl - pn)
        m = pn + params.safe_d * u
        perp = np.array([-u[1], u[0]])
        side = np.sign(geometry.wrap_angle(angles[far] - angles[near]))  # the gap opens this way
        q = [pn + params.safe_d * perp, pn - params.safe_d * perp]
        bearing = [geometry.wrap_angle(np.arctan2(p[1], p[0]) - angles[near]) for p in q]
        qq = q[0] if np.sign(bearing[0]) == side else q[1]
        a = np.arctan2(qq[1], qq[0])
        idx = int(np.round(geometry.wrap_angle(a - angles[0]) / dtheta)) % n if circular else int(
            np.clip(np.round((a - angles[0]) / dtheta), 0, n - 1))  # fmt: skip
        out.append((float(np.linalg.norm(m)), idx, "B"))
    return out


def _same_surface(xy, near: int, far: int, n: int, circular: bool, tol: float) -> bool:
    """Whether the far end continues the wall of the near end (a wall seen at a grazing angle, no
    occlusion): it lies within ``tol`` + 2 % of its range of the line through the near end and the
    near end's other neighbour."""
    step = 1 if far == (near + 1) % n else -1
    other = near - step
    if circular:
        other %= n
    elif not 0 <= other < n:
        return False
    a, b, p = xy[other], xy[near], xy[far]
    d = b - a
    length = np.hypot(*d)
    if length < 1e-9:
        return False
    off = abs(d[0] * (p[1] - a[1]) - d[1] * (p[0] - a[0])) / length
    return bool(off < tol + 0.02 * np.hypot(*p))


def sections(r: np.ndarray, idx: int, radii: np.ndarray, circular: bool) -> tuple[np.ndarray, np.ndarray]:
    """``(start_idx, end_idx)`` (R,) of the sections of ``radii`` (R,) m through beam ``idx``: the run of
    beams longer than the radius that contains ``idx`` (indices may run below 0 or past n for a
    wrapped run; ±inf for a full circle; start > end where beam ``idx`` itself is not longer)."""
    n = len(r)
    radii = np.asarray(radii, dtype=np.float64)
    if circular:
        fwd = np.roll(r, -idx)
        bwd = np.concatenate([[r[idx]], fwd[:0:-1]])
    else:
        fwd, bwd = r[idx:], r[idx::-1]
    kf = np.searchsorted(-np.minimum.accumulate(fwd), -radii, side="left")  # first beam not longer
    kb = np.searchsorted(-np.minimum.accumulate(bwd), -radii, side="left")
    start, end = (idx - kb + 1).astype(np.float64), (idx + kf - 1).astype(np.float64)
    if circular:
        full = kf >= n
        start[full], end[full] = -np.inf, np.inf
    return start, end


def _intervals(r, dtheta, circular, d, idx, params: CandidateParams):
    """Radii (R,) m every ``step`` up to ``d`` and, for each, the beams [lo, hi] (R,) where θ meets
    HJ > safe_dis and JG > safe_dis on every section up to that radius (lo > hi: none)."""
    radii = np.arange(max(params.step, params.safe_dis), d + 1e-9, params.step)
    if len(radii) == 0 or radii[-1] < d - 1e-9:
        radii = np.append(radii, d)
    beyond = np.minimum(radii + params.safe_dis, r.max() - 1e-9)  # beams free safe_dis beyond the radius (or to the limit)
    start, end = sections(r, idx, beyond, circular)
    margin = params.safe_dis / (radii * dtheta)  # beams spanning an arc of safe_dis
    with np.errstate(invalid="ignore"):
        lo = np.maximum.accumulate(np.where(start <= end, start + margin, np.inf))
        hi = np.minimum.accumulate(np.where(start <= end, end - margin, -np.inf))
    return radii, lo, hi


def stands(r, dtheta, circular, d, idx, kind, params: CandidateParams) -> bool:
    """Whether the goal (d, idx) meets HJ > safe_dis and JG > safe_dis on every section OP crosses
    (and |OP| > d_tho for A-type)."""
    if kind == "A" and d <= params.d_tho:
        return False
    _, lo, hi = _intervals(r, dtheta, circular, d, idx, params)
    return bool(lo[-1] < idx < hi[-1])


def adjust(r, dtheta, circular, d, idx, kind, params: CandidateParams) -> tuple[float, int] | None:
    """The adjusted goal (|OP| m, beam) or None: the beam moved to the nearest one that stands
    (both types); for A-type also |OP| shortened to the farthest radius where one stands, above d_tho."""
    n = len(r)
    radii, lo, hi = _intervals(r, dtheta, circular, d, idx, params)
    with np.errstate(invalid="ignore"):
        ok = np.floor(lo) + 1 <= np.ceil(hi) - 1  # a beam strictly inside (lo, hi)
    if kind == "B":
        ok[:-1] = False
    else:
        ok &= radii > params.d_tho
    if not ok.any():
        return None
    k = int(np.nonzero(ok)[0][-1])
    if not np.isfinite(lo[k]) and not np.isfinite(hi[k]):
        return float(radii[k]), int(idx % n)
    beam = int(np.clip(idx, np.floor(lo[k]) + 1, np.ceil(hi[k]) - 1))
    return float(radii[k]), beam % n
