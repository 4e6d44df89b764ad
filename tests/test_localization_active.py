"""Active localisation after a kidnapping: the robot drives, while the filter is ambiguous after the
jump, towards the places that tell its hypotheses apart (scenario.active_run with kidnap times)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from slam2d.localization import KnownMap, MclConfig, ParticleFilter
from slam2d.localization.scenario import (
    PERIOD,
    active_run,
    converged_at,
    replay,
    wander,
)
from slam2d.sim import World


def test_active_run_is_the_wanderers_stream_until_the_kidnap_and_the_same_jump():
    world = World.office()
    known = KnownMap.from_world(world)
    passive = wander(world, known, 8.0, seed=2, kidnap_at=[5.0])
    pf = ParticleFilter(known, MclConfig(), 12.0, seed=2)
    pf.init_pose(passive.truth[0], 0.1, math.radians(3.0))
    stream, track = active_run(world, known, pf, 8.0, seed=2, kidnap_at=[5.0])
    k = passive.kidnaps[0]
    assert stream.kidnaps == [k] and k == round(5.0 / PERIOD)
    assert track.tracking()[:k].all()  # the filter tracks, so the robot wanders as without it
    np.testing.assert_allclose(stream.truth[:k + 1], passive.truth[:k + 1])  # the teleport lands alike
    assert np.hypot(*(stream.truth[k, :2] - stream.truth[k - 1, :2])) >= 5.0
    assert stream.travelled[k] == stream.travelled[k - 1]  # a teleport is no travel


def test_active_moves_after_a_kidnap_recover_where_the_wandering_robot_stays_ambiguous(wings_plan):
    """The wings, kidnap seed 6: after the jump the filter holds the true wing and the other one, which
    it cannot tell apart while the robot wanders (ambiguous 20 s on); driving to where their predicted
    scans differ, it tracks at the truth within 15 s of the jump and never claims a wrong place."""
    from slam2d.sim.world import load_world

    world, known = load_world(str(wings_plan)), KnownMap.load(wings_plan)
    passive = wander(world, known, 30.0, 6, kidnap_at=[10.0])
    outcomes = {}
    for name in ("passive", "active"):
        pf = ParticleFilter(known, MclConfig(), 12.0, seed=6)
        pf.init_pose(passive.truth[0], 0.1, math.radians(3.0))
        if name == "active":
            stream, track = active_run(world, known, pf, 30.0, 6, kidnap_at=[10.0])
        else:
            stream, track = passive, replay(pf, passive)
        k = stream.kidnaps[0]
        assert not (track.tracking() & (track.position_error > 0.5))[k + 10:].any(), name
        c = converged_at(track, k)
        outcomes[name] = None if c is None else (c - k) * PERIOD
    assert outcomes["passive"] is None or outcomes["passive"] > 15.0
    assert outcomes["active"] is not None and outcomes["active"] <= 15.0


def test_the_way_to_a_goal_does_not_lead_through_a_gap_the_robot_does_not_fit():
    """A gap narrower than the lane the robot keeps clear is no way (lab_b's kidnap seed 4 turned in front
    of one for 15 s, the way leading into it and the laser refusing it); a wider one is."""
    from slam2d.localization.active import way_to

    for gap, passable in ((0.5, False), (1.0, True)):
        occupied = np.zeros((60, 100), dtype=bool)
        occupied[[0, -1], :] = occupied[:, [0, -1]] = True
        occupied[:, 50] = True
        occupied[20:20 + round(gap / 0.05), 50] = False  # the only gap in the wall, from y = 1 m
        known = KnownMap(occupied, ~occupied, 0.05, (0.0, 0.0))
        field = way_to(known, np.array([4.0, 1.5]))
        assert np.isfinite(field[30, 20]) == passable, gap  # from (1.0, 1.5) on the other side


def test_the_disambiguating_goal_is_near_by_the_way_the_robot_drives_not_through_a_wall(data_file, two_place_filter):
    """lab_a, active kidnap seed 4, 15.7 s after the start: the filter holds the room 8.2 m east of the
    true one (80 %) and the true one; inside them the scans are alike (0.02-0.04 nat an update), the
    rooms beside them and the corridor outside their doors differ. Measured straight, the nearest decisive
    place was in the next room, 2-3 m off through the wall but 9 m by the door; the robot drove 10 s
    through its own room, where the hypotheses look alike, and the kidnap was recovered too late. The
    goal is the nearest by the way: the corridor by the door, and its distance is that way."""
    from slam2d.localization.active import disambiguating_goal, way_length

    known = KnownMap.load(data_file("rooms/lab_a_scan_furnitures.png"))
    best, truth = np.array([25.84, 33.2, -0.44]), np.array([17.65, 33.19, -0.45])
    pf = two_place_filter(known, [(best, 400), (truth, 100)])
    way = way_length(known, pf.estimate.pose)
    for seed in range(3):
        goal = disambiguating_goal(pf, seed=seed)
        assert goal is not None and goal.separation >= 1.0
        cell = known.world_to_cell(goal.pose[None, :2])[0]
        assert goal.distance == pytest.approx(way[cell[0], cell[1]])
        assert goal.distance < 7.0, goal  # through the next room: 9 m
        assert goal.pose[1] < 29.3  # in the corridor, south of the rooms' wall


def test_the_evidence_a_scan_adds_is_given_per_contender(wings_plan, two_place_filter):
    """The U plan's west wing held by three hypotheses (the truth, the east wing's copy, the east wing turned
    by a half turn 8 m south): per contender, the evidence one scan adds against it (``gains``: what the
    trace of office_c's active moves reads), whose mean weighted by the contenders is ``separation``; at the
    far end of the wing none against the east wing's copy, some against the turned one."""
    from slam2d.localization.active import gains, separation

    known = KnownMap.load(wings_plan)
    truth = np.array([7.7, 17.0, -np.pi / 2])
    pf = two_place_filter(known, [(truth, 300), (truth + [17.5, 0.0, 0.0], 200),
                                  (truth + [17.5, -8.0, np.pi], 100)])  # fmt: skip
    goals = np.array([truth, truth + [0.0, -8.0, 0.0]])  # here; in sight of the joining corridor
    gain, weights, free = gains(pf, goals)
    assert gain.shape == (2, 2) and np.allclose(weights, [1 / 3, 1 / 6], atol=0.02) and free.all()
    hyps = pf.estimate.hypotheses
    copy = 0 if abs(hyps[1].pose[2] - truth[2]) < 0.5 else 1  # the row of the copy not turned
    assert gain[copy, 0] < 0.05 < gain[1 - copy, 0]
    assert gain[copy, 1] > 0.5  # the joining corridor tells the wings apart
    sep, _ = separation(pf, goals)
    assert np.allclose(sep, weights @ np.minimum(gain, pf.evidence_threshold) / weights.sum())
