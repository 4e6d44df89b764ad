"""Bad input: outlier stamps and poses, non-finite fields, corrupt bags; counted skips or one-line errors."""

from __future__ import annotations

import json
import logging
import shutil
import signal
import subprocess
import sys
import time
from datetime import datetime

import numpy as np
import pytest
import yaml
from test_readers import _flaser, _write_bag

from slam2d.datasets import base
from slam2d.datasets.carmen import CarmenSource
from slam2d.datasets.rosbag import RosbagSource
from slam2d.errors import InputError
from slam2d.runs import signals
from slam2d.runs import sweep as sweeps
from slam2d.runs.sweep import run_sweep

N = 300
RANGES = [1.0, 2.0, 3.0, 4.0]


def _log(tmp_path, lines, name="run.clf"):
    path = tmp_path / name
    path.write_text("\n".join(lines) + "\n")
    return path


def _walk(n=N):
    """FLASER lines of a robot driving 0.1 m per 0.2 s along x, stamps from 100 s."""
    return [_flaser(RANGES, 100.0 + 0.2 * i, odom=(0.1 * i, 0.0, 0.0)) for i in range(n)]


# ---------------------------------------------------------------- item 1: one bad stamp


def test_extra_digit_in_first_stamp_drops_only_that_scan(tmp_path):
    lines = _walk()
    lines[0] = lines[0].replace(" 100.0 host", " 1000.0 host")
    source = CarmenSource(_log(tmp_path, lines))
    scans = list(source)
    assert len(scans) == N - 1 and source.skipped == {base.LATE: 1}
    assert scans[0].stamp == pytest.approx(100.2)


def test_line_moved_earlier_drops_only_that_line(tmp_path):
    lines = _walk()
    lines.insert(20, lines.pop(200))
    source = CarmenSource(_log(tmp_path, lines))
    stamps = [s.stamp for s in source]
    assert len(stamps) == N - 1 and source.skipped == {base.LATE: 1}
    assert np.all(np.diff(stamps) > 0)


def test_bag_scan_stamped_far_ahead_is_the_outlier(tmp_path):
    scans = [(100.0 + 0.2 * i, RANGES) for i in range(N)]
    scans[50] = (scans[50][0], RANGES, None, 2e9)  # header stamp, recorded in place
    odoms = [(100.0 + 0.2 * i, (0.1 * i, 0.0, 0.0)) for i in range(N)]
    source = RosbagSource(_write_bag("ros1", tmp_path / "a.bag", scans=scans, odoms=odoms))
    assert len(list(source)) == N - 1 and source.skipped == {base.LATE: 1}


def _clock_reset():
    """A log whose clock goes back 70 s after 100 scans: the last 200 cannot be ordered."""
    return _walk(100) + [_flaser(RANGES, 50.0 + 0.2 * i, odom=(10.0, 0.0, 0.0)) for i in range(200)]


def test_losing_more_than_a_small_fraction_fails_naming_it(tmp_path):
    with pytest.raises(InputError, match=r"run.clf: 16 of 300 scans \(5%\) unusable \(8 scans stamped after .*"
                                         r"more than the 5% allowed \(dataset.max_skipped\)$"):
        list(CarmenSource(_log(tmp_path, _clock_reset())))


def test_max_skipped_lets_a_lossy_log_through_with_a_warning(tmp_path, caplog):
    source = CarmenSource(_log(tmp_path, _clock_reset()))
    source.max_skipped = 1.0
    with caplog.at_level(logging.WARNING):
        assert len(list(source)) == 92  # the 8 scans before the reset are outvoted by the 200 after it
    assert "208 of 300 scans (69.3%) skipped" in caplog.text


# ---------------------------------------------------------------- item 2: numeric fields


