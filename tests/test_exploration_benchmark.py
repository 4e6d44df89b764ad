"""The exploration benchmark's pairing of runs (benchmarks/exploration.py): ratios per world and seed, and the
figure of their spread."""

import math

from conftest import load_benchmark


def _bench():
    return load_benchmark("exploration")


def _run(world, seed, strategy, d90, d99):
    return {"world": world, "seed": seed, "strategy": strategy, "distance_to_90": d90, "distance_to_99": d99,
            "reachable_area_m2": 300.0}  # fmt: skip


RUNS = [
    _run("lab", 0, "utility", 40.0, 80.0), _run("lab", 0, "nearest_frontier", 50.0, 100.0),
    _run("lab", 0, "explore_lite", 40.0, 160.0),
    _run("lab", 1, "utility", 30.0, math.nan), _run("lab", 1, "nearest_frontier", 60.0, 90.0),  # never reached 99 %
    _run("lab_furnitures", 0, "utility", 20.0, 30.0), _run("lab_furnitures", 0, "nearest_frontier", 10.0, 20.0),
]  # fmt: skip


def test_each_pair_is_the_same_world_and_seed_and_a_run_short_of_the_coverage_is_left_out():
    bench = _bench()
    assert sorted(bench.paired(RUNS, "utility", "nearest_frontier", 99)) == [("lab", 0, 0.8), ("lab_furnitures", 0, 1.5)]
    assert sorted(bench.paired(RUNS, "utility", "nearest_frontier", 90)) == [
        ("lab", 0, 0.8), ("lab", 1, 0.5), ("lab_furnitures", 0, 2.0)]  # fmt: skip
    assert bench.paired(RUNS, "utility", "explore_lite", 99) == [("lab", 0, 0.5)]
    table = "\n".join(bench.paired_ratios(RUNS))
    assert "| nearest_frontier | 90 % | 3 | 0.80 | " in table
    assert table.splitlines()[3].endswith("| 0.80–1.50 | 1 |")  # to 99 %: the range, shorter in one pair


def test_the_figure_of_the_spread_is_drawn(tmp_path):
    out = tmp_path / "spread.png"
    _bench().figure(RUNS, str(out))
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and out.stat().st_size > 10_000


def test_every_run_reports_its_online_pose_error_and_clearance_against_the_targets():
    bench = _bench()
    runs = [{"world": "lab", "strategy": "utility", "seed": 0, "pose_error_p95": 0.04, "pose_error_max": 0.12,
             "pose_error_max_time": 310.0, "heading_error_max_deg": 1.5, "min_clearance": 0.061, "coverage": 0.999},
            {"world": "lab", "strategy": "tour", "seed": 0, "pose_error_p95": 0.04, "pose_error_max": 0.31,
             "pose_error_max_time": 90.0, "heading_error_max_deg": 2.0, "min_clearance": 0.07, "coverage": 0.995},
            {"world": "lab", "strategy": "nearest_frontier", "seed": 0, "min_clearance": 0.02, "coverage": 0.99}]
    rows = bench.per_run_safety(runs)[2:-1]
    assert rows[0] == "| lab | nearest_frontier | 0 | – / – | – | – | 2.0 | 99.0 % | – |"  # logged before
    assert rows[1].endswith("| 4.0 / 31.0 | 90 | 2.0 | 7.0 | 99.5 % | no |")  # the max over 25 cm
    assert rows[2].endswith("| 4.0 / 12.0 | 310 | 1.5 | 6.1 | 99.9 % | yes |")
