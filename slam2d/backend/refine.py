"""Dense refinement: after the final batch, the keyframes are aligned to each other's scans.

Every pair of keyframes within ``RefineConfig.radius`` of each other (positions, m) facing within
``MAX_HEADING_GAP`` is aligned point-to-line (``dense.align_pairs``: the later keyframe's points,
thinned to ``SOURCE_VOXEL``, against the local lines of the earlier one's) from the relative pose
the graph gives them. A pair whose scan found a line for at least ``min_overlap`` of its points,
and whose alignment stayed within ``MAX_CORRECTION`` of where it started, becomes a between factor
with the alignment's Hessian as information, under the loops' kernel. The graph is solved with
those factors beside its own (``PoseGraph.solve_with``); the pairs are aligned again from the new
poses for each of ``rounds``.
"""

from __future__ import annotations

import logging
import time

import numpy as np
from scipy.spatial import cKDTree

from slam2d import geometry
from slam2d.backend import dense
from slam2d.backend.probability_grid import voxel_filter
from slam2d.config import RefineConfig

log = logging.getLogger(__name__)

SOURCE_VOXEL = 0.15  # m: a source scan keeps one point per square of this side
MAX_HEADING_GAP = np.deg2rad(90.0)  # rad: keyframes facing further apart are not paired
REGULARISE = 1e-9  # share of the trace added to the diagonal: a corridor's pair leaves one direction free
CHUNK = 20000  # pairs aligned together
MAX_CORRECTION = (0.3, np.deg2rad(5.0))  # m, rad: an alignment that moved further is dropped


def pairs_within(poses, radius: float) -> np.ndarray:
    """Keyframe pairs (P, 2), i < j, whose positions lie within ``radius`` (m) and headings within
    ``MAX_HEADING_GAP`` of each other."""
    poses = np.asarray(poses, dtype=np.float64).reshape(-1, 3)
    pairs = cKDTree(poses[:, :2]).query_pairs(radius, output_type="ndarray").reshape(-1, 2)
    pairs = np.sort(pairs, axis=1)
    gap = np.abs(geometry.wrap_angle(poses[pairs[:, 1], 2] - poses[pairs[:, 0], 2]))
    return pairs[gap <= MAX_HEADING_GAP]


def _align(targets, sources, pairs, start):
    """``dense.align_pairs`` over ``CHUNK`` pairs at a time (memory grows with the points stacked)."""
    parts = [dense.align_pairs(targets, sources, pairs[a:a + CHUNK], start[a:a + CHUNK])
             for a in range(0, len(pairs), CHUNK)]  # fmt: skip
    if not parts:
        return np.zeros((0, 3)), np.zeros((0, 3, 3)), np.zeros(0)
    return tuple(np.concatenate(p) for p in zip(*parts))


def refine(graph, points: list[np.ndarray], cfg: RefineConfig) -> tuple[np.ndarray, dict[str, float]]:
    """Refine ``graph`` (a PoseGraph after its final batch) against the keyframes' ``points`` (each
    (M, 2), base frame, m, in key order); returns the poses (K, 3) and counts for the summary."""
    t0 = time.perf_counter()
    targets = [dense.surface(p) for p in points]
    sources = [voxel_filter(p, SOURCE_VOXEL) for p in points]
    poses = graph.estimate()
    stats = {"dense pairs aligned": 0, "dense pairs kept": 0}
    for _ in range(cfg.rounds):
        pairs = pairs_within(poses, cfg.radius)
        start = geometry.between(poses[pairs[:, 0]], poses[pairs[:, 1]])
        aligned, info, share = _align(targets, sources, pairs, start)
        moved = geometry.between(start, aligned)
        keep = ((share >= cfg.min_overlap) & (np.hypot(moved[:, 0], moved[:, 1]) <= MAX_CORRECTION[0])
                & (np.abs(moved[:, 2]) <= MAX_CORRECTION[1]))  # fmt: skip
        info = 0.5 * (info + np.transpose(info, (0, 2, 1)))
        info += np.eye(3) * (REGULARISE * np.trace(info, axis1=1, axis2=2))[:, None, None]
        poses = graph.solve_with(pairs[keep], aligned[keep], info[keep])
        stats["dense pairs aligned"] += len(pairs)
        stats["dense pairs kept"] += int(keep.sum())
        log.info("dense refinement: %d of %d pairs kept", keep.sum(), len(pairs))
    stats["dense refinement seconds"] = round(time.perf_counter() - t0, 2)
    return poses, stats