def test_absurd_pose_and_odometry_jump_are_skipped(tmp_path):
    lines = _walk()
    lines[40] = _flaser(RANGES, 108.0, odom=(1e15, 0.0, 0.0))
    lines[80] = _flaser(RANGES, 116.0, odom=(10_000.0, 0.0, 0.0))
    lines[0] = _flaser(RANGES, 100.0, odom=(-10_000.0, 0.0, 0.0))  # the first scan has no predecessor
    source = CarmenSource(_log(tmp_path, lines))
    scans = list(source)
    assert len(scans) == N - 3 and source.skipped == {base.BAD_POSE: 1, base.JUMP: 2}
    assert max(abs(s.odom[0]) for s in scans) < 30


def test_robotlaser_non_finite_angular_resolution(tmp_path, caplog):
    def robotlaser(res, t):
        return (f"ROBOTLASER1 0 -1.0 2.0 {res} 20.0 0.01 0 3 1.0 2.0 3.0 0 0 0 0 0 0 0 "
                f"0.1 0.0 0.5 0.5 0.0 {t} host {t}")

    lines = [robotlaser(1.0, 0.2 * i) for i in range(40)]
    lines[3] = robotlaser("nan", 0.6)
    lines[5] = robotlaser("inf", 1.0)
    source = CarmenSource(_log(tmp_path, lines))
    source.max_skipped = 0.1
    with caplog.at_level(logging.WARNING):
        assert len(list(source)) == 38
    assert source.skipped == {"malformed ROBOTLASER1 lines": 2}
    assert "run.clf:4: ROBOTLASER1 line skipped: non-finite start angle, angular resolution" in caplog.text


@pytest.mark.parametrize("increment", [np.nan, np.inf])
def test_bag_non_finite_angle_increment(tmp_path, increment):
    scans = [(1.0 + 0.2 * i, RANGES) for i in range(40)]
    scans[7] = (scans[7][0], RANGES, increment)
    odoms = [(1.0 + 0.2 * i, (0.0, 0.0, 0.0)) for i in range(40)]
    source = RosbagSource(_write_bag("ros1", tmp_path / "a.bag", scans=scans, odoms=odoms))
    scans = list(source)
    assert len(scans) == 39 and source.skipped == {"scans with a non-finite angle or range limit": 1}
    assert all(np.isfinite(s.angles).all() for s in scans)


@pytest.mark.parametrize("bad", [(np.nan, 0.0, 0.0), (0.0, 0.0, np.nan), (1e15, 0.0, 0.0)])
def test_bag_odometry_message_with_nan_or_absurd_pose_is_dropped(tmp_path, bad, caplog):
    scans = [(1.0 + 0.2 * i, RANGES) for i in range(40)]
    odoms = [(1.0 + 0.2 * i, (0.1 * i, 0.0, 0.0)) for i in range(40)]
    odoms[10] = (odoms[10][0], bad)
    source = RosbagSource(_write_bag("ros1", tmp_path / "a.bag", scans=scans, odoms=odoms))
    with caplog.at_level(logging.WARNING):
        scans = list(source)
    assert len(scans) == 40 and not source.skipped
    assert np.isfinite([s.odom for s in scans]).all() and abs(scans[10].odom[0] - 1.0) < 1e-9
    assert "a.bag: /odom message 10: non-finite or absurd pose or stamp; dropped" in caplog.text


# ---------------------------------------------------------------- item 5: corrupt bag chunk


def test_corrupt_bag_chunk_names_the_file(tmp_path):
    scans = [(1.0 + 0.2 * i, np.linspace(1.0, 5.0, 180)) for i in range(200)]
    odoms = [(1.0 + 0.2 * i, (0.0, 0.0, 0.0)) for i in range(200)]
    path = _write_bag("ros1", tmp_path / "c.bag", scans=scans, odoms=odoms, compression="BZ2")
    data = bytearray(path.read_bytes())
    mid = len(data) // 3
    data[mid:mid + 64] = bytes(64)
    path.write_bytes(bytes(data))
    source = RosbagSource(path)  # the index at the end is intact
    with pytest.raises(InputError, match=r"c.bag: /(scan|odom) message \d+: unreadable"):
        list(source)


# ---------------------------------------------------------------- item 6: map.yaml, label images, robot radius


