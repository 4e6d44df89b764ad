"""Time-optimal parametrisation of a planar path with toppra (TOPP-RA, Pham & Pham 2018).

Geometry: the waypoints (x, y) m are densified (one point every ``spacing``
m along each segment) and joined by a natural cubic spline ``q(s)``
parametrised by chord length, so ``|q'| ~ 1`` and ``s`` is close to arc
length. Densifying keeps the spline within a few mm of the collision-checked
polyline; only the corners are rounded, over about one ``spacing``.

Limits, in toppra's variables ``x = ṡ²`` and ``u = s̈`` at each gridpoint:

- path speed ``|q'| ṡ <= v_max``: ``x <= v_max² / |q'|²``;
- differential-drive yaw rate: the robot follows the path tangent, so
  ``ω = κ v`` with curvature ``κ = (q' × q'') / |q'|³``, hence
  ``x <= ω_max² |q'|⁴ / (q' × q'')²`` — i.e. the speed is bounded by
  ``ω_max`` times the radius of curvature. This is exact for a robot that
  keeps its heading on the path tangent, whereas adding a heading
  coordinate θ(s) to the path would spline θ separately from (x, y) (drift
  from the true tangent, angle wrapping) for no gain;
- tangential acceleration ``dv/dt = |q'| u + (q'·q''/|q'|) x`` in
  ``[-a_max, a_max]`` (a linear constraint, interpolation discretisation).
  The centripetal part ``ω v <= ω_max v_max`` (0.12 m/s² with the defaults)
  is implied by the other two limits.

The output is sampled every ``dt`` s from toppra's gridpoint velocities with
constant path acceleration between gridpoints (as toppra's
``ParametrizeConstAccel``); it starts and ends at rest.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from pydantic import Field

from slam2d.config import Section

__all__ = ["TrajectoryLimits", "TimedPath", "time_parametrize", "spline_path", "plot_profile"]


class TrajectoryLimits(Section):
    """Kinematic limits of a small indoor differential-drive robot."""

    v_max: float = Field(0.4, gt=0, description="path speed limit, m/s")
    a_max: float = Field(0.5, gt=0, description="tangential acceleration limit, m/s²")
    omega_max: float = Field(0.3, gt=0, description="yaw-rate limit, rad/s")


@dataclass(eq=False)
class TimedPath:
    """A trajectory sampled in time: ``t`` (N,) s, ``xy`` (N, 2) m, ``velocity`` (N, 2) m/s,
    ``speed`` (N,) m/s, ``accel`` (N,) tangential m/s², ``omega`` (N,) yaw rate rad/s,
    ``heading`` (N,) rad; ``duration`` s, ``length`` m along the spline,
    ``max_deviation`` m of the spline from the input polyline."""

    t: np.ndarray
    xy: np.ndarray
    velocity: np.ndarray
    speed: np.ndarray
    accel: np.ndarray
    omega: np.ndarray
    heading: np.ndarray
    duration: float
    length: float
    max_deviation: float
    limits: TrajectoryLimits


def _dedupe(waypoints: np.ndarray) -> np.ndarray:
    keep = np.ones(len(waypoints), dtype=bool)
    keep[1:] = np.hypot(*np.diff(waypoints, axis=0).T) > 1e-9
    return waypoints[keep]


def _densify(waypoints: np.ndarray, spacing: float) -> np.ndarray:
    """Points every <= ``spacing`` along the (K, D) polyline, the waypoints included."""
    seg = np.diff(waypoints, axis=0)
    n = np.maximum(np.ceil(np.linalg.norm(seg, axis=1) / spacing - 1e-9).astype(int), 1)
    k = np.repeat(np.arange(len(seg)), n)
    frac = np.concatenate([np.arange(m) / m for m in n]) if len(n) else np.zeros(0)
    return np.vstack([waypoints[k] + frac[:, None] * seg[k], waypoints[-1:]])


def spline_path(waypoints, spacing: float = 0.1):
    """toppra ``SplineInterpolator`` through the densified waypoints (natural cubic, chord length)."""
    import toppra

    pts = _densify(_dedupe(np.asarray(waypoints, dtype=np.float64).reshape(-1, 2)), spacing)
    ss = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(pts, axis=0).T))])
    return toppra.SplineInterpolator(ss, pts, bc_type="natural")


def _x_max(q1: np.ndarray, q2: np.ndarray, limits: TrajectoryLimits) -> np.ndarray:
    """Largest ṡ² allowed by the speed and yaw-rate limits, from q' and q''."""
    n1 = np.maximum(np.hypot(q1[..., 0], q1[..., 1]), 1e-9)
    cross = np.abs(q1[..., 0] * q2[..., 1] - q1[..., 1] * q2[..., 0])
    with np.errstate(divide="ignore"):
        x_turn = np.where(cross > 1e-12, limits.omega_max**2 * n1**4 / cross**2, np.inf)
    return np.minimum(limits.v_max**2 / n1**2, x_turn)


