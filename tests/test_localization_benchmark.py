"""The localisation benchmark's counting (benchmarks/localization.py): a run that is no success and ends
ambiguous at a look-alike place of the map's analysis, the true pose held by a hypothesis, is counted apart;
every other failure counts."""

from conftest import load_benchmark


def _bench():
    return load_benchmark("localization")


def _row(world, scenario, ok, end, lookalikes, false=False, seen=0, rank=0):
    key = "recovered" if "kidnap" in scenario else "converged"
    return {"world": world, "scenario": scenario, "filter": "slam2d", "seed": 0, key: ok, "end_state": end,
            "lookalikes_at_end": lookalikes, "seen_alike_at_end": seen, "truth_rank": rank, "false": false}  # fmt: skip


ROWS = [
    _row("ring", "active", False, "ambiguous", 3),  # apart: ambiguous where the analysis finds look-alikes
    _row("ring", "active", False, "ambiguous", 0),  # a failure: ambiguous where the analysis finds none
    _row("plan", "active", False, "tracking", 2),  # a failure: tracking, too late
    _row("plan", "active", False, "ambiguous", 2, rank=None),  # a failure: no hypothesis holds the true pose
    _row("plan", "active", True, "ambiguous", 2),  # a success that ends ambiguous: a success
    _row("plan", "active", True, "tracking", 0),
    _row("plan", "active_kidnap", False, "lost", 1),  # a failure: lost
    _row("plan", "active_kidnap", False, "ambiguous", 1),  # apart
    _row("plan", "active_kidnap", True, "tracking", 0, false=True),
    _row("plan", "active_kidnap", False, "ambiguous", 0, seen=2),  # apart only by what the laser sees
]  # fmt: skip


def test_only_failures_ending_ambiguous_at_a_look_alike_are_counted_apart():
    bench = _bench()
    active = [r for r in ROWS if r["scenario"] == "active"]
    assert bench.apart(active, "converged") == (2, 6, 1)
    kidnap = [r for r in ROWS if r["scenario"] == "active_kidnap"]
    assert bench.apart(kidnap, "recovered") == (1, 4, 2)
    assert bench.apart(kidnap, "recovered", seen=False) == (1, 4, 1)
    lines = bench.counting(ROWS).splitlines()
    assert "| all | slam2d | active | 2 / 6 (33.3 %) | 1 / 1 | 2 / 5 (40.0 %) | 2 / 5 (40.0 %) | 3 | 0 |" in lines
    assert ("| all | slam2d | active_kidnap | 1 / 4 (25.0 %) | 1 / 2 | 1 / 3 (33.3 %) | 1 / 2 (50.0 %) | 1 | 1 |"
            in lines)  # fmt: skip
    assert "| ring | slam2d | active | 0 / 2 (0.0 %) | 1 / 1 | 0 / 1 (0.0 %) | 0 / 1 (0.0 %) | 1 | 0 |" in lines
    assert not any("| global |" in line for line in lines)  # no rows, no line
