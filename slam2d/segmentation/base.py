"""What a similarity measure and a segmentation method are (the Protocols), both by name, and
:func:`segment`, which runs a method named in a config."""

from __future__ import annotations

import time
from typing import Protocol

import numpy as np

from slam2d.registry import Registry


class SimilarityMeasure(Protocol):
    """Similarity of observations for spectral segmentation."""

    def __call__(self, obs, **options):
        """Symmetric (N, N) similarity in [0, 1] with unit diagonal of the
        :class:`slam2d.segmentation.observations.Observations` ``obs``: a dense array or a scipy sparse one."""
        ...


class SegmentationMethod(Protocol):
    """Splits the free space of a grid into rooms."""

    def __call__(self, free: np.ndarray, resolution: float, **options):
        """Room labels (H, W) int (0 off the rooms) of ``free`` (H, W) bool at ``resolution`` m per cell, or a dict
        of run facts holding them as ``labels`` (and ``seconds`` if the method times itself)."""
        ...


SIMILARITY_MEASURES = Registry(
    "similarity_measures", "measure", key="segmentation.similarity", options_key="similarity_params",
    builtins=dict.fromkeys(("hausdorff", "nearest_neighbour", "feature_points", "visibility"),
                           "slam2d.segmentation.similarity"),
    aliases={"nearest_neighbor": "nearest_neighbour", "knn": "nearest_neighbour"})
"""The similarity measures by name: ``create(name, options, obs)`` is the similarity of ``obs``."""

SEGMENTATION_METHODS = Registry(
    "segmentation_methods", "method", key="segmentation.method", options_key="segmentation.params",
    builtins={"spectral": "slam2d.segmentation.spectral",
              **dict.fromkeys(("morphological", "distance", "voronoi"), "slam2d.segmentation.baselines")})
"""The segmentation methods by name: ``create(name, options, free, resolution, similarity=..., seed=...)`` runs
one; a method that compares observations takes the measure's name (``similarity``) and the run's ``seed``."""


def register_similarity(name: str, **kw):
    """Decorator of a :class:`SimilarityMeasure` function: ``segmentation.similarity: name``."""
    return SIMILARITY_MEASURES.register(name, **kw)


def register_method(name: str, **kw):
    """Decorator of a :class:`SegmentationMethod` function: ``segmentation.method: name``."""
    return SEGMENTATION_METHODS.register(name, **kw)


def segment(free, resolution: float, method: str = "spectral", similarity: str = "visibility", params=None,
            seed: int = 0, key: str | None = None) -> dict:  # fmt: skip
    """Labels (H, W) int32 of the free space ``free`` (H, W) bool at ``resolution`` m/cell by ``method`` with its
    ``params`` (checked first: an InputError names the bad key, under ``key``, default ``segmentation.params``)
    and run facts: ``seconds`` (wall), and what the method reports (k, silhouette and similarity for spectral).
    ``similarity`` and ``seed`` go to the methods that take them."""
    options = SEGMENTATION_METHODS.resolve_options(method, params, key)
    t0 = time.perf_counter()
    out = SEGMENTATION_METHODS.create(method, options, free, resolution, similarity=similarity, seed=seed)
    seconds = time.perf_counter() - t0
    facts = dict(out) if isinstance(out, dict) else {"labels": out}
    facts["labels"] = np.asarray(facts["labels"], np.int32)
    return {"seconds": seconds, **facts}
