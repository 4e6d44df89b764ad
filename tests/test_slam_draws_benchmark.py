"""benchmarks/slam_draws.py's table: every draw, the median and the draws that beat Cartographer, per log."""

from __future__ import annotations

import pytest
from conftest import load_benchmark


def test_the_draws_table_counts_the_draws_below_cartographer():
    bench = load_benchmark("slam_draws")
    rows = bench.table({"csail": [1.10293, 0.02739, 0.02715, 1.05073], "aces": [0.03553, 0.0356, 0.03644, 0.03585]})
    csail = next(line for line in rows.splitlines() if line.startswith("| csail"))
    aces = next(line for line in rows.splitlines() if line.startswith("| aces"))
    assert "| 0.53906 |" in csail and "2 of 4 (< 0.0319)" in csail
    assert "| 0.03572 |" in aces and "4 of 4 (< 0.0375)" in aces
    assert rows.splitlines()[0].count("draw ") == 4
    assert "| draw 4 | draw 5 |" in bench.table({"aces": [0.0355, 0.0356]}, first=4).splitlines()[0]


def test_an_unknown_log_is_refused_by_name(capsys):
    with pytest.raises(SystemExit):
        load_benchmark("slam_draws").main(["intel", "kitti"])
    assert "unknown logs: kitti" in capsys.readouterr().err
