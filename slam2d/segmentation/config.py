"""``slam2d segment`` config: a map, a segmentation method, where the ground truth is."""

from __future__ import annotations

from typing import Annotated, Any

from pydantic import Field

from slam2d.config import CommandConfig, Section
from slam2d.registry import Choice
from slam2d.segmentation.base import SIMILARITY_MEASURES

SIMILARITY_ALIASES = SIMILARITY_MEASURES.aliases
"""Other names of the similarity measures -> theirs (the registry's)."""


class SegmentationConfig(Section):
    """How a map is split into rooms (:func:`slam2d.segmentation.rooms.segment_map`)."""

    method: Annotated[str, Choice("segmentation_methods", options="params")] = Field(
        "spectral", description="spectral clustering, or a baseline of slam2d.segmentation.baselines"
    )
    similarity: Annotated[str, Choice("similarity_measures")] = Field(
        "visibility", description="spectral: similarity of virtual observations (ignored by the baselines)"
    )
    params: dict[str, Any] = Field(
        default_factory=dict, description="the method's own parameters (SpectralConfig fields but similarity, or "
        "the baseline's)"
    )


class SegmentConfig(CommandConfig):
    """``slam2d segment``: the map, its ground truth and the segmentation."""

    ground_truth: str | None = Field(
        None, description="ground-truth room image (default: <stem>_gt_segmentation.png beside the map)"
    )
    segmentation: SegmentationConfig = SegmentationConfig()
