"""Map accuracy as wall-to-wall spans (the 2018 thesis' Table 5-1): the measure recovers a known scale error,
leaves unseen faces out, and a simulator run reports it."""

from __future__ import annotations

import numpy as np
import pytest

from slam2d.evaluation.map_accuracy import Span, measure_spans, span_summary
from slam2d.sim.spans import OFFICE_SPANS, random_spans, spans_of, world_spans
from slam2d.sim.world import World


@pytest.fixture(scope="module")
def office():
    return World.office()


@pytest.fixture(scope="module")
def wall_points(office):
    """Laser endpoints on every face of the office, from a 0.5 m lattice of free points (the true map)."""
    xs, ys = np.meshgrid(np.arange(0.25, 20.0, 0.5), np.arange(0.25, 12.0, 0.5))
    origins = np.column_stack([xs.ravel(), ys.ravel()])
    origins = origins[office.free(origins, 0.1)]
    angles = np.tile(np.linspace(-np.pi, np.pi, 720, endpoint=False), (len(origins), 1))
    ranges = office.raycast_many(origins, angles, 30.0)
    return (origins[:, None, :] + ranges[..., None] * np.stack([np.cos(angles), np.sin(angles)], -1)).reshape(-1, 2)


def test_the_office_spans_have_their_plan_lengths(office):
    spans = {s.name: s.length for s in world_spans(office)}
    assert len(spans) == len(OFFICE_SPANS)
    assert spans["B1 east-west"] == pytest.approx(4.9)  # wall centres 5 m apart, 0.1 m thick
    assert spans["west lobby north-south"] == pytest.approx(5.1)
    assert spans["south corridor, end to end"] == pytest.approx(19.9)


def test_the_true_map_measures_its_spans(office, wall_points):
    spans = world_spans(office)
    errors = measure_spans(wall_points, spans) - [s.length for s in spans]
    assert np.abs(errors).max() < 1e-3


@pytest.mark.parametrize("scale", [0.98, 1.01, 1.02])
def test_a_scale_error_is_recovered_span_by_span(office, wall_points, scale):
    spans = world_spans(office)
    centre = np.array([10.0, 6.0])
    measured = measure_spans(centre + scale * (wall_points - centre), spans)
    lengths = np.array([s.length for s in spans])
    assert measured == pytest.approx(scale * lengths, abs=2e-3)
    summary = span_summary(spans, measured)
    assert summary["seen"] == len(spans)
    assert summary["mean_error_m"] == pytest.approx((scale - 1) * lengths.mean(), abs=1e-3)


def test_a_face_missing_from_the_map_leaves_its_span_out(office, wall_points):
    spans = world_spans(office)
    b1 = next(s for s in spans if s.name == "B1 east-west")
    keep = ~((wall_points[:, 0] < 0.2) & (wall_points[:, 1] < 3.4))  # B1's west wall unseen
    measured = measure_spans(wall_points[keep], spans)
    assert np.isnan(measured[spans.index(b1)])
    assert span_summary(spans, measured)["seen"] == len(spans) - 1


def test_the_far_face_of_a_wall_is_not_taken_for_the_near_one():
    span = Span("room", (2.0, 0.0), (1.0, 0.0), 2.0, 2.0)
    near = np.column_stack([np.full(20, 4.0), np.linspace(-0.1, 0.1, 20)])
    far = near + [0.1, 0.0]  # the same wall's other side, seen from the next room
    left = np.column_stack([np.zeros(20), np.linspace(-0.1, 0.1, 20)])
    assert measure_spans(np.vstack([left, far, near]), [span])[0] == pytest.approx(4.0)


def test_floor_plans_get_seeded_spans_across_their_rooms(data_file):
    world = World.from_png(data_file("rooms/office_a.png"))
    spans = random_spans(world, 8, seed=3)
    assert len(spans) == 8 and all(s.length >= 1.5 for s in spans)
    assert [s.origin for s in spans] == [s.origin for s in random_spans(world, 8, seed=3)]
    assert spans_of(world, seed=3) != spans_of(world, seed=4)
