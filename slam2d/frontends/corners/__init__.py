"""Corner frontend: corners from the range derivative, a global corner list, pose from matched corners.

After the patrol-robot thesis (Tian 2016, sections 2.3.2, 2.3.3 and 4.2.1):

- Extraction (``extraction``): mean-filter the range sequence, take its first derivative
  dr/dphi; local extrema of the derivative are candidates. A corner bends the
  range curve, so its derivative jumps there: each candidate moves to the
  largest normalised jump |r'(i - g) - r'(i + g)| / r(i) within g = half
  window + 1 beams (this merges the maximum and minimum that flank one corner)
  and must reach ``min_slope_change``. Rejected: candidates in the first or
  last ``border_beams`` beams, next to a range jump or a missing beam (an
  occlusion edge), and, as a check the thesis leaves implicit, those whose two
  arms (``arm_beams`` beams each side) are not straight or do not turn by
  ``min_turn_deg`` (by ``significance`` standard errors of the arms' fits).
  An arm ends at a range jump. The corner point is the intersection of the
  arms' TLS lines; its bisector direction is kept too.
- The global corner list (``map``): a new corner within ``merge_radius`` of a listed
  one (and with a bisector within ``max_angle_deg``) is that corner (its
  estimate becomes the running mean); otherwise it is appended once. Look-ups
  use a KD-tree rebuilt lazily (after ``rebuild_every`` appends or when
  entries have moved). A corner seen in one scan only is never matched:
  entries need ``min_observations`` sightings, and tentative ones not seen
  again for ``tentative_scans`` scans are dropped.
- Pose (``matching``): observed corners (at the odometry guess) are associated with listed
  corners within ``match_radius``; the base pose minimises the point residuals
  of all matched corners plus the prior (Gauss-Newton), dropping chi-square
  outliers. One corner fixes position but not heading about it, and the
  information says so. The prior is the pose's own covariance, grown by
  odometry noise (``motion``) since the last match: corners are sparse and a
  few centimetres noisy, so they correct a drifted pose strongly and a fresh
  one little. A one-scan odometry outlier (a turn undone by the next delta)
  is bridged, and the odometry heading is calibrated online (a curvature
  bias and a turn scale, from the accepted matches' heading corrections), so
  it drifts less between matches.
- Confidence: 1 matched corner 0.33, 2 corners 0.66, 3 or more 1.0 (thesis).
  Matched corners are also returned as landmark observations (range, bearing
  from the base) with the list's stable ids.

The frontend class is ``frontend``.
"""

from slam2d.frontends.corners.extraction import (
    CornerExtraction,
    CornerExtractionConfig,
    extract_corners,
)
from slam2d.frontends.corners.frontend import CornerFrontend
from slam2d.frontends.corners.map import CornerMap
from slam2d.frontends.corners.matching import (
    CornerMatch,
    corner_confidence,
    match_corners,
)

__all__ = [
    "CornerExtractionConfig",
    "CornerExtraction",
    "CornerMap",
    "CornerMatch",
    "extract_corners",
    "match_corners",
    "corner_confidence",
    "CornerFrontend",
]
