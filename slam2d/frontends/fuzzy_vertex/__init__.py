"""Fuzzy geometric units and vertex landmarks (Chen & Zhang, 2006).

Chen Dongyue, Zhang Liming, "Fuzzy geometric maps and vertex self-localization
for SLAM", Control Theory & Applications 23(5), 2006. Each scan goes through:

1. Twice classification (section 4.1): a coarse pass in beam order starts a
   new set where a point cannot join the current *collinear set* (every point
   within ``xi`` of the least-squares line through the others); a fine pass
   moves the tail point of Q_i to Q_{i+1} while that lowers its line distance.
2. Basic geometric units (section 4.2, eqs. 2-3): ``G = {begin, end, line, l, n}``
   with the orthogonal least-squares line, the end points projected on it and
   the half-width ``l = sqrt(mse + delta_a^2) / (1 - e^-0.5)``.
3. Vertex landmarks (section 4.3.1, eqs. 4-5): two joined units (end of G_i
   within ``sigma`` of the start of G_{i+1}) give ``M = {o, R, m}`` with ``o``
   the intersection of their lines, ``R = min(l_i, l_{i+1})``, ``m = 1``.
4. Matching and offset (eqs. 6, 9): vertices match when
   ``d(o, o') <= min(R, R')``; the paper's offset is ``V* = sum m (o - o') / sum m``
   (heading from a compass). Without a compass the pose is a weighted 2D
   Kabsch fit (weights ``m``) on >= 2 vertices, translation only on one.
5. Map update (eqs. 10-12 for vertices, 13-21 for units).

Lines are kept in normal form ``n . p = rho`` with ``n = (cos phi, sin phi)``
instead of the paper's slope-intercept ``y = a x + b`` (which fails on
vertical walls); :func:`vertex_from_slopes` is eq. 4 verbatim. Two errata are
read as intended: eq. 21 is ``d12 = (n1 l2 d1 + n2 l1 d2) / (n1 l2 + n2 l1)``
and eq. 20 (as printed it subtracts the distances themselves) is the
n-weighted analogue of eq. 11, ``l12 = (n1 l1 + n2 l2) / (n1 + n2) - |d1 - d2| / 2``.

Additions to the paper, each a config option (``FuzzyVertexFrontend.Config``):
a gap cut in the classification (``max_gap``); a minimum size of a unit; a
minimum angle between a vertex's lines, which must cross near the junction;
the directions of a vertex's two walls (arms), checked on matches and used as
a heading measurement (``arm_heading``); the directions of all units matched
to the unit map by eqs. 13-15 as a heading measurement too, also when no
vertex matched (``wall_heading``; the translation then stays the odometry's
and the scan still counts as a fallback); the heading error's displacement at
each unit added to ``delta_a`` (``heading_lever``); a floor and a cap on
``R`` (eq. 11 only shrinks it); a rigidity check on the matched set; the
odometry prediction fused with the vertex fit by information
(``odometry_prior``), with fits too far from it rejected (``max_mahalanobis``);
the pruning of vertices seen only once; and an online calibration of the
odometry heading (curvature bias and turn scale) from the accepted fits
(``calibration``, see ``odometry.HeadingCalibration``). With ``heading="translation"``,
``arm_heading``, ``wall_heading``, ``odometry_prior``, ``rigid_check``,
``calibration`` and the gates off, the frontend is the paper's method as printed.

Modules: ``classification`` (step 1), ``extraction`` (steps 2-3), ``matching`` (step 4 and
the unit matching of eqs. 13-15), ``map`` (step 5), ``frontend`` (the frontend class).
"""

from slam2d.frontends.fuzzy_vertex.classification import (
    coarse_classification,
    fine_classification,
    twice_classification,
)
from slam2d.frontends.fuzzy_vertex.extraction import (
    FUZZY_SCALE,
    Units,
    Vertices,
    extract_vertices,
    fit_units,
    half_width,
    line_intersection,
    scan_points,
    vertex_from_slopes,
)
from slam2d.frontends.fuzzy_vertex.frontend import FuzzyVertexFrontend
from slam2d.frontends.fuzzy_vertex.map import (
    UnitMap,
    VertexMap,
    fuse_units,
    update_vertices,
)
from slam2d.frontends.fuzzy_vertex.matching import (
    fit_se2,
    match_units,
    match_vertices,
    rigid_matches,
    translation_offset,
)

__all__ = [
    "FUZZY_SCALE",
    "Units",
    "Vertices",
    "FuzzyVertexFrontend",
    "twice_classification",
    "coarse_classification",
    "fine_classification",
    "scan_points",
    "fit_units",
    "half_width",
    "line_intersection",
    "vertex_from_slopes",
    "extract_vertices",
    "match_vertices",
    "rigid_matches",
    "translation_offset",
    "fit_se2",
    "update_vertices",
    "match_units",
    "fuse_units",
    "VertexMap",
    "UnitMap",
]
