"""Line-segment frontend: per-scan segment extraction, a global segment map, SE(2) from line normals.

After the patrol-robot thesis (Tian 2016, sections 2.3.1 and 2.3.3):

- Extraction (``extraction``) walks the ordered scan points. The turning angle between the
  chords (p_lo, p_i) and (p_i, p_hi), where p_lo and p_hi lie ``support_length``
  metres of path before and after p_i (one beam each side in the thesis; a
  fixed path length is steadier under range noise), forms a sequence. Long
  runs near zero are line segments, fitted by total least squares and grown
  over neighbouring points within ``grow_tolerance`` of the line (touching
  runs whose union stays within it merge); peaks above ``corner_angle_deg``
  (adjacent peak samples merged) are corners. Chains are split at range
  jumps. Split-and-merge (iterative end-point fit) is the alternative ``method``.
- The global segment map (``map``) holds each line's point moments (count, centroid,
  scatter) in the map frame; a re-observed line is merged into its map line
  (moments added, TLS refitted, endpoints extended), never re-extracted.
- Matching (``matching``) associates observed segments (at the odometry guess) with map
  lines by normal angle, distance and overlap, then solves the base pose by
  Gauss-Newton: each matched line gives a distance residual along its map
  normal at the observed centroid (variance sigma^2 / N) and an angle residual
  (variance sigma^2 / scatter along the line), Cauchy-weighted, plus the
  odometry delta as a prior. When a histogram of normal-angle differences
  points to another heading, the solve also starts from there and the more
  consistent solution wins (odometry turns can be off by 10 degrees and
  more). A corridor constrains nothing along itself, so the information is
  small there (only the odometry prior).
- Confidence is the thesis's eq. 7: matched observed length / observed length.
- Optionally (``calibration``, off by default) the odometry heading is
  calibrated online from the accepted matches (see ``odometry.HeadingCalibration``).

:func:`lines_from_grid` extracts map lines from an occupancy grid (Canny and
probabilistic Hough, scikit-image, through ``slam2d.mapping.geometric``); :meth:`LineFrontend.reanchor` rebuilds the
map lines from such a grid (the ``reanchor_every`` option does it from the
frontend's own recent scans). The segments and their moments are ``segments``; the
frontend class is ``frontend``.
"""

from slam2d.frontends.lines.extraction import (
    LineExtraction,
    LineExtractionConfig,
    extract_lines,
    lines_from_grid,
)
from slam2d.frontends.lines.frontend import LineFrontend
from slam2d.frontends.lines.map import SegmentMap
from slam2d.frontends.lines.matching import (
    LineMatch,
    LineMatchConfig,
    associate,
    heading_correction,
    match_lines,
)
from slam2d.frontends.lines.segments import Segments, fit_line

__all__ = [
    "LineExtractionConfig",
    "LineMatchConfig",
    "Segments",
    "LineExtraction",
    "SegmentMap",
    "LineMatch",
    "fit_line",
    "extract_lines",
    "associate",
    "heading_correction",
    "match_lines",
    "lines_from_grid",
    "LineFrontend",
]
