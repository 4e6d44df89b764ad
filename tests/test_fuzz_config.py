"""Fuzzing every numeric config field of every command.

Property 1 (every command, every numeric field, its implementations' own options included): an
override with an extreme or random value gives a config, or a one-line InputError naming the key;
never another exception.

Property 2 (the commands quick enough to run many times: SLAM on the simulator's first scans,
segment and plan on a small floor plan): a run with such an
override ends with its results folder or an InputError, and its memory (RSS sampled while it
runs) stays within the budget a ceiling of ``SLAM2D_MAX_MEMORY_GB`` declares.

Seeded (``derandomize``) so CI is deterministic; SLAM2D_FUZZ_EXAMPLES=N runs N examples each.
"""

from __future__ import annotations

import math
import os
import threading

import numpy as np
import psutil
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from PIL import Image
from pydantic import BaseModel

from slam2d import config
from slam2d.errors import InputError
from slam2d.runs.commands import COMMANDS, command_model, resolved, run_command

EXAMPLES = int(os.environ.get("SLAM2D_FUZZ_EXAMPLES", "60"))
RUNS = max(8, EXAMPLES // 4)
FUZZ = settings(max_examples=EXAMPLES, derandomize=True, deadline=None, database=None,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
EXTREMES = [math.nan, math.inf, -math.inf, 0, -1, 1e-300, 1e-9, 1e9, 1e12, 1e300, 2**63, -(2**63), 0.5, 7]
MEMORY_GB = 1.0  # the ceiling the runs are given
MEMORY_SLACK_MB = 300  # what a run may add besides the allocations the ceiling checks (imports, caches)


def numeric_keys(node, prefix: str = "") -> list[str]:
    """Dotted keys of every int or float value (not bool) in a resolved config, options dicts included."""
    items = ((n, getattr(node, n)) for n in type(node).model_fields) if isinstance(node, BaseModel) else node.items()
    keys = []
    for name, value in items:
        if isinstance(value, (BaseModel, dict)):
            keys += numeric_keys(value, f"{prefix}{name}.")
        elif isinstance(value, (int, float)) and not isinstance(value, bool):
            keys.append(prefix + name)
    return keys


KEYS = {name: numeric_keys(resolved(command_model(name)())) for name in COMMANDS}
VALUES = st.one_of(st.sampled_from(EXTREMES), st.floats(allow_nan=True, allow_infinity=True),
                   st.integers(-(2**70), 2**70))  # fmt: skip


def _override(key: str, value) -> dict:
    """``{key: value}`` as --set gives it, an options dict's key as its section (``frontend.options={k: v}``)."""
    for section in (".options.", ".params.", ".mcl.", ".similarity_params."):
        if section in key:
            head, tail = key.split(section, 1)
            return {head + section[:-1]: {tail: value}} if "." not in tail else {key: value}
    return {key: value}


def test_every_command_has_numeric_keys_to_fuzz():
    assert all(KEYS[name] for name in COMMANDS)
    assert "frontend.options.voxel_size" in KEYS["run"] and "planning.queries" in KEYS["plan"]


@FUZZ
@given(data=st.data())
def test_a_numeric_override_gives_a_config_or_an_input_error(data):
    name = data.draw(st.sampled_from(sorted(COMMANDS)))
    key = data.draw(st.sampled_from(KEYS[name]))
    value = data.draw(VALUES)
    try:
        cfg = resolved(config.load(None, _override(key, value), command_model(name)))
    except InputError as err:
        assert "\n" not in str(err) and key.split(".")[0] in str(err), str(err)
        return
    assert cfg is not None


class PeakRss:
    """The largest RSS (bytes) above the one at entry while the block runs, sampled every 5 ms."""

    def __enter__(self):
        self._proc, self._stop = psutil.Process(), threading.Event()
        self.start = self.peak = self._proc.memory_info().rss
        self._thread = threading.Thread(target=self._sample, daemon=True)
        self._thread.start()
        return self

    def _sample(self):
        while not self._stop.wait(0.005):
            self.peak = max(self.peak, self._proc.memory_info().rss)

    def __exit__(self, *exc):
        self._stop.set()
        self._thread.join()
        self.peak = max(self.peak, self._proc.memory_info().rss)

    @property
    def added_mb(self) -> float:
        return (self.peak - self.start) / 1e6


@pytest.fixture(scope="module")
def small_plan(tmp_path_factory):
    """Two 3 m x 3 m rooms joined by a door, 0.05 m/px."""
    free = np.zeros((70, 130), bool)
    free[5:65, 5:62] = True
    free[5:65, 67:125] = True
    free[30:40, 62:67] = True
    path = tmp_path_factory.mktemp("plan") / "plan.png"
    Image.fromarray(np.where(free, 255, 0).astype(np.uint8)).save(path)
    return path


def _base(name: str, plan, out) -> dict:
    if name == "run":
        return {"dataset": {"max_scans": 20}, "output": {"root": str(out), "figures": False}}
    base = {"map": str(plan), "output": {"root": str(out), "figures": False}}
    if name == "segment":
        return base | {"segmentation": {"method": "morphological"}}
    return base | {"planning": {"queries": 3, "min_distance": 2.0}}


@settings(FUZZ, max_examples=RUNS)
@given(data=st.data())
def test_a_run_with_a_numeric_override_ends_cleanly_within_its_memory(data, small_plan, tmp_path, monkeypatch):
    monkeypatch.setenv("SLAM2D_MAX_MEMORY_GB", str(MEMORY_GB))
    name = data.draw(st.sampled_from(["run", "segment", "plan"]))
    key = data.draw(st.sampled_from([k for k in KEYS[name] if not k.endswith(("threads", "queries", "max_scans"))]))
    value = data.draw(st.one_of(st.sampled_from(EXTREMES), st.floats(-1e4, 1e4)))
    base = _base(name, small_plan, tmp_path)
    with PeakRss() as rss:
        try:
            cfg = config.load(None, base | _override(key, value), command_model(name))
            folder = run_command(cfg, quiet=True)
        except InputError:
            folder = None
    assert rss.added_mb < 1000 * MEMORY_GB + MEMORY_SLACK_MB, (key, value, rss.added_mb)
    if folder is not None:
        assert (folder / "metrics.json").is_file()
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]  # no half-written folder left
