"""Fuzzing every reader and parser: truncation, byte flips, NaN/inf/huge numbers, shuffled and duplicated lines.

Property: a reader either raises a one-line InputError naming the file, or
returns a result whose counts add up (scans used + skipped = scans in the
file) and whose numbers are finite. Never another exception type.

Seeded (``derandomize``) so CI is deterministic; SLAM2D_FUZZ_EXAMPLES=N runs
N examples per reader instead of the default (a longer run).
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from test_readers import _flaser, _write_bag

from slam2d.errors import InputError

EXAMPLES = int(os.environ.get("SLAM2D_FUZZ_EXAMPLES", "100"))
FUZZ = settings(max_examples=EXAMPLES, derandomize=True, deadline=None, database=None,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])

NUMBERS = ["nan", "inf", "-inf", "1e308", "-1e308", "1e15", "2e9", "0", "-0", "-1", "abc", "", "1e-320"]

# ---------------------------------------------------------------- mutations

LINE_OPS = st.one_of(
    st.tuples(st.just("truncate"), st.floats(0, 1)),
    st.tuples(st.just("flip"), st.floats(0, 1), st.integers(0, 255)),
    st.tuples(st.just("number"), st.floats(0, 1), st.floats(0, 1), st.sampled_from(NUMBERS)),
    st.tuples(st.just("swap"), st.floats(0, 1), st.floats(0, 1)),
    st.tuples(st.just("duplicate"), st.floats(0, 1)),
    st.tuples(st.just("delete"), st.floats(0, 1)),
)
BYTE_OPS = st.one_of(
    st.tuples(st.just("truncate"), st.floats(0, 1)),
    st.tuples(st.just("flip"), st.floats(0, 1), st.integers(0, 255)),
    st.tuples(st.just("zeros"), st.floats(0, 1), st.integers(1, 256)),
)


def _at(seq, u: float) -> int:
    return min(int(u * len(seq)), max(len(seq) - 1, 0))


def _line_op(lines: list[bytes], op) -> list[bytes]:
    kind, *a = op
    if not lines:
        return lines
    i = _at(lines, a[0])
    if kind == "number":
        tokens = lines[i].split(b" ")
        tokens[_at(tokens, a[1])] = a[2].encode()
        lines[i] = b" ".join(tokens)
    elif kind == "swap":
        j = _at(lines, a[1])
        lines[i], lines[j] = lines[j], lines[i]
    elif kind == "duplicate":
        lines.insert(i, lines[i])
    elif kind == "delete":
        del lines[i]
    return lines


def _byte_op(data: bytes, op) -> bytes:
    kind, *a = op
    i = _at(data, a[0])
    if kind == "truncate":
        return data[:i]
    if kind == "flip":
        return data[:i] + bytes([a[1]]) + data[i + 1:]
    return data[:i] + bytes(a[1]) + data[i + a[1]:]


def mutate(data: bytes, ops, lines: bool = True) -> bytes:
    """``data`` after ``ops``: line operations on text, byte operations on anything."""
    for op in ops:
        if lines and op[0] in ("number", "swap", "duplicate", "delete"):
            data = b"\n".join(_line_op(data.split(b"\n"), op))
        else:
            data = _byte_op(data, op)
    return data


def _names_file(err: InputError, *paths) -> None:
    assert any(str(p) in err.where for p in paths), f"{err} does not name {paths}"
    assert "\n" not in str(err) and len(str(err)) < 600, str(err)


def _fuzz_dir(tmp_path_factory, name: str) -> Path:
    return tmp_path_factory.mktemp(name)


# ---------------------------------------------------------------- scan readers


def _check_scans(source) -> None:
    """Read every scan; the counts add up and the numbers are sane."""
    scans = list(source)
    assert len(scans) + sum(source.skipped.values()) == len(source)
    if scans:
        stamps = np.array([s.stamp for s in scans])
        assert np.isfinite(stamps).all() and np.all(np.diff(stamps) >= 0)
        assert np.all(np.abs([s.odom for s in scans]) < 1e6)
        assert all(np.isfinite(s.angles).all() for s in scans)


def _read_scans(make, path, max_skipped: float) -> None:
    try:
        source = make(path)
        source.max_skipped = max_skipped
        _check_scans(source)
    except InputError as err:
        _names_file(err, path)


def _carmen_log() -> bytes:
    lines = ["# fuzz", "PARAM robot_front_laser_offset 0.0"]
    for i in range(30):
        lines.append(f"ODOM {0.1 * i} 0.0 0.0 0.1 0.0 0.0 {100.0 + 0.2 * i} host 0.0")
        lines.append(_flaser([1.0 + 0.01 * i, 2.0, 3.0, 4.0], 100.1 + 0.2 * i, odom=(0.1 * i, 0.0, 0.0)))
    lines.append("ROBOTLASER1 0 -1.0 2.0 1.0 20.0 0.01 0 3 1.0 2.0 3.0 0 3.0 0.0 0.0 3.0 0.0 0.0 "
                 "0.1 0.0 0.5 0.5 0.0 106.1 host 0.0")
    return ("\n".join(lines) + "\n").encode()


@FUZZ
@given(ops=st.lists(LINE_OPS, min_size=1, max_size=6), max_skipped=st.sampled_from([0.05, 1.0]))
def test_fuzz_carmen(tmp_path_factory, ops, max_skipped):
    from slam2d.datasets.carmen import CarmenSource

    path = _fuzz_dir(tmp_path_factory, "carmen") / "fuzz.clf"
    path.write_bytes(mutate(_carmen_log(), ops))
    _read_scans(CarmenSource, path, max_skipped)


SCAN_FIELD = st.sampled_from([None, np.nan, np.inf, -np.inf, 0.0, -0.01, 1e15])


@FUZZ
@given(
    increments=st.lists(SCAN_FIELD, min_size=12, max_size=12),
    stamps=st.lists(st.sampled_from([None, 2e9, 0.0, 5.0]), min_size=12, max_size=12),
    odom=st.lists(st.sampled_from([None, np.nan, np.inf, 1e15, -1e4]), min_size=12, max_size=12),
    max_skipped=st.sampled_from([0.05, 1.0]),
    kind=st.sampled_from(["ros1", "ros2"]),
)
def test_fuzz_bag_fields(tmp_path_factory, increments, stamps, odom, max_skipped, kind):
    from slam2d.datasets.rosbag import RosbagSource

    ranges = [1.0, 2.0, 3.0, 4.0]
    scans = [(10.0 + 0.2 * i, ranges, increments[i], 10.0 + 0.2 * i if stamps[i] is None else stamps[i])
             for i in range(12)]
    odoms = [(10.0 + 0.2 * i, (0.1 * i if odom[i] is None else odom[i], 0.0, 0.0)) for i in range(12)]
    name = "fuzz.bag" if kind == "ros1" else "fuzz_ros2"
    path = _write_bag(kind, _fuzz_dir(tmp_path_factory, "bag") / name, scans=scans, odoms=odoms)
    _read_scans(RosbagSource, path, max_skipped)


class Blob(bytes):
    """File contents that print as their length (a failing example stays readable)."""

    def __repr__(self) -> str:
        return f"<{len(self)} bytes>"


@pytest.fixture(scope="module")
def bag_bytes(tmp_path_factory):
    """A small valid ROS 1 bag, chunks compressed (so a flipped byte can break a chunk)."""
    scans = [(10.0 + 0.2 * i, np.linspace(1.0, 4.0, 30)) for i in range(40)]
    odoms = [(10.0 + 0.2 * i, (0.05 * i, 0.0, 0.0)) for i in range(40)]
    path = _write_bag("ros1", tmp_path_factory.mktemp("bag") / "ok.bag", scans=scans, odoms=odoms,
                      compression="BZ2")
    return Blob(path.read_bytes())


@FUZZ
@given(ops=st.lists(BYTE_OPS, min_size=1, max_size=4), max_skipped=st.sampled_from([0.05, 1.0]))
def test_fuzz_bag_bytes(tmp_path_factory, bag_bytes, ops, max_skipped):
    from slam2d.datasets.rosbag import RosbagSource

    path = _fuzz_dir(tmp_path_factory, "bagbytes") / "fuzz.bag"
    path.write_bytes(mutate(bag_bytes, ops, lines=False))
    _read_scans(RosbagSource, path, max_skipped)


# ---------------------------------------------------------------- other parsers


def _parses(read, path, *also) -> None:
    """``read(path)`` returns (with finite poses, if it has any) or raises an InputError naming the file."""
    try:
        result = read(path)
    except InputError as err:
        _names_file(err, path, *also)
        return
    poses = getattr(result, "poses", None)
    assert poses is None or np.isfinite(poses).all()


G2O = b"\n".join([b"VERTEX_SE2 0 0 0 0", b"VERTEX_SE2 1 1 0 0.1", b"VERTEX_SE2 2 2 0.1 0.2",
                  b"EDGE_SE2 0 1 1 0 0.1 100 0 0 100 0 1000", b"EDGE_SE2 1 2 1 0.1 0.1 100 0 0 100 0 1000",
                  b"EDGE_SE2 0 2 2 0.1 0.2 50 0 0 50 0 500", b"FIX 0", b""])
RELATIONS = b"\n".join([b"# t1 t2 x y z roll pitch yaw", b"1.0 2.0 0.5 0.0 0 0 0 0.1",
                        b"2.0 3.0 0.4 0.1 0 0 0 -0.1", b"1.0 3.0 0.9 0.1 0 0 0 0.0", b""])
TUM = b"\n".join([b"# t x y z qx qy qz qw", b"1.0 0 0 0 0 0 0 1", b"2.0 1 0 0 0 0 0.0998 0.995",
                  b"3.0 2 0.5 0 0 0 0.1987 0.980", b""])
MOVINGAI_MAP = b"type octile\nheight 4\nwidth 5\nmap\n.....\n.@@..\n..T..\n.....\n"
SCEN = b"version 1\n0\tm.map\t5\t4\t0\t0\t4\t3\t5.41421356\n0\tm.map\t5\t4\t1\t0\t2\t3\t3.41421356\n"


@pytest.mark.parametrize("name, data, read", [
    ("graph.g2o", G2O, "slam2d.datasets.g2o:read_g2o"),
    ("fuzz.relations", RELATIONS, "slam2d.evaluation.relations:read_relations"),
    ("fuzz.tum", TUM, "slam2d.evaluation.trajectory:read_tum"),
    ("m.map", MOVINGAI_MAP, "slam2d.planning.grid:load_movingai_map"),
    ("m.scen", SCEN, "slam2d.planning.grid:load_scenarios"),
])
def test_fuzz_text_parsers(tmp_path_factory, name, data, read):
    from importlib import import_module

    module, func = read.split(":")
    reader = getattr(import_module(module), func)

    @FUZZ
    @given(ops=st.lists(LINE_OPS, min_size=1, max_size=5))
    def fuzz(ops):
        path = _fuzz_dir(tmp_path_factory, "text") / name
        path.write_bytes(mutate(data, ops))
        _parses(reader, path)

    fuzz()


@pytest.fixture(scope="module")
def map_files(tmp_path_factory):
    """(map.yaml bytes, map.pgm bytes) of a small saved map."""
    from slam2d.config import MappingConfig
    from slam2d.mapping.export import save_map_server
    from slam2d.mapping.grid import OccupancyGrid

    lo = np.full((12, 16), -3.0, np.float32)
    lo[6, 2:14] = 3.0
    pgm, yml = save_map_server(OccupancyGrid(lo, 0.1, (-1.0, 2.0)), tmp_path_factory.mktemp("map") / "map",
                               MappingConfig())
    return Blob(yml.read_bytes()), Blob(pgm.read_bytes())


@FUZZ
@given(yaml_ops=st.lists(LINE_OPS, max_size=4), image_ops=st.lists(BYTE_OPS, max_size=3))
def test_fuzz_map_yaml_and_image(tmp_path_factory, map_files, yaml_ops, image_ops):
    from slam2d.mapping.export import load_map_server

    folder = _fuzz_dir(tmp_path_factory, "map")
    (folder / "map.yaml").write_bytes(mutate(map_files[0], yaml_ops))
    (folder / "map.pgm").write_bytes(mutate(map_files[1], image_ops, lines=False))
    _parses(load_map_server, folder / "map.yaml", folder / "map.pgm")


CONFIG = yaml.safe_dump({"name": "fuzz", "seed": 3, "dataset": {"kind": "carmen", "path": "x.clf", "max_scans": 9},
                         "mapping": {"resolution": 0.1, "free_thresh": 0.2}, "frontend": {"name": "icp"}}).encode()
SWEEP = yaml.safe_dump({"name": "s", "workers": 2, "config": {"dataset": {"max_scans": 5}},
                        "grid": {"seed": [1, 2]}, "variants": [{"name": "a", "set": {"mapping.resolution": 0.2}}]}
                       ).encode()


@FUZZ
@given(ops=st.lists(LINE_OPS, min_size=1, max_size=5))
def test_fuzz_config_and_sweep_yaml(tmp_path_factory, ops):
    from slam2d import config
    from slam2d.runs.sweep import load_sweep

    folder = _fuzz_dir(tmp_path_factory, "yaml")
    (folder / "c.yaml").write_bytes(mutate(CONFIG, ops))
    (folder / "s.yaml").write_bytes(mutate(SWEEP, ops))
    _parses(config.load, folder / "c.yaml")
    _parses(load_sweep, folder / "s.yaml")