def _map(tmp_path, wall=slice(2, 18)):
    """A 20 x 20 free map with a wall on row 10, written as map.pgm + map.yaml; the YAML's path."""
    from slam2d.config import MappingConfig
    from slam2d.mapping.export import save_map_server
    from slam2d.mapping.grid import OccupancyGrid

    lo = np.full((20, 20), -3.0, np.float32)
    lo[10, wall] = 3.0
    return save_map_server(OccupancyGrid(lo, 0.1, (0.0, 0.0)), tmp_path / "map", MappingConfig())[1]


@pytest.mark.parametrize("key, value, message", [
    ("resolution", "0", "key 'resolution': must be > 0"),
    ("resolution", "-0.05", "key 'resolution': must be > 0"),
    ("resolution", ".nan", "key 'resolution': expected a finite number, got nan"),
    ("resolution", "abc", "key 'resolution': expected a finite number, got 'abc'"),
    ("origin", "[0.0, abc, 0.0]", "key 'origin': expected a finite number, got 'abc'"),
    ("origin", "[0.0, .inf, 0.0]", "key 'origin': expected a finite number, got inf"),
    ("occupied_thresh", "high", "key 'occupied_thresh': expected a finite number, got 'high'"),
    ("free_thresh", "0.9", "keys .free_thresh. 0.9 and .occupied_thresh. 0.65: expected 0 <= free_thresh <"),
    ("negate", "2", "key 'negate': expected 0 or 1, got 2"),
    ("image", "[1, 2]", "key 'image': expected a file name"),
])
def test_map_yaml_values_are_validated(tmp_path, key, value, message):
    from slam2d.mapping.export import load_map_server

    yml = _map(tmp_path)
    lines = [f"{key}: {value}" if line.startswith(f"{key}:") else line for line in yml.read_text().splitlines()]
    yml.write_text("\n".join(lines) + "\n")
    with pytest.raises(InputError, match=f"map.yaml: {message}"):
        load_map_server(yml)


def test_map_image_that_is_not_an_image(tmp_path):
    from slam2d.mapping.export import load_map_server

    yml = _map(tmp_path)
    (tmp_path / "map.pgm").write_bytes(b"\x00garbage" * 50)
    with pytest.raises(InputError, match=r"map.pgm: not a readable image"):
        load_map_server(yml)


def test_16_bit_map_image_is_scaled_not_clipped(tmp_path):
    from PIL import Image

    from slam2d.mapping.export import load_map_server

    yml = _map(tmp_path)
    grey = np.full((4, 6), 65535, np.uint16)  # free
    grey[1] = 0  # occupied
    grey[2] = 205 * 257  # unknown
    Image.fromarray(grey).save(tmp_path / "map16.png")
    yml.write_text(yml.read_text().replace("image: map.pgm", "image: map16.png"))
    grid = load_map_server(yml)
    assert grid.free_mask(0.196)[::-1].sum(axis=1).tolist() == [6, 0, 0, 6]
    assert grid.occupied_mask(0.65)[::-1].sum(axis=1).tolist() == [0, 6, 0, 0]


def test_plan_rejects_bad_labels_and_radius(tmp_path):
    from slam2d.planning.query import plan_on_map

    yml = _map(tmp_path)
    junk = tmp_path / "labels.png"
    junk.write_text("not an image")
    with pytest.raises(InputError, match="labels.png: not a readable label image"):
        plan_on_map(yml, (0.5, 0.5), (1.5, 0.5), "rooms", robot_radius=0.0, labels=junk)
    for radius in (np.nan, np.inf, -0.1):
        with pytest.raises(InputError, match="robot_radius: must be a finite number >= 0"):
            plan_on_map(yml, (0.5, 0.5), (1.5, 0.5), None, robot_radius=radius)


# ---------------------------------------------------------------- items 3-4: interrupted runs and sweeps


def _cli(*args) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "slam2d.cli", *map(str, args)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)


