"""Scan-to-local-map ICP on kiss-icp's C++ building blocks, planar points (z = 0).

In the manner of kiss-icp's core, each part is a module built by a small factory from the
config (``config.IcpConfig``): the local map (``mapping``), the adaptive threshold
(``threshold``) and the registration (``registration``, with the point-to-line kernels in
``point_to_line`` and the neighbour search in ``grid``); ``frontend`` runs them per scan.

The frontend keeps the robot base pose in its own odometry-like local frame
and a kiss-icp ``VoxelHashMap`` of the last ``map_window`` scans in that frame
(points in the base frame, so the laser mounting pose is already applied).
Each scan is registered to the map starting from the wheel-odometry
prediction, not kiss-icp's constant-velocity model; the returned delta is the
base motion from the previous scan to this one. kiss-icp's
``AdaptiveThreshold`` (fed with the deviation of the result from odometry)
sets the correspondence distance and the robust kernel.

Two solvers share the map, the threshold and the checks:

- ``point_to_line`` (default): 2D Gauss-Newton over (x, y, theta). Each scan
  point is matched to its ``neighbours`` nearest map points (a bucketed grid
  searched in numba); where they form a line the residual is the distance
  across it, where they do not but the scan's own neighbouring beams do, the
  residual is across the scan's line, else it is point-to-point (isolated
  points are dropped). Geman-McClure weights with the adaptive scale to
  ``coarse_convergence``, then a refinement with the fixed ``refine_kernel``
  to ``convergence``; a weak prior on the odometry
  delta keeps directions the scan cannot see (corridors) at odometry.
- ``point_to_point``: kiss-icp's own 6-DoF ``Registration`` on (x, y, 0)
  points, projected to SE(2). With every point at z = 0 the z rows of the
  problem pin z, roll and pitch: the result is planar exactly (checked, and a
  non-planar result falls back to odometry).

The information matrix is J^T W J / sigma^2 of the final residuals in
(x, y, theta), sigma^2 estimated from them, plus the odometry prior, expressed
in the frame of the delta and bounded so every direction's std lies in
[min_sigma, max_sigma]. The confidence is the fraction of points whose
residual is within ``inlier_distance``. Too few points, a non-finite or
non-planar result, a correction beyond the divergence bound or too few
matches fall back to odometry with confidence 0, counted in ``events``.

Degeneracy-aware fusion (``degeneracy``; off by default, ``degeneracy_ratio`` 0): where the
scan constrains a direction less than ``degeneracy_ratio`` times the odometry does (a
generalised eigenvalue of the scan's information against the odometry's), the match's
correction in that direction is dropped and the prediction stands there (solution
remapping, Zhang et al. ICRA 2016): along a corridor the distance comes from odometry,
position across and heading from the walls. Counted under ``DEGENERATE_EVENT``.

Moving points (``moving``; ``moving_margin``, off by default): a scan point that two of the last scans of the
local map saw through (their beams either side of its bearing all reached beyond it by the
margin) was not there then: a person walking. After the match, such points are left out,
the scan is matched again from the result, and they are kept out of the local map (counted
under ``MOVING_EVENT``). A person walking beside the robot along a corridor otherwise drags
the pose along with them: lengthwise nothing else fixes it.

Odometry that lies (frozen then jumping, a wild step, slip): with
``retry_beyond_reach`` the constant-velocity and the no-motion predictions are
also tried as starts when the odometry prediction lies beyond the ICP's reach
from either (translation plus the chord of the turn at ``threshold_range``
above the adaptive threshold: a match from odometry can stop short with enough
points matched; off by default). When the match from the odometry prediction
diverges from it, the two predictions are tried as starts and priors of their
own; a match that agrees with one of them and matches well overrules odometry (counted
under ``ODOMETRY_OVERRULED_EVENT``) instead of falling back to it.

Motion filter: while odometry says the robot moved less than ``still_distance``
and ``still_angle_deg`` since the last registered scan, a scan is not
registered (nor added to the map); its delta is the odometry one with the
tightest information, counted in ``events`` under ``STILL_EVENT`` (a third
of ACES is such scans).
The filter applies only after a registration that agreed with odometry
(within ``STILL_TRUST_XY`` and ``STILL_TRUST_THETA``): after a large correction
the next scan is registered whatever odometry says. Nor does it apply to a scan
whose ranges changed from the last registered scan's by more than
``STILL_RANGE_CHANGE`` × ``still_distance`` (median over the beams): odometry
that freezes while the robot moves says "still", the scan does not
(``STILL_SCAN_MOVED_EVENT``).
"""

from slam2d.frontends.icp.config import IcpConfig
from slam2d.frontends.icp.frontend import (
    DEGENERATE_EVENT,
    MOVING_EVENT,
    ODOMETRY_OVERRULED_EVENT,
    STILL_EVENT,
    STILL_SCAN_MOVED_EVENT,
    IcpFrontend,
)

__all__ = [
    "DEGENERATE_EVENT",
    "MOVING_EVENT",
    "ODOMETRY_OVERRULED_EVENT",
    "STILL_EVENT",
    "STILL_SCAN_MOVED_EVENT",
    "IcpConfig",
    "IcpFrontend",
]
