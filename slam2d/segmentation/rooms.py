"""Split a map file into rooms: the free space of a floor plan or map_server map, a method's labels,
the region graph and the scores against a ground truth, as one :class:`RoomSegmentation`.

A floor-plan image: free = gray >= 250, 0.05 m/px unless ``resolution`` is given, row 0 the top. A
map_server map (``map.yaml``): free = occupancy probability < ``free_thresh``, rows up in y.
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass
from pathlib import Path

import networkx as nx
import numpy as np

from slam2d.errors import InputError
from slam2d.mapping.export import map_yaml_free_thresh
from slam2d.mapping.maps import is_map_yaml, load_map
from slam2d.mapping.topological import region_graph
from slam2d.segmentation.base import SEGMENTATION_METHODS, segment
from slam2d.segmentation.evaluate import load_ground_truth, score

__all__ = ["RoomSegmentation", "segment_map", "segment_free", "find_ground_truth", "free_space"]



FURNISHED_SUFFIX = "_furnitures"
GT_SUFFIX = "_gt_segmentation.png"


def free_space(map_path, resolution: float | None = None) -> dict:
    """Free space of a map file (:func:`slam2d.mapping.maps.load_map`), in the orientation of its image.

    Returns ``dict(free (H, W) bool, resolution m, origin (x, y) m, row0_top)``: a floor plan is
    segmented as drawn (``row0_top``: image row 0 the top); a map_server map in grid rows (rows up in y),
    free = occupancy probability < its YAML's ``free_thresh``.
    """
    path = Path(map_path)
    grid = load_map(path, resolution)
    if is_map_yaml(path):
        free = grid.free_mask(map_yaml_free_thresh(path))
        return dict(free=free, resolution=grid.resolution, origin=grid.origin, row0_top=False)
    return dict(free=np.flipud(grid.free_mask()), resolution=grid.resolution, origin=(0.0, 0.0), row0_top=True)


def find_ground_truth(map_path) -> Path | None:
    """``<stem>_gt_segmentation.png`` beside the map (the unfurnished stem's for ``*_furnitures``), or None."""
    path = Path(map_path)
    stem = path.stem
    if stem.endswith(FURNISHED_SUFFIX):
        stem = stem[: -len(FURNISHED_SUFFIX)]
    gt = path.with_name(stem + GT_SUFFIX)
    return gt if gt.is_file() else None


def segment_free(free, resolution, method, similarity="visibility", params=None, seed: int = 0
                 ) -> tuple[np.ndarray, dict]:  # fmt: skip
    """Labels (H, W) int32 of the free space ``free`` (H, W) bool at ``resolution`` m/cell by ``method``
    (a :data:`~slam2d.segmentation.base.SEGMENTATION_METHODS` name, with ``similarity`` for spectral, the
    method's ``params`` and the run's ``seed``), and run facts (seconds, cpu_seconds; k, silhouette and
    similarity for spectral)."""
    cpu0 = time.process_time()
    run = segment(free, resolution, method, similarity, params, seed=seed)
    run["cpu_seconds"] = time.process_time() - cpu0
    return run.pop("labels"), run


@dataclass(frozen=True, eq=False)
class RoomSegmentation:
    """Rooms of one map. labels: (H, W) int32 in the map's grid orientation (0 = not a room);
    image_labels: the same in the image's orientation (row 0 the top); free: (H, W) bool;
    resolution m/cell; origin (x, y) m; row0_top: whether grid row 0 is the image's top;
    graph: the region graph; metrics: method, rooms, portals, seconds, scores (what metrics.json holds)."""

    map_path: Path
    labels: np.ndarray
    image_labels: np.ndarray
    free: np.ndarray
    resolution: float
    origin: tuple[float, float]
    row0_top: bool
    graph: nx.Graph
    metrics: dict

    @property
    def title(self) -> str:
        """The figure's title: map stem, method and similarity measure."""
        m = self.metrics
        return f"{self.map_path.stem}: {m['method']}" + (f" ({m['similarity']})" if "similarity" in m else "")


def segment_map(map_path, method="spectral", similarity="visibility", *, ground_truth=None, resolution=None,
                params=None, seed: int = 0) -> RoomSegmentation:
    """Segment the map at ``map_path`` into rooms.

    method: a :data:`~slam2d.segmentation.base.SEGMENTATION_METHODS` name; similarity: the spectral
    measure (ignored by the baselines); seed: the run's seed (spectral's default);
    ground_truth: GT image (default: found beside the map, see :func:`find_ground_truth`);
    resolution: m/px for an image map (default 0.05); params: the method's parameters (checked before
    any work). The metrics:
    ``seconds`` (wall) and ``cpu_seconds`` of the segmentation itself, ``furnished`` (the map is a
    ``*_furnitures`` variant), rooms, portals, and the scores against a ground truth.
    """
    map_path = Path(map_path)
    SEGMENTATION_METHODS.resolve_options(method, params, "segmentation.params")  # before reading the map
    m = free_space(map_path, resolution)
    if not m["free"].any():
        raise InputError(map_path, "no free cell: nothing to segment (check the image, negate and free_thresh)")
    labels, run = segment_free(m["free"], m["resolution"], method, similarity, params, seed)
    graph = region_graph(labels, m["resolution"], m["origin"], row0_top=m["row0_top"])
    image_labels = labels if m["row0_top"] else np.flipud(labels)
    metrics = dict(map=str(map_path), furnished=map_path.stem.endswith(FURNISHED_SUFFIX), method=method, **run,
                   rooms=graph.number_of_nodes(), portals=graph.number_of_edges(), params=_params_jsonable(params or {}))
    metrics.update(_score(image_labels, ground_truth, map_path))
    return RoomSegmentation(map_path, labels, image_labels, m["free"], m["resolution"], m["origin"], m["row0_top"],
                            graph, metrics)


def _score(image_labels, ground_truth, map_path) -> dict:
    """Recall, precision, rooms found / in GT against the given or found GT image; {} without one."""
    gt_path = Path(ground_truth) if ground_truth is not None else find_ground_truth(map_path)
    if gt_path is None:
        return {}
    gt = load_ground_truth(gt_path)
    if gt.shape != image_labels.shape:
        raise InputError(gt_path, f"ground truth is {gt.shape[1]}x{gt.shape[0]} px, the map "
                                  f"{image_labels.shape[1]}x{image_labels.shape[0]}")  # fmt: skip
    return dict(score(image_labels, gt), ground_truth=str(gt_path))


def _params_jsonable(params: dict) -> dict:
    """Parameters with anything JSON cannot hold given as its repr."""
    out = {}
    for k, v in params.items():
        try:
            json.dumps(v)
            out[k] = v
        except TypeError:
            out[k] = repr(v)
    return out