def _wait_for(predicate, timeout=120.0):
    end = time.monotonic() + timeout
    while not predicate():
        assert time.monotonic() < end, "timed out"
        time.sleep(0.1)


def _stop(proc: subprocess.Popen, sig) -> str:
    """Send ``sig`` to ``proc`` alone (as a scheduler or `timeout` does); its stderr once it has exited
    128 + the signal's number (SIGINT 130, SIGTERM 143)."""
    time.sleep(0.5)
    proc.send_signal(sig)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 128 + sig, err
    return err


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_signal_during_run_leaves_no_folder(tmp_path, sig):
    root = tmp_path / "results"
    proc = _cli("run", "-q", "--set", f"output.root={root}")  # the whole default route: long enough
    _wait_for(lambda: root.is_dir() and any(root.iterdir()))
    assert "stopped: no results folder written" in _stop(proc, sig)
    assert list(root.iterdir()) == []


def _sweep(tmp_path, variants, name="sweep"):
    path = tmp_path / f"{name}.yaml"
    config = {"output": {"root": str(tmp_path / "res")}, "mapping": {"resolution": 0.1}}
    path.write_text(yaml.safe_dump({"workers": 1, "config": config, "variants": variants}))
    return path


QUICK = {"dataset.max_scans": 10}


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_signal_during_ablate_stops_and_keeps_finished_variants(tmp_path, sig):
    sweep = _sweep(tmp_path, [{"name": "quick", "set": QUICK}, {"name": "long", "set": {"seed": 1}},
                              {"name": "queued", "set": {"seed": 2}}])
    proc = _cli("ablate", "-q", sweep)
    runs = lambda: list((tmp_path / "res").glob("ablate-sweep-*/runs/*"))  # noqa: E731
    _wait_for(lambda: any(p.name.startswith(".long-") for p in runs()))
    err = _stop(proc, sig)
    (folder,) = (tmp_path / "res").iterdir()
    assert [p.name[:6] for p in runs()] == ["quick-"]  # no hidden, no queued variant
    assert f"1 of 3 variants finished in {folder}; resume with: slam2d ablate {sweep} --resume {folder}" in err
    assert (folder / "table.md").read_text().count("not run (sweep stopped)") == 2


def test_resume_runs_only_missing_variants(tmp_path):
    sweep = _sweep(tmp_path, [{"name": "a", "set": QUICK}, {"name": "b", "set": {**QUICK, "seed": 1}}])
    folder, _ = run_sweep(sweep, quiet=True)
    (kept,) = (folder / "runs").glob("a-*")
    shutil.rmtree(next((folder / "runs").glob("b-*")))
    (folder / "runs" / ".b-stale").mkdir()  # left by a killed process
    again, rows = run_sweep(sweep, quiet=True, resume=folder)
    assert again == folder and [r["error"] for r in rows] == ["", ""]
    names = sorted(p.name for p in (folder / "runs").iterdir())
    assert len(names) == 2 and names[0] == kept.name and names[1].startswith("b-")
    with pytest.raises(InputError, match="not a sweep folder"):
        run_sweep(sweep, quiet=True, resume=tmp_path / "res")


def test_bad_executor_leaves_no_folder_and_same_second_sweeps_do_not_collide(tmp_path, monkeypatch):
    sweep = _sweep(tmp_path, [{"name": "a", "set": QUICK}])
    with pytest.raises(InputError, match="unknown executor 'bogus'"):
        run_sweep(sweep, executor="bogus", quiet=True)
    assert not (tmp_path / "res").exists()

    class Frozen(datetime):
        @classmethod
        def now(cls, tz=None):
            return datetime(2026, 1, 2, 3, 4, 5)

    monkeypatch.setattr(sweeps, "datetime", Frozen)
    first, _ = run_sweep(sweep, quiet=True)
    second, _ = run_sweep(sweep, quiet=True)
    assert (first.name, second.name) == ("ablate-sweep-20260102-030405", "ablate-sweep-20260102-030405-2")


# ---------------------------------------------------------------- item 7: one-line errors before the work starts


