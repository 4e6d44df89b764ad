"""No silent nonsense: a pipe, a folder or a device given as an input file is named as such; scans whose range
limits contradict each other are reported as that; a resumed sweep must be the sweep it was started with."""

from __future__ import annotations

import os

import pytest
import yaml
from test_readers import _flaser

from slam2d.datasets.carmen import CarmenSource
from slam2d.errors import InputError


@pytest.fixture
def fifo(tmp_path):
    path = tmp_path / "pipe.yaml"
    os.mkfifo(path)
    return path


def test_pipe_folder_and_device_as_config(tmp_path, fifo):
    from slam2d import config

    with pytest.raises(InputError, match=r"pipe.yaml: a named pipe \(FIFO\), not a file$"):
        config.load(fifo)  # read, it would block
    with pytest.raises(InputError, match=r"^/dev/null: a device, not a file$"):
        config.load("/dev/null")  # read, it would be an empty config
    with pytest.raises(InputError, match=r": a folder, not a file$"):
        config.load(tmp_path)
    with pytest.raises(InputError, match=r"missing.yaml: config file not found$"):
        config.load(tmp_path / "missing.yaml")


def test_pipe_and_device_as_log_and_map(tmp_path, fifo):
    from slam2d.datasets.rosbag import RosbagSource
    from slam2d.mapping.maps import load_map

    with pytest.raises(InputError, match=r"pipe.yaml: a named pipe \(FIFO\), not a file$"):
        CarmenSource(fifo)
    with pytest.raises(InputError, match=r"^/dev/null: a device, not a file$"):
        CarmenSource("/dev/null")
    with pytest.raises(InputError, match=r"^/dev/null: a device, not a file$"):
        RosbagSource("/dev/null")
    with pytest.raises(InputError, match=r"pipe.yaml: a named pipe \(FIFO\), not a file$"):
        load_map(fifo)


def test_range_min_above_range_max_is_reported_as_bad_limits(tmp_path):
    path = tmp_path / "run.clf"
    path.write_text("\n".join(_flaser([1.0, 2.0, 3.0], 100.0 + 0.2 * i, odom=(0.1 * i, 0.0, 0.0))
                              for i in range(20)) + "\n")
    with pytest.raises(InputError, match=r"unusable \(\d+ scans with bad range limits \(range_min not below "
                                         r"range_max\)\)"):
        list(CarmenSource(path, range_min=5.0, range_max=1.0))


def test_resume_with_a_different_sweep_is_an_error(tmp_path):
    from slam2d.runs.sweep import run_sweep

    config = {"output": {"root": str(tmp_path / "res")}, "mapping": {"resolution": 0.1}, "dataset": {"max_scans": 5}}
    first, second = tmp_path / "a.yaml", tmp_path / "b.yaml"
    first.write_text(yaml.safe_dump({"workers": 1, "config": config, "variants": [{"name": "a", "set": {"seed": 1}}]}))
    second.write_text(yaml.safe_dump({"workers": 1, "config": config, "variants": [{"name": "a", "set": {"seed": 2}}]}))
    folder, _ = run_sweep(first, quiet=True)
    with pytest.raises(InputError, match=rf"^--resume {folder}: its sweep.yaml differs from {second}"):
        run_sweep(second, quiet=True, resume=folder)
    first.write_text("# the same sweep, commented\n" + first.read_text())
    assert run_sweep(first, quiet=True, resume=folder)[0] == folder


def test_pipe_and_device_as_trajectory_world_and_graph(fifo):
    from slam2d.datasets.g2o import read_g2o
    from slam2d.evaluation.trajectory import read_tum
    from slam2d.sim.world import World

    for read in (read_tum, World.from_png, read_g2o):
        with pytest.raises(InputError, match=r"pipe.yaml: a named pipe \(FIFO\), not a file$"):
            read(fifo)
        with pytest.raises(InputError, match=r"^/dev/null: a device, not a file$"):
            read("/dev/null")
