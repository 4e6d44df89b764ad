"""Room segmentation of grid maps.

- :mod:`~slam2d.segmentation.observations`: (pose, scan) observations, real or
  ray-cast from a lattice of viewpoints on the free space;
- :mod:`~slam2d.segmentation.similarity`: Hausdorff, nearest-neighbour,
  feature-point and virtual-visibility similarity of observations;
- :mod:`~slam2d.segmentation.spectral`: spectral clustering with a
  silhouette-chosen k (``segment_spectral``);
- :mod:`~slam2d.segmentation.labelling`: labels for every free cell from the
  clustered observations, and merging of segments cut where there is no doorway;
- :mod:`~slam2d.segmentation.base`: the measures and methods by name, and ``segment``, which runs one;
- :mod:`~slam2d.segmentation.evaluate`: per-room recall / precision against
  ground-truth room images (Bormann et al., ICRA 2016).

Submodules import lazily, so ``import slam2d.segmentation`` stays cheap.
"""

from __future__ import annotations

from slam2d.registry import lazy_exports

_EXPORTS = {
    "SEGMENTATION_METHODS": "base",
    "SIMILARITY_MEASURES": "base",
    "segment": "base",
    "register_method": "base",
    "register_similarity": "base",
    "load_floor_plan": "evaluate",
    "load_ground_truth": "evaluate",
    "score": "evaluate",
    "Observations": "observations",
    "observations_from_scans": "observations",
    "virtual_observations": "observations",
    "SIMILARITIES": "similarity",
    "similarity_matrix": "similarity",
    "SpectralConfig": "spectral",
    "SegmentationResult": "spectral",
    "segment_spectral": "spectral",
    "spectral_clusters": "spectral",
    "label_free_cells": "labelling",
}

__all__ = sorted(_EXPORTS)

__getattr__ = lazy_exports(__name__, _EXPORTS)