def _speed_bound(path, gridpoints: np.ndarray, limits: TrajectoryLimits, sub: int = 8) -> np.ndarray:
    """Upper bound on ṡ² at each gridpoint: the smallest bound over the two adjacent stages.

    ṡ² is linear in s between gridpoints, so bounding it by the stage minimum
    (sampled ``sub`` times per stage) keeps the limits between gridpoints too.
    """
    frac = np.linspace(0.0, 1.0, sub + 1)
    s = gridpoints[:-1, None] + np.diff(gridpoints)[:, None] * frac[None, :]
    x = _x_max(path(s.ravel(), 1), path(s.ravel(), 2), limits).reshape(s.shape)
    stage = x.min(axis=1)
    out = np.empty(len(gridpoints))
    out[0], out[-1] = stage[0], stage[-1]
    out[1:-1] = np.minimum(stage[:-1], stage[1:])
    return out


def _constraint(limits: TrajectoryLimits):
    """toppra constraint with the speed, yaw-rate and tangential-acceleration limits."""
    from toppra.constraint import DiscretizationType, LinearConstraint, canlinear_colloc_to_interpolate

    class DiffDriveConstraint(LinearConstraint):
        def __init__(self):
            super().__init__()
            self.dof = 2
            self.identical = True
            self.set_discretization_type(DiscretizationType.Interpolation)

        def compute_constraint_params(self, path, gridpoints, *args, **kwargs):
            qs = path(gridpoints, 1)
            qss = path(gridpoints, 2)
            n1 = np.maximum(np.hypot(qs[:, 0], qs[:, 1]), 1e-9)
            xbound = np.column_stack([np.zeros(len(n1)), _speed_bound(path, gridpoints, limits)])
            a = n1[:, None]
            b = ((qs * qss).sum(axis=1) / n1)[:, None]
            f = np.array([[1.0], [-1.0]])
            g = np.array([limits.a_max, limits.a_max])
            a, b, c, f, g, _, _ = canlinear_colloc_to_interpolate(
                a, b, np.zeros_like(a), f, g, None, None, gridpoints, identical=True
            )
            return a, b, c, f, g, None, xbound  # toppra's order: ..., ubound, xbound

    return DiffDriveConstraint()


def _gridpoints(path, ds: float, dtheta: float, sub: int = 8) -> np.ndarray:
    """Knots of the spline, each interval cut to <= ``ds`` and <= ``dtheta`` of tangent turn."""
    knots = path.ss_waypoints
    length = np.diff(knots)
    frac = np.linspace(0.0, 1.0, sub + 1)
    s = knots[:-1, None] + length[:, None] * frac[None, :]
    q1, q2 = path(s.ravel(), 1), path(s.ravel(), 2)
    n1 = np.maximum(np.hypot(q1[:, 0], q1[:, 1]), 1e-9)
    kappa = (np.abs(q1[:, 0] * q2[:, 1] - q1[:, 1] * q2[:, 0]) / n1**3).reshape(s.shape).max(axis=1)
    n = np.maximum(np.ceil(np.maximum(length / ds, length * kappa / dtheta) - 1e-9).astype(int), 1)
    k = np.repeat(np.arange(len(length)), n)
    within = np.concatenate([np.arange(m) / m for m in n])
    return np.concatenate([knots[k] + within * length[k], knots[-1:]])


def _sample(path, ss, sd, dt: float):
    """Times, path positions, path speeds and accelerations every ``dt`` s (constant s̈ per stage)."""
    xs = sd**2
    ds = np.diff(ss)
    t_grid = np.concatenate([[0.0], np.cumsum(2.0 * ds / np.maximum(sd[:-1] + sd[1:], 1e-12))])
    us = (xs[1:] - xs[:-1]) / (2.0 * ds)
    t = np.concatenate([np.arange(0.0, t_grid[-1], dt), t_grid[-1:]])
    i = np.clip(np.searchsorted(t_grid, t, side="right") - 1, 0, len(us) - 1)
    tau = t - t_grid[i]
    v = np.maximum(sd[i] + tau * us[i], 0.0)
    s = np.minimum(ss[i] + tau * sd[i] + 0.5 * tau**2 * us[i], ss[-1])
    return t, s, v, us[i], t_grid[-1]


