"""Shared fixtures: real data from SLAM2D_DATA (default ../shared/datasets)."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

DATA_ROOT = Path(os.environ.get("SLAM2D_DATA", Path(__file__).resolve().parents[1] / ".." / "shared" / "datasets"))


def _data_file(rel: str) -> Path:
    path = DATA_ROOT / rel
    if not path.exists():
        if os.environ.get("SLAM2D_REQUIRE_DATA") == "1":
            pytest.fail(f"required data file missing: {path} (SLAM2D_REQUIRE_DATA=1)")
        pytest.skip(f"data file not found: {path} (set SLAM2D_DATA)")
    return path


@pytest.fixture
def data_file():
    """Call with a path relative to SLAM2D_DATA; skips (or fails in CI) when absent."""
    return _data_file
