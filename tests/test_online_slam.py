"""OnlineSlam: the batch pipeline's frontend and pose graph fed one scan at a time, with a live grid."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pytest

from slam2d import config, geometry
from slam2d.datasets.registry import open_dataset
from slam2d.errors import InputError
from slam2d.mapping.occupancy import OccupancyGrid, beam_segments, build_grid, logit
from slam2d.pipeline import SlamPipeline
from slam2d.slam import GridUpdate, KeyframeGrid, OnlineSlam

SCANS = 600


def common_lattice(grid: OccupancyGrid, ref: OccupancyGrid) -> tuple[np.ndarray, np.ndarray]:
    """The two grids' log-odds on one lattice covering both (0, unknown, outside either)."""
    res = ref.resolution
    corners = [np.round(np.array(g.origin[::-1]) / res).astype(int) for g in (grid, ref)]
    lo = np.minimum(*corners)
    hi = np.maximum(corners[0] + grid.shape, corners[1] + ref.shape)
    out = []
    for g, c in zip((grid, ref), corners):
        a = np.zeros(hi - lo, np.float32)
        r, k = c - lo
        a[r : r + g.shape[0], k : k + g.shape[1]] = g.log_odds
        out.append(a)
    return out[0], out[1]


def classes(log_odds: np.ndarray) -> np.ndarray:
    """Per cell 1 occupied, -1 free, 0 neither (the default map_server thresholds)."""
    mapping = config.MappingConfig()
    occupied, free = logit(mapping.occupied_thresh), logit(mapping.free_thresh)
    return np.where(log_odds > occupied, 1, np.where(log_odds < free, -1, 0))


def agreement(grid: OccupancyGrid, ref: OccupancyGrid) -> float:
    """Fraction of the cells ``ref`` classifies as occupied or free that ``grid`` classifies the same."""
    a, b = (classes(g) for g in common_lattice(grid, ref))
    known = b != 0
    return float(np.mean(a[known] == b[known]))


def same_log_odds(grid: OccupancyGrid, ref: OccupancyGrid) -> float:
    """Fraction of the cells known in either grid whose log-odds agree to 1e-5."""
    a, b = common_lattice(grid, ref)
    known = (a != 0) | (b != 0)
    return float(np.mean(np.abs(a - b)[known] < 1e-5))


@dataclass
class LoopEvent:
    """The state right after a scan whose keyframe added loop closures."""

    update: GridUpdate
    expected_replaced: int
    beams_so_far: int
    keyframes: int
    vs_current: float  # agreement with build_grid at the current estimates
    vs_placed: float  # agreement with build_grid at the poses the keyframes were traced at


@dataclass
class Session:
    cfg: config.ExperimentConfig
    online: OnlineSlam
    poses: np.ndarray  # finish()
    pose_gap: list[float] = field(default_factory=list)  # |pose - back end's estimate of the scan| per scan
    errors: list[float] = field(default_factory=list)  # |pose - ground truth| per scan, m
    loops: list[LoopEvent] = field(default_factory=list)


def usable_beams(scans, cfg) -> int:
    return len(beam_segments(np.zeros((len(scans), 3)), scans, cfg.mapping)[1])


def loop_event(online: OnlineSlam, placed_before: np.ndarray, closed_before: int, beams: int) -> LoopEvent:
    """Check the grid against full rebuilds; count the keyframes that moved beyond the tolerance."""
    grid_map = online.map
    estimate = online.backend.graph.estimate()
    shift = np.hypot(*(estimate[:closed_before, :2] - placed_before[:closed_before, :2]).T)
    turn = np.abs(geometry.wrap_angle(estimate[:closed_before, 2] - placed_before[:closed_before, 2]))
    moved = shift + grid_map._reach[:closed_before] * turn > grid_map.tolerance
    update = grid_map.last
    grid = online.grid
    keys, offsets = online.backend.scan_anchors()
    at_placed = geometry.compose(grid_map.placed_poses()[keys], offsets)
    cfg = online.cfg.mapping
    return LoopEvent(update, int(np.count_nonzero(moved)), beams, len(estimate),
                     agreement(grid, build_grid(online.poses, online.scans, cfg)),
                     agreement(grid, build_grid(at_placed, online.scans, cfg)))  # fmt: skip


@pytest.fixture(scope="module")
def session() -> Session:
    """The first SCANS scans of the simulator default, fed one at a time; checks after every scan."""
    cfg = config.load(None, ["parallel=false", f"dataset.max_scans={SCANS}"])
    online = OnlineSlam(cfg)
    out = Session(cfg, online, np.zeros(0))
    beams = 0
    for scan in open_dataset(cfg.dataset, seed=cfg.seed):
        loops = online.backend.stats["loop closures added"]
        placed, closed = online.map.placed_poses(), online.backend.graph.num_keyframes - 1
        online.add(scan)
        beams += usable_beams([scan], cfg)
        pose = online.pose
        key, offset = online.backend.scan_anchors(scan.index)
        estimate = geometry.compose(online.backend.graph.estimate()[key[0]], offset[0])
        out.pose_gap.append(float(np.abs(geometry.between(estimate, pose)).max()))
        out.errors.append(float(np.hypot(*(pose[:2] - scan.ground_truth[:2]))))
        if online.backend.stats["loop closures added"] > loops:
            out.loops.append(loop_event(online, placed, closed, beams))
    out.poses = online.finish()
    return out