def _deviation(points: np.ndarray, polyline: np.ndarray) -> float:
    """Largest distance (m) from ``points`` to the polyline."""
    a, b = polyline[:-1], polyline[1:]
    ab = b - a
    l2 = np.maximum((ab**2).sum(axis=1), 1e-18)
    best = np.full(len(points), np.inf)
    for lo in range(0, len(a), 256):  # chunks bound memory on long paths
        sl = slice(lo, lo + 256)
        ap = points[:, None, :] - a[None, sl]
        u = np.clip((ap * ab[None, sl]).sum(axis=2) / l2[None, sl], 0.0, 1.0)
        d = np.hypot(*(ap - u[..., None] * ab[None, sl]).transpose(2, 0, 1))
        best = np.minimum(best, d.min(axis=1))
    return float(best.max()) if len(best) else 0.0


def time_parametrize(waypoints, limits: TrajectoryLimits | None = None, spacing: float = 0.1,
                     ds: float = 0.05, dtheta: float = 0.05, dt: float = 0.05) -> TimedPath:  # fmt: skip
    """Time-optimal rest-to-rest trajectory along the waypoints (K, 2) (x, y) m.

    ``spacing`` m between spline points; toppra gridpoints are the spline
    knots, with each interval cut so that a stage is at most ``ds`` m long
    and turns the tangent by at most ``dtheta`` rad; ``dt`` s between output
    samples.
    """
    import toppra
    import toppra.algorithm

    limits = limits or TrajectoryLimits()
    wp = _dedupe(np.asarray(waypoints, dtype=np.float64).reshape(-1, 2))
    if len(wp) < 2:
        return _at_rest(wp if len(wp) else np.zeros((1, 2)), limits)
    path = spline_path(wp, spacing)
    grid = _gridpoints(path, ds, dtheta)
    algo = toppra.algorithm.TOPPRA([_constraint(limits)], path, gridpoints=grid, solver_wrapper="seidel")
    _, sd, _ = algo.compute_parameterization(0.0, 0.0)
    if sd is None or not np.all(np.isfinite(sd)):
        raise RuntimeError(f"toppra could not parametrise the path ({algo.problem_data.return_code})")
    t, s, v, u, duration = _sample(path, grid, sd, dt)
    q1, q2 = path(s, 1), path(s, 2)
    n1 = np.maximum(np.hypot(q1[:, 0], q1[:, 1]), 1e-9)
    xy = path(s)
    return TimedPath(
        t=t,
        xy=xy,
        velocity=q1 * v[:, None],
        speed=n1 * v,
        accel=n1 * u + (q1 * q2).sum(axis=1) / n1 * v**2,
        omega=(q1[:, 0] * q2[:, 1] - q1[:, 1] * q2[:, 0]) / n1**2 * v,
        heading=np.arctan2(q1[:, 1], q1[:, 0]),
        duration=float(duration),
        length=float(np.hypot(*np.diff(path(grid), axis=0).T).sum()),
        max_deviation=_deviation(path(grid), wp),
        limits=limits,
    )


def _at_rest(point: np.ndarray, limits: TrajectoryLimits) -> TimedPath:
    z = np.zeros(1)
    return TimedPath(z, point[:1].copy(), np.zeros((1, 2)), z, z, z, z, 0.0, 0.0, 0.0, limits)


def plot_profile(timed: TimedPath, path=None, title: str | None = None):
    """Figure of speed, yaw rate and tangential acceleration over time with their limits.

    Saved to ``path`` (PNG) when given; returns the matplotlib Figure.
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    lim = timed.limits
    fig = Figure(figsize=(8.0, 6.0), dpi=120)
    FigureCanvasAgg(fig)
    axes = fig.subplots(3, 1, sharex=True)
    rows = (
        (timed.speed, lim.v_max, "speed (m/s)"),
        (timed.omega, lim.omega_max, "yaw rate (rad/s)"),
        (timed.accel, lim.a_max, "tangential accel. (m/s²)"),
    )
    for ax, (y, bound, label) in zip(axes, rows):
        ax.plot(timed.t, y, linewidth=1.2)
        for sign in (1, -1) if y is not timed.speed else (1,):
            ax.axhline(sign * bound, color="tab:red", linestyle="--", linewidth=0.8)
        ax.set_ylabel(label)
        ax.grid(True, alpha=0.3)
    axes[-1].set_xlabel("time (s)")
    axes[0].set_title(title or f"{timed.length:.2f} m in {timed.duration:.1f} s")
    fig.tight_layout()
    if path is not None:
        Path(path).parent.mkdir(parents=True, exist_ok=True)
        fig.savefig(path)
    return fig
