"""``slam2d segment`` config: a map, a segmentation method, where the ground truth is."""

from __future__ import annotations

from typing import Any, Literal

from pydantic import Field, field_validator

from slam2d.config import CommandConfig, Section

SIMILARITY_ALIASES = {"nearest_neighbor": "nearest_neighbour", "knn": "nearest_neighbour"}


class SegmentationConfig(Section):
    """How a map is split into rooms (:func:`slam2d.segmentation.rooms.segment_map`)."""

    method: Literal["spectral", "morphological", "distance", "voronoi"] = Field(
        "spectral", description="spectral clustering, or a baseline of slam2d.segmentation.baselines"
    )
    similarity: Literal["visibility", "hausdorff", "nearest_neighbour", "feature_points"] = Field(
        "visibility", description="spectral: similarity of virtual observations (ignored by the baselines)"
    )
    params: dict[str, Any] = Field(
        default_factory=dict, description="the method's own parameters (SpectralConfig fields, or the baseline's)"
    )

    @field_validator("similarity", mode="before")
    @classmethod
    def _alias(cls, value):
        return SIMILARITY_ALIASES.get(value, value) if isinstance(value, str) else value


class SegmentConfig(CommandConfig):
    """``slam2d segment``: the map, its ground truth and the segmentation."""

    ground_truth: str | None = Field(
        None, description="ground-truth room image (default: <stem>_gt_segmentation.png beside the map)"
    )
    segmentation: SegmentationConfig = SegmentationConfig()
