"""Readers and the simulator, all yielding the same Scan stream."""

from slam2d.datasets.base import DATASETS, DatasetReader, register_dataset  # noqa: F401