def test_binary_config_and_relations_files(tmp_path):
    from slam2d import config
    from slam2d.evaluation.relations import read_relations

    blob = tmp_path / "blob.yaml"
    blob.write_bytes(bytes(range(256)) * 4)
    with pytest.raises(InputError, match=r"blob.yaml: not a text file \(byte 128 is not UTF-8\)"):
        config.load(blob)
    with pytest.raises(InputError, match=r"blob.yaml: not a text file"):
        read_relations(blob)


@pytest.mark.parametrize("sweep, message", [
    ({"workers": "abc", "variants": [{"set": {"seed": 1}}]}, r"sweep.yaml: workers: expected a positive integer"),
    ({"workers": 0, "variants": [{"set": {"seed": 1}}]}, r"sweep.yaml: workers: expected a positive integer"),
    ({"variants": [{"set": 5}]}, r"sweep.yaml: variants\[0\]: each variant needs 'set', a mapping"),
    ({"config": 5, "variants": [{"set": {"seed": 1}}]}, r"sweep.yaml: config: expected a mapping"),
    ({"variants": 5}, r"sweep.yaml: variants: expected a list, got 5"),
    ({"grid": [1]}, r"sweep.yaml: grid: expected a dict"),
    ({"variants": [{"name": "ok", "set": {"seed": 1}}, {"name": "typo", "set": {"frontend.name": "icpp"}}]},
     r"frontend.name: unknown frontend 'icpp'"),
    ({"variants": [{"name": ".hidden", "set": {"seed": 1}}]}, r"variant '.hidden'.*key 'name': .*no leading '.'"),
])
def test_bad_sweep_files(tmp_path, sweep, message):
    from slam2d.runs.sweep import load_sweep

    path = tmp_path / "sweep.yaml"
    path.write_text(yaml.safe_dump(sweep))
    with pytest.raises(InputError, match=message):
        load_sweep(path)


@pytest.mark.parametrize("override, message", [
    ("name=a/b", r"key 'name': .*must be a folder name"),
    ("seed=-1", r"key 'seed': Input should be greater than or equal to 0"),
    ("mapping.free_thresh=0.9", r"key 'mapping': .*free_thresh 0.9 must be below occupied_thresh 0.65"),
])
def test_bad_overrides_refused_by_the_config(override, message):
    from slam2d import config

    with pytest.raises(InputError, match=message):
        config.load(None, [override])


def test_output_root_that_is_a_file_and_tilde(tmp_path, monkeypatch):
    from slam2d import config
    from slam2d.runs.run import run_experiment

    afile = tmp_path / "afile"
    afile.write_text("x")
    with pytest.raises(InputError, match=r"output.root: .*afile is a file, not a folder"):
        run_experiment(config.load(None, [f"output.root={afile}", "dataset.max_scans=5"]), quiet=True)
    monkeypatch.setenv("HOME", str(tmp_path))
    folder = run_experiment(config.load(None, ["output.root=~/res", "dataset.max_scans=5",
                                               "mapping.resolution=0.1"]), quiet=True)
    assert folder.parent == tmp_path / "res"


def test_resolution_too_fine_for_any_map_is_refused_before_the_run(tmp_path, monkeypatch):
    from slam2d import config, pipeline
    from slam2d.runs.run import run_experiment

    monkeypatch.setattr(pipeline.SlamPipeline, "run", lambda *a, **k: pytest.fail("the SLAM ran"))
    cfg = config.load(None, [f"output.root={tmp_path}", "mapping.resolution=1e-7"])
    with pytest.raises(InputError, match=r"mapping.resolution: 1e-07 m per cell: even the 1 m margin alone"):
        run_experiment(cfg, quiet=True)
    assert list(tmp_path.iterdir()) == []


