"""Line frontend: extraction, TLS, the line map, matching, grid lines, and a run on the simulator."""

import numpy as np
import pytest

from slam2d import config, geometry
from slam2d.datasets.registry import open_dataset
from slam2d.datasets.simulator import World
from slam2d.evaluation.trajectory import ate
from slam2d.frontends.lines import (
    LineExtractionConfig,
    LineFrontend,
    LineMatchConfig,
    SegmentMap,
    Segments,
    extract_lines,
    fit_line,
    lines_from_grid,
    match_lines,
)
from slam2d.frontends.odometry import odometry_information
from slam2d.pipeline import SlamPipeline
from slam2d.types import Scan

BEAMS = np.linspace(-np.pi, np.pi, 360, endpoint=False)


def scan_of(world: World, pose, noise: float = 0.0, seed: int = 0):
    """Hit ranges and beam angles (sensor = base frame) of a 360-beam, 12 m scan from ``pose``."""
    r = world.raycast(pose[:2], BEAMS + pose[2], 12.0)
    r = r + noise * np.random.default_rng(seed).standard_normal(len(r))
    hit = r < 11.9
    return r[hit], BEAMS[hit]


def segments_at(world, pose, noise=0.0, seed=0, **extraction):
    r, a = scan_of(world, pose, noise, seed)
    return extract_lines(r, a, LineExtractionConfig(**extraction))


def room():
    """6 m x 4 m room, walls as segments."""
    c = np.array([[0, 0], [6, 0], [6, 4], [0, 4]], float)
    return World(np.stack([c, np.roll(c, -1, axis=0)], axis=1))


@pytest.mark.parametrize("method", ["angle", "split_merge"])
@pytest.mark.parametrize("noise", [0.0, 0.01])
def test_l_shaped_scan_gives_two_segments_meeting_at_the_corner(method, noise):
    world = World(np.array([[[0, 0], [4, 0]], [[4, 0], [4, 3]]], float))
    pose = np.array([1.5, 1.2, 0.3])
    ext = segments_at(world, pose, noise, method=method)
    segs = ext.segments.transformed(pose)
    assert len(segs) == 2
    order = np.argsort(np.abs(segs.normal[:, 0]))  # the wall y = 0 first, then x = 4
    segs = segs.subset(order)
    # normals face the robot: +y for the wall y = 0, -x for the wall x = 4
    assert np.degrees(segs.alpha) == pytest.approx([90.0, 180.0], abs=0.1 + 20 * noise)
    assert np.abs(segs.offset - [0.0, -4.0]).max() < 0.002 + 0.3 * noise
    # the two lines meet at the corner, and each segment reaches it
    corner = np.linalg.solve(segs.normal, segs.offset)
    assert np.linalg.norm(corner - [4.0, 0.0]) < 0.002 + 0.5 * noise
    reach = np.linalg.norm(segs.ends - np.array([4.0, 0.0]), axis=2).min(axis=1)
    assert reach.max() < 0.05
    # the turning-angle peak marks the corner
    peaks = geometry.transform_points(pose, ext.points[ext.corners])
    assert np.linalg.norm(peaks - [4.0, 0.0], axis=1).min() < 0.05


def test_segments_split_at_range_jumps():
    # a near wall in front of a far wall: the far wall splits into two chains around it
    world = World(np.array([[[-1, 1], [1, 1]], [[-6, 3], [6, 3]]], float))
    ext = segments_at(world, np.array([0.0, 0.0, 0.0]))
    segs = ext.segments
    assert sorted(np.round(np.abs(segs.offset), 3)) == [1.0, 3.0, 3.0]  # far wall seen on both sides of the near one
    assert len(np.unique(ext.chain[ext.spans[:, 0]])) == 3


def test_short_segments_are_dropped():
    world = World(np.array([[[2, -0.1], [2, 0.1]], [[-2, 2], [2, 2]]], float))  # 0.2 m and 4 m long
    segs = segments_at(world, np.zeros(3), min_length=0.3).segments
    assert len(segs) == 1 and segs.offset[0] == pytest.approx(-2.0, abs=1e-6)


def test_tls_fit_is_exact_on_collinear_points():
    t = np.linspace(-3, 5, 17)
    points = np.column_stack([t, 0.5 * t + 1.0])
    centroid, normal, rms = fit_line(points)
    assert rms < 1e-12
    assert abs(normal @ np.array([1.0, 0.5])) < 1e-12  # normal is perpendicular to the line direction
    assert centroid[1] == pytest.approx(0.5 * centroid[0] + 1.0, abs=1e-12)
    assert np.allclose(np.abs(points @ normal - centroid @ normal), 0.0, atol=1e-12)


def test_segment_map_extends_a_reobserved_line():
    lines = SegmentMap()
    lines.add(Segments.from_ends([[[0.0, 0.0], [2.0, 0.0]]]), index=0)
    lines.merge(np.array([0]), Segments.from_ends([[[1.5, 0.0], [4.0, 0.0]]]), index=1)
    assert len(lines) == 1 and lines.seen[0] == 2
    x = lines.lines.ends[0, :, 0]
    assert x.min() == pytest.approx(0.0) and x.max() == pytest.approx(4.0)
    assert np.abs(lines.lines.ends[0, :, 1]).max() < 1e-12
    assert lines.lines.count[0] == pytest.approx(40.0 + 50.0)