def test_online_session_ends_with_the_batch_pipeline_poses(session):
    batch = SlamPipeline(session.cfg).run(open_dataset(session.cfg.dataset, seed=session.cfg.seed))
    assert batch.stats["loop closures added"] > 0
    assert session.poses.shape == batch.poses.shape == (SCANS, 3)
    assert np.allclose(session.poses, batch.poses, rtol=0, atol=1e-9)
    assert session.online.backend.summary() == {k: v for k, v in batch.stats.items() if not k.startswith("frontend ")}


def test_pose_is_the_back_end_estimate_and_near_ground_truth(session):
    assert max(session.pose_gap) < 1e-9
    errors = np.array(session.errors)
    assert np.median(errors) < 0.02, np.median(errors)  # 4.5 mm
    assert errors.max() < 0.1, errors.max()  # 2.7 cm
    online = session.online
    keys, offsets = online.backend.scan_anchors()
    assert np.allclose(online.poses[-1], geometry.compose(online.backend.graph.pose(keys[-1]), offsets[-1]))


def test_grid_after_loop_closures_matches_a_rebuild(session):
    assert len(session.loops) >= 3
    for event in session.loops:
        assert event.vs_current >= 0.99, event
        assert event.vs_placed >= 0.998, event  # only the tolerance separates it from the rebuild


def test_grid_after_finish_matches_a_rebuild(session):
    online = session.online
    assert agreement(online.grid, build_grid(session.poses, online.scans, session.cfg.mapping)) >= 0.99


def test_re_render_traces_only_the_keyframes_that_moved(session):
    events = session.loops
    for event in events:
        assert event.update.replaced == event.expected_replaced, event
        assert event.update.placed <= 1
    moving = [e for e in events if e.update.replaced > 0]
    assert moving, "no loop closure moved a keyframe beyond the tolerance"
    for event in moving:
        assert event.update.replaced < event.keyframes - 1
        assert event.update.beams < event.beams_so_far, event  # a full rebuild traces beams_so_far
    traced, rebuild = sum(e.update.beams for e in events), sum(e.beams_so_far for e in events)
    assert traced < 0.5 * rebuild, (traced, rebuild)


def test_keyframe_grid_is_build_grid_when_each_keyframe_is_one_scan():
    """One scan a keyframe: the patches folded in order clamp as build_grid does (but for a rare
    cell boundary crossed differently in floating point, as the grids' origins differ)."""
    cfg = config.load(None, ["dataset.max_scans=40"])
    scans = list(open_dataset(cfg.dataset, seed=cfg.seed))
    poses = np.array([s.ground_truth for s in scans])
    grid = KeyframeGrid(cfg.mapping)
    for k, scan in enumerate(scans):
        grid.add_scan(k, np.zeros(3), scan)
    first = grid.update(poses)
    assert (first.placed, first.replaced) == (len(scans), 0)
    assert same_log_odds(grid.grid(), build_grid(poses, scans, cfg.mapping)) > 0.9995
    moved = poses.copy()
    moved[10:20, 0] += 0.3  # ten keyframes moved by 0.3 m
    update = grid.update(moved)
    assert (update.placed, update.replaced) == (0, 10)
    assert same_log_odds(grid.grid(), build_grid(moved, scans, cfg.mapping)) > 0.9995
    moved[30:33, 1] += 40.0  # beyond the grid: it grows
    assert grid.update(moved).replaced == 3
    assert same_log_odds(grid.grid(), build_grid(moved, scans, cfg.mapping)) > 0.9995
    assert grid.update(moved + 0.2 * grid.tolerance * np.array([1, 0, 0])).replaced == 0


def test_online_needs_the_pose_graph_back_end():
    with pytest.raises(InputError, match="backend.name"):
        OnlineSlam(config.load(None, ["backend.name=none"]))


def test_grid_takes_every_nth_scan_as_build_grid_does():
    cfg = config.load(None, ["parallel=false", "dataset.max_scans=120", "mapping.every_nth_scan=3"])
    online = OnlineSlam(cfg)
    for scan in open_dataset(cfg.dataset, seed=cfg.seed):
        online.add(scan)
    keys, offsets = online.backend.scan_anchors()
    grid = online.grid
    at_placed = np.nan_to_num(geometry.compose(online.map.placed_poses()[keys], offsets))  # NaN: no scan taken
    assert same_log_odds(grid, build_grid(at_placed, online.scans, cfg.mapping)) > 0.99
    assert agreement(grid, build_grid(online.poses, online.scans, cfg.mapping)) >= 0.99


def test_an_estimate_corrupted_by_a_false_match_is_detected_and_brought_back():
    """A false scan match (one frontend result off by 0.5 m, 0.3 m, 0.1 rad) throws the online estimate 0.58 m
    off; the next scans, matched to the local map from before it, and the loop closures bring it back within
    5 cm in 3 s (30 scans), and it stays there."""
    from dataclasses import replace

    cfg = config.load(None, ["parallel=false", "dataset.max_scans=400"])
    online = OnlineSlam(cfg)
    process, offset, corrupt_at = online.frontend.process, np.array([0.5, 0.3, 0.1]), 300

    def corrupted(scan, delta):
        result = process(scan, delta)
        if scan.index == corrupt_at:
            result = replace(result, delta=geometry.compose(result.delta, offset))
            online.frontend.pose = geometry.compose(online.frontend.pose, offset)
        return result

    online.frontend.process = corrupted
    errors = []
    for scan in open_dataset(cfg.dataset, seed=cfg.seed):
        online.add(scan)
        errors.append(float(np.hypot(*(online.pose[:2] - scan.ground_truth[:2]))))
    errors = np.array(errors)
    assert errors[:corrupt_at].max() < 0.05 and errors[corrupt_at] > 0.4  # corrupted ...
    assert errors[corrupt_at + 30:].max() < 0.05  # ... and corrected
