"""Room segmentation against ground truth: per-room pixel recall and precision.

Follows the benchmark of Bormann et al., "Room segmentation: survey,
implementation, and analysis", ICRA 2016 (``ipa_room_segmentation``,
``EvaluationSegmentation::computePrecisionRecall``, "micro" averages):

- ground truth: the GT image read as grayscale, thresholded ``> 250``, each
  8-connected white component one room; components of ``<= 100`` px dropped;
- segments: every label ``!= 0`` of the segmentation; segments of ``<= 100`` px
  are dropped as well (as the reference does);
- recall: for each GT room, the largest overlap with any segment divided by
  the room's area; averaged over GT rooms;
- precision: for each segment, the largest overlap with any GT room divided by
  the segment's *full* area (pixels outside every GT room, e.g. on door lines
  drawn into the GT, count against precision, as in the reference); averaged
  over segments.

Percentages in [0, 100]. The overlaps are one contingency matrix built with
``np.bincount`` over (segment, room) label pairs.
"""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np
from scipy import ndimage

from slam2d.errors import InputError, not_a_file

__all__ = ["load_floor_plan", "load_ground_truth", "score", "contingency", "FREE_THRESHOLD", "MIN_ROOM_PX"]

log = logging.getLogger(__name__)

FREE_THRESHOLD = 250
"""Floor plan pixels ``>= FREE_THRESHOLD`` are free; GT pixels ``> FREE_THRESHOLD`` are room."""

MIN_ROOM_PX = 100
"""GT rooms and segments of this many pixels or fewer are ignored."""

RESOLUTION = 0.05
"""Metres per pixel of the rooms/ benchmark maps."""


def _read_gray(path) -> np.ndarray:
    """Image file as a (H, W) uint8 grayscale array (16-bit images scaled, not clipped)."""
    from slam2d.mapping.image import read_grey

    path = Path(path)
    if not path.is_file():
        raise InputError(path, not_a_file(path) or "file not found")
    return read_grey(path)


def load_floor_plan(path) -> tuple[np.ndarray, float]:
    """Floor plan PNG -> (free (H, W) bool, resolution 0.05 m/px).

    Free is a gray value ``>= 250`` (white); everything else is obstacle or
    unknown. Row 0 is the image's top row (no flip).
    """
    gray = _read_gray(path)
    return gray >= FREE_THRESHOLD, RESOLUTION


def load_ground_truth(path) -> np.ndarray:
    """GT segmentation PNG -> room labels (H, W) int32: 0 = no room, rooms 1..R.

    White (``> 250``) 8-connected components are rooms; components of
    ``<= 100`` px are dropped. Rooms are numbered in raster order of their
    first pixel.
    """
    gray = _read_gray(path)
    return label_rooms(gray > FREE_THRESHOLD)


def label_rooms(mask: np.ndarray, min_px: int = MIN_ROOM_PX) -> np.ndarray:
    """8-connected components of ``mask`` larger than ``min_px``, numbered 1..R (int32)."""
    lab, n = ndimage.label(np.asarray(mask, dtype=bool), structure=np.ones((3, 3), dtype=int))
    if n == 0:
        return lab.astype(np.int32)
    sizes = np.bincount(lab.ravel(), minlength=n + 1)
    keep = sizes > min_px
    keep[0] = False
    remap = np.zeros(n + 1, dtype=np.int32)
    remap[keep] = np.arange(1, int(keep.sum()) + 1, dtype=np.int32)
    return remap[lab]


def _compact(labels: np.ndarray) -> tuple[np.ndarray, int]:
    """Relabel non-zero values to 1..n (0 stays 0); returns (compact labels, n)."""
    flat = labels.ravel()
    uniq, inv = np.unique(flat, return_inverse=True)
    if uniq.size and uniq[0] == 0:
        return inv.reshape(labels.shape), uniq.size - 1
    return (inv + 1).reshape(labels.shape), uniq.size


def contingency(labels: np.ndarray, gt: np.ndarray) -> np.ndarray:
    """Overlap counts C[s, r] (pixels) of compacted segment s and GT label r, row/col 0 = background."""
    seg, ns = _compact(np.asarray(labels))
    ng = int(gt.max()) if gt.size else 0
    pair = seg.ravel().astype(np.int64) * (ng + 1) + gt.ravel().astype(np.int64)
    return np.bincount(pair, minlength=(ns + 1) * (ng + 1)).reshape(ns + 1, ng + 1)


def score(labels, gt) -> dict:
    """Per-room recall and precision (%) of a segmentation against GT room labels.

    labels: (H, W) int, 0 = unlabelled, any other value a segment id.
    gt: (H, W) int from :func:`load_ground_truth` (0 = no room, rooms 1..R).
    Returns ``dict(recall, precision, rooms_found, rooms_gt)``: recall averaged
    over GT rooms, precision over segments (both ``> 100`` px; see the module
    docstring for the exact definition); a side with no rooms scores 0.
    """
    labels = np.asarray(labels)
    gt = np.asarray(gt)
    if labels.shape != gt.shape:
        raise InputError("score", f"labels {labels.shape} and ground truth {gt.shape} differ in shape")
    if gt.size and gt.min() < 0:
        raise InputError("score", "ground truth labels must be >= 0")
    c = contingency(labels, gt)
    seg_area = c.sum(axis=1)[1:]
    gt_area = c.sum(axis=0)[1:]
    seg_ok = seg_area > MIN_ROOM_PX
    gt_ok = gt_area > MIN_ROOM_PX
    inner = c[1:, 1:][np.ix_(seg_ok, gt_ok)]
    recall = inner.max(axis=0) / gt_area[gt_ok] if inner.size else np.zeros(int(gt_ok.sum()))
    precision = inner.max(axis=1) / seg_area[seg_ok] if inner.size else np.zeros(int(seg_ok.sum()))
    return dict(
        recall=100.0 * float(recall.mean()) if recall.size else 0.0,
        precision=100.0 * float(precision.mean()) if precision.size else 0.0,
        rooms_found=int(seg_ok.sum()),
        rooms_gt=int(gt_ok.sum()),
    )
