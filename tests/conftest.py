"""Shared fixtures: real data from SLAM2D_DATA (default ../shared/datasets); the localisation benchmark's plans."""

from __future__ import annotations

import os
import sys
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


def load_benchmark(name: str):
    """The module of ``benchmarks/<name>.py``, loaded from its file (the benchmarks are scripts, not a package)."""
    import importlib.util

    path = Path(__file__).resolve().parents[1] / "benchmarks" / f"{name}.py"
    spec = importlib.util.spec_from_file_location(f"{name}_bench", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture
def data_file():
    """Call with a path relative to SLAM2D_DATA; skips (or fails in CI) when absent."""
    return _data_file


@pytest.fixture
def wings_plan(tmp_path) -> Path:
    """The localisation benchmark's U-shaped plan (two wings alike but where the corridor joining them leaves)
    as a PNG (0.05 m/px) in ``tmp_path``."""
    from PIL import Image

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
    from localization import _wings

    Image.fromarray(_wings()[::-1]).save(tmp_path / "wings.png")
    return tmp_path / "wings.png"


@pytest.fixture
def two_place_filter():
    """Call with a KnownMap and ``places`` [(pose (3,), particles), ...]: a ParticleFilter whose equally weighted
    particles sit at those places (5 cm, 0.01 rad spread; the first place its initial pose), estimate clustered."""
    import math

    import numpy as np

    from slam2d.localization import MclConfig, ParticleFilter

    def make(known, places):
        rng = np.random.default_rng(0)
        pf = ParticleFilter(known, MclConfig(), 12.0, seed=0)
        pf.init_pose(np.asarray(places[0][0], float))
        pf.particles = np.concatenate([np.asarray(pose, float) + rng.standard_normal((n, 3)) * [0.05, 0.05, 0.01]
                                       for pose, n in places])  # fmt: skip
        pf.log_w = np.full(len(pf.particles), -math.log(len(pf.particles)))
        pf._estimate = pf._cluster_estimate()
        return pf

    return make