def test_line_matching_recovers_a_known_offset_and_reports_matched_length():
    world = room()
    a, b = np.array([2.5, 1.8, 0.2]), np.array([2.8, 2.0, 0.25])
    reference = segments_at(world, a, 0.005, seed=1).segments.transformed(a)
    north = np.argmax(reference.centroid[:, 1])
    map_lines = reference.subset(np.arange(len(reference)) != north)  # the map lacks the north wall
    obs = segments_at(world, b, 0.005, seed=2).segments
    guess = geometry.compose(b, [0.06, -0.04, np.deg2rad(1.5)])
    match = match_lines(obs, map_lines, guess, odometry_information(0.05, 2.0), LineMatchConfig())
    err = geometry.between(b, match.pose)
    assert np.hypot(err[0], err[1]) < 0.005 and abs(err[2]) < np.deg2rad(0.1)
    unmatched = match.matched < 0
    assert unmatched.sum() == 1
    assert geometry.transform_points(b, obs.centroid[unmatched])[0, 1] == pytest.approx(4.0, abs=0.01)
    length = obs.length
    assert match.confidence == pytest.approx(length[~unmatched].sum() / length.sum(), rel=1e-12)
    assert 0.5 < match.confidence < 1.0


def test_corridor_information_is_small_along_the_corridor():
    world = World(np.array([[[-20, 0], [20, 0]], [[-20, 2], [20, 2]]], float))
    a, b = np.array([0.0, 1.0, 0.0]), np.array([0.4, 1.05, 0.02])
    map_lines = segments_at(world, a).segments.transformed(a)
    obs = segments_at(world, b).segments
    match = match_lines(obs, map_lines, geometry.compose(b, [0.0, 0.03, 0.01]), odometry_information(0.05, 2.0))
    vals, vecs = np.linalg.eigh(match.information[:2, :2])
    assert vals[0] < 1e-6 * vals[1]
    along = geometry.rotation(b[2]).T @ np.array([1.0, 0.0])  # the corridor axis in the base frame
    assert abs(vecs[:, 0] @ along) > 0.999
    err = geometry.between(b, match.pose)
    assert abs(err[1]) < 0.002 and abs(err[2]) < np.deg2rad(0.05)  # across and heading are recovered


def test_lines_from_an_occupancy_grid_face_the_free_side():
    res = 0.05
    grid = np.ones((80, 120), bool)  # 6 m x 4 m, walls all around a free room
    grid[10:70, 10:110] = False
    segs = lines_from_grid(grid, res, origin=(-1.0, 2.0))
    # room interior in metres: x in [-0.5, 4.5], y in [2.5, 5.5]; the four walls each yield a line
    for offset, normal in [((-0.5, 0), (1, 0)), ((4.5, 0), (-1, 0)), ((0, 2.5), (0, 1)), ((0, 5.5), (0, -1))]:
        n = np.array(normal, float)
        wall = np.abs(segs.normal @ n - 1) < 1e-3
        assert wall.any(), normal
        dist = np.abs(segs.centroid[wall] @ n - np.array(offset) @ n)
        assert dist.min() < 2 * res
    frontend = LineFrontend()
    assert frontend.reanchor(grid, res, (-1.0, 2.0)) == len(frontend.map) > 0
    assert (frontend.map.seen >= frontend.config.min_seen).all()


def test_unknown_option_is_rejected():
    from slam2d.errors import InputError
    from slam2d.frontends.base import create_frontend

    with pytest.raises(InputError, match="frontend.options.extraction.min_lenght"):
        create_frontend("lines", {"extraction": {"min_lenght": 1.0}})


def test_lines_frontend_beats_odometry_on_the_simulator():
    cfg = config.load(None, ["dataset.max_scans=200", "frontend.name=lines"])
    result = SlamPipeline(cfg).run(open_dataset(cfg.dataset))
    est = ate(result.poses, result.ground_truth)["rmse"]
    odo = ate(result.odometry, result.ground_truth)["rmse"]
    assert est < 0.5 * odo, (est, odo)
    assert np.mean(result.confidences > 0.5) > 0.8


def test_standing_still_among_a_few_short_segments_stays_put():
    # three short wall pieces 3-4 m away, 180 one-degree beams, 1.5 cm range noise, the robot not moving
    pieces = np.array([[[3.0, -0.3], [3.0, 0.4]], [[-0.2, 3.5], [0.5, 3.5]], [[-3.2, -0.8], [-3.2, -0.1]]])
    world = World(pieces)
    beams = np.deg2rad(np.arange(-90.0, 270.0, 1.0))
    pose = np.array([0.1, 0.2, 0.3])

    def drift(options):
        fe = LineFrontend(LineFrontend.Config(**options))
        est = np.zeros(3)
        worst = np.zeros(3)
        for k in range(40):
            r = world.raycast(pose[:2], beams + pose[2], 12.0)
            r = r + 0.015 * np.random.default_rng(k).standard_normal(len(r))
            r = np.where(r < 11.9, r, np.nan)
            scan = Scan(stamp=0.2 * k, ranges=r, angles=beams, range_min=0.05, range_max=12.0, index=k)
            est = geometry.compose(est, fe.process(scan, np.zeros(3)).delta)
            worst = np.maximum(worst, np.abs(est))
        return worst

    still = drift({})
    assert np.hypot(still[0], still[1]) < 0.025 and still[2] < np.deg2rad(0.5), still
    loose = drift({"odom_sigma_xy": 0.05, "odom_sigma_theta_deg": 2.0})  # the earlier, loose odometry prior
    assert loose[2] > 2.0 * still[2], (loose, still)  # the heading wandered with the segments' noise