def test_long_offending_input_is_cut_in_the_message(tmp_path):
    from slam2d import config

    path = tmp_path / "bomb.yaml"
    lines = ["a0: &a0 [x, x, x, x, x, x, x, x, x]"]
    lines += [f"a{i}: &a{i} [{', '.join([f'*a{i - 1}'] * 9)}]" for i in range(1, 6)]
    path.write_text("\n".join(lines) + "\nseed: [*a5, *a5]\n")  # an alias bomb: 10^6 strings
    with pytest.raises(InputError) as err:
        config.load(path)
    assert len(str(err.value)) < 300 and "\n" not in str(err.value)
    assert "key 'seed': Input should be a valid integer (got [[[[...], [...]" in str(err.value)  # not expanded


def test_duplicate_yaml_key_is_an_error_naming_the_line(tmp_path):
    from slam2d import config

    path = tmp_path / "dup.yaml"
    path.write_text("seed: 1\nmapping:\n  resolution: 0.1\n  resolution: 0.2\n")
    with pytest.raises(InputError, match=r"dup.yaml:4: malformed YAML \(duplicate key 'resolution'\)"):
        config.load(path)


# ---------------------------------------------------------------- item 8: smaller


def test_metrics_json_has_null_not_nan(tmp_path):
    from slam2d.runs.results import json_text

    text = json_text({"a": float("nan"), "b": np.array([1.0, np.inf]), "c": np.float64(2.0), "d": (np.nan,)})
    assert json.loads(text) == {"a": None, "b": [1.0, None], "c": 2.0, "d": [None]}


def test_plan_without_path_writes_no_folder_and_segment_needs_free_space(tmp_path):
    from typer.testing import CliRunner

    from slam2d.cli import app

    yml = _map(tmp_path, wall=slice(None))  # the wall splits the map
    res = CliRunner().invoke(app, ["plan", "-q", str(yml), "--start", "1.0,0.5", "--goal", "1.0,1.5",
                                   "--robot-radius", "0", "--out", str(tmp_path / "out")])
    assert res.exit_code == 1 and "no path" in res.output
    assert list((tmp_path / "out").iterdir()) == []
    (tmp_path / "map.pgm").write_bytes((tmp_path / "map.pgm").read_bytes().replace(b"\xfe", b"\x00"))  # all walls
    res = CliRunner().invoke(app, ["segment", "-q", str(yml), "--out", str(tmp_path / "seg")])
    assert res.exit_code == 2 and "no free cell" in res.output
    res = CliRunner().invoke(app, ["segment", "-q", str(yml), "--out", str(yml)])
    assert res.exit_code == 2 and f"--out: {yml} is a file, not a folder" in res.output


def test_16_bit_floor_plans_and_worlds_are_scaled_not_clipped(tmp_path):
    from PIL import Image

    from slam2d.planning.grid import load_grid
    from slam2d.segmentation.evaluate import load_floor_plan as segmentation_floor_plan
    from slam2d.sim.world import World

    grey = np.full((6, 8), 65535, np.uint16)  # white: free
    grey[2:4, 3:5] = 30000  # mid grey: not free, occupied in a world
    Image.fromarray(grey).save(tmp_path / "plan16.png")
    free, _ = segmentation_floor_plan(tmp_path / "plan16.png")
    assert free.sum() == 44
    assert load_grid(tmp_path / "plan16.png").free.sum() == 44
    assert World.from_png(tmp_path / "plan16.png", 0.1).grid[0].sum() == 4


def test_an_error_a_signal_caused_is_reported_as_stopped(tmp_path, monkeypatch):
    import typer

    from slam2d.cli import common as cli
    from slam2d.runs.results import results_folder

    monkeypatch.setattr(signals, "_STOPPED", True)  # a signal arrived; its exception became another one
    with pytest.raises(typer.Exit) as stop:
        with cli._stoppable("no results folder written"):
            raise ImportError("initialization failed")  # pybind11 modules say so when an import is interrupted
    assert stop.value.exit_code == 130
    with pytest.raises(KeyboardInterrupt):
        with results_folder(tmp_path, "swallowed"):
            pass  # the signal's own exception was swallowed (in a __del__): the folder is still not published
    assert list(tmp_path.iterdir()) == []
