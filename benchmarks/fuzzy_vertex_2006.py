"""Chen & Zhang (2006), section 5.1, re-created: dead reckoning vs edge matching vs vertex localisation.

The paper's MATLAB simulation: 18 range beams 20 degrees apart (360 degrees),
20 m range, 5 % range error, up to 20 % motion error, start at (5, 5), equal
steps, a compass for the heading, 10 trials; mean localisation error over the
first n steps and time per step. The paper does not give its room layout (only
a figure) nor its step count, so this script uses a polygonal room of its
scale (an L-shaped hall with a box pillar, a triangular and a pentagonal
obstacle) and a route of 1 m steps from (5, 5) twice round them (149 steps).

Motion error: ``sample_odometry`` with alpha3 = alpha2 = 0.01 (std 10 % of a
step along and across the motion, so +-20 % is the 2-sigma band). With the
compass (the paper's assumption 3) the odometry heading is the true one and
each odometry step is turned by it; without it (``--no-compass``) the heading
drifts (alpha1 = 0.01, alpha2 = 0.001: 10 % of each turn, 1.8 degrees per
metre) and the methods also fit the heading.

Methods: dead reckoning; edge matching (units matched by eqs. 13-15,
translation by n-weighted least squares on the matched lines' normal offsets,
then unit fusion, as in Gasos & Rosetti's scheme the paper compares against);
vertex localisation (eqs. 6-12, the paper's translation-only offset, no
odometry prior); and the frontend's defaults for real logs (SE(2) fit, wall
directions, odometry prior, rigidity check and gate; without the compass also
the online odometry-heading calibration); and, where present, slam2d's
``lines`` frontend with options loosened for 18 beams.

    .venv/bin/python benchmarks/fuzzy_vertex_2006.py [--trials 10] [--no-compass]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from slam2d import geometry
from slam2d.config import LaserModel, OdometryNoise
from slam2d.datasets.simulator import World, beam_angles, check_route, measure_ranges, route_poses, sample_odometry
from slam2d.frontends import fuzzy_vertex as fv
from slam2d.types import Scan

START = (5.0, 5.0)
STEP = 1.0  # m, the paper's step length lambda
RANGE_ERROR = 0.05  # range noise std as a fraction of the range
LASER = LaserModel(beams=18, fov_deg=360.0, range_min=0.05, range_max=20.0, range_noise=0.0, dropout=0.0)


def paper_world() -> World:
    """An L-shaped 20 m x 16 m hall with a box, a triangle and a pentagon (rings in metres)."""
    hall = [[0, 0], [20, 0], [20, 9], [13, 9], [13, 16], [0, 16]]
    box = [[8, 3], [11, 3], [11, 6], [8, 6]]
    triangle = [[15, 2], [18, 2], [16.5, 5]]
    pentagon = [[3, 10], [6, 9.5], [7, 12], [5, 14], [2.5, 12.5]]
    return World.from_polygons([hall, box, triangle, pentagon], name="chen-zhang-2006")


def paper_route(laps: int = 2) -> np.ndarray:
    """Closed route (M, 2) from the start (5, 5) round the obstacles, about 70 m a lap."""
    lap = [
        [5, 7.5], [11, 7.5], [11, 14], [9, 14], [9, 8], [14, 7.5], [19, 7.5],
        [19, 1], [13, 1], [13, 7], [7, 7], [7, 1.5], [2, 1.5], [2, 5], START,
    ]  # fmt: skip
    return np.array([START] + lap * laps, float)


def simulate(world: World, seed: int, compass: bool):
    """Ground truth (N, 3), odometry (N, 3) and scans of one trial."""
    wp = check_route(world, paper_route())
    _, truth = route_poses(wp, speed=STEP, turn_rate=1e6, scan_rate=1.0)
    rng = np.random.default_rng(seed)
    if compass:
        motion = OdometryNoise(alpha1=0.0, alpha2=0.01, alpha3=0.01, alpha4=0.0)
    else:  # the heading random walk: 10 % of each turn, 1.8 degrees per metre
        motion = OdometryNoise(alpha1=0.01, alpha2=0.001, alpha3=0.01, alpha4=0.0)
    odom = sample_odometry(truth, motion, rng)
    if compass:  # encoder steps turned by the true heading
        steps = geometry.between(odom[:-1], odom[1:])[:, :2]
        moves = np.einsum("kij,kj->ki", geometry.rotation(truth[:-1, 2]), steps)
        xy = truth[0, :2] + np.vstack([np.zeros((1, 2)), np.cumsum(moves, axis=0)])
        odom = np.column_stack([xy, truth[:, 2]])
    angles = beam_angles(LASER)
    true_r = world.raycast_poses(truth, angles, LASER.range_max)
    noise = true_r * RANGE_ERROR * rng.standard_normal(true_r.shape)  # proportional range error
    ranges = measure_ranges(true_r, LASER, noise, np.zeros_like(true_r, bool))
    lo, hi = LASER.range_min, LASER.range_max
    return truth, odom, [
        Scan(float(k), ranges[k], angles.copy(), lo, hi, odom=odom[k], ground_truth=truth[k], index=k)
        for k in range(len(truth))
    ]


# --------------------------------------------------------------------------- methods

SPARSE = dict(  # 18 beams, 5 % range noise: wide joints (20 degrees apart), range-proportional xi
    min_range=0.05,
    max_range=20.0,
    xi=0.05,
    xi_range=0.05,
    max_gap=None,
    min_unit_points=2,
    min_unit_length=0.0,
    sigma=1.5,
    min_vertex_angle_deg=60.0,
    dead_reckoning_error=0.02,
    dead_reckoning_rel=0.1,
    min_radius=0.2,
    max_radius=2.0,
    max_correction_xy=2.0,
    max_correction_theta_deg=30.0,
    prune_after=None,
)


def vertex_paper(compass: bool) -> fv.FuzzyVertexFrontend:
    """Eqs. 6-12 as printed: translation offset V* (heading from the compass or odometry), no prior."""
    opts = dict(SPARSE, heading="translation", arm_heading=False, wall_heading=False, odometry_prior=False)
    opts.update(rigid_check=False)
    opts.update(max_arm_error_deg=None, max_mahalanobis=None, heading_lever=not compass)
    opts.update(calibration={"enabled": False})
    return fv.FuzzyVertexFrontend(fv.FuzzyVertexFrontend.Config(**opts))


def vertex_full(compass: bool) -> fv.FuzzyVertexFrontend:
    """The frontend's extensions on: SE(2) fit (translation with a compass), wall directions, prior, gate."""
    heading = "translation" if compass else "se2"
    walls = not compass  # with a compass the heading is known
    opts = dict(SPARSE, heading=heading, arm_heading=walls, wall_heading=walls, heading_lever=walls)
    opts.update(heading_error_deg=0.01 if compass else 2.0, heading_rel=0.0 if compass else 0.1)
    opts.update(calibration={"enabled": not compass})  # a compass heading needs no calibration
    return fv.FuzzyVertexFrontend(fv.FuzzyVertexFrontend.Config(**opts))


class EdgeMatching:
    """Edge (line) matching on the fuzzy unit map: the baseline of section 3."""

    def __init__(self, compass: bool):
        self.cfg = fv.FuzzyVertexFrontend.Config(**SPARSE)
        self.compass = compass
        self.map = fv.UnitMap(self.cfg.min_radius)
        self.pose = None

    def process(self, scan: Scan, odom_delta) -> np.ndarray:
        cfg = self.cfg
        pred = np.asarray(scan.odom if self.pose is None else geometry.compose(self.pose, odom_delta), float)
        delta_a = cfg.dead_reckoning_rel * float(np.hypot(*np.asarray(odom_delta)[:2]))
        points, ranges, _ = fv.scan_points(scan, cfg.min_range, cfg.max_range)
        bounds, _ = fv.twice_classification(points, cfg.xi + cfg.xi_range * ranges, cfg.max_gap)
        local = fv.fit_units(points, bounds, delta_a, cfg.min_unit_points, cfg.min_unit_length)
        pose = pred if self.pose is None else self._localise(pred, local)
        self.map.integrate(local.transformed(pose), pose)
        self.pose = pose
        return pose

    def _localise(self, pred, local: fv.Units) -> np.ndarray:
        world = local.transformed(pred)
        li, gj = fv.match_units(world, self.map.units, pred)
        if len(li) == 0:
            return pred
        g, w = self.map.units.select(gj), world.n[li]
        pose = pred.copy()
        if not self.compass:  # n-weighted mean line-angle difference
            dphi = (g.phi - world.phi[li] + np.pi / 2) % np.pi - np.pi / 2
            pose[2] = geometry.wrap_angle(pred[2] + (w * dphi).sum() / w.sum())
            world = local.transformed(pose)
        normal = np.column_stack([np.cos(g.phi), np.sin(g.phi)])
        offset = g.rho - np.einsum("ki,ki->k", normal, world.mid[li])
        a = (w[:, None, None] * normal[:, :, None] * normal[:, None, :]).sum(0) + 1e-6 * np.eye(2)
        v = np.linalg.solve(a, (w[:, None] * normal * offset[:, None]).sum(0))
        if np.hypot(*v) > self.cfg.max_correction_xy:
            return pred
        pose[:2] += v
        return pose


# slam2d's own line frontend (Tian 2016 extraction), loosened for 18 sparse beams
LINES_SPARSE = {
    "extraction": {
        "min_points": 3,
        "min_length": 0.1,
        "jump_distance": 5.0,
        "support_length": 1.0,
        "max_rms": 0.5,
        "grow_tolerance": 0.3,
    }
}


def lines_frontend(compass: bool):
    from slam2d.frontends import create_frontend
    from slam2d.frontends import lines  # noqa: F401  (registers "lines")

    return FrontendRunner(create_frontend("lines", LINES_SPARSE))


class FrontendRunner:
    """Chains a frontend's deltas from the true start pose."""

    def __init__(self, frontend):
        self.frontend, self.pose = frontend, None

    def process(self, scan: Scan, odom_delta) -> np.ndarray:
        result = self.frontend.process(scan, odom_delta)
        self.pose = np.asarray(scan.odom, float) if self.pose is None else geometry.compose(self.pose, result.delta)
        return self.pose


class DeadReckoning:
    def process(self, scan: Scan, odom_delta) -> np.ndarray:
        return np.asarray(scan.odom, float)


METHODS = {
    "dead reckoning": lambda compass: DeadReckoning(),
    "edge matching": EdgeMatching,
    "vertex localisation (paper)": lambda compass: FrontendRunner(vertex_paper(compass)),
    "vertex localisation (frontend defaults)": lambda compass: FrontendRunner(vertex_full(compass)),
}
try:  # another slam2d frontend, where present
    import slam2d.frontends.lines  # noqa: F401

    METHODS["slam2d lines frontend (sparse options)"] = lines_frontend
except ImportError:
    pass


def run_trial(method: str, truth, odom, scans, compass: bool) -> tuple[np.ndarray, float]:
    """Localisation errors (N,) in m and CPU seconds per step."""
    runner = METHODS[method](compass)
    est = np.zeros_like(truth)
    t0 = time.process_time()
    for k, scan in enumerate(scans):
        delta = np.zeros(3) if k == 0 else geometry.between(odom[k - 1], odom[k])
        est[k] = runner.process(scan, delta)
    per_step = (time.process_time() - t0) / len(scans)
    return np.hypot(*(est[:, :2] - truth[:, :2]).T), per_step


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--trials", type=int, default=10)
    ap.add_argument("--no-compass", action="store_true", help="odometry heading drifts; fit SE(2)")
    args = ap.parse_args()
    compass = not args.no_compass
    world = paper_world()
    errors = {m: [] for m in METHODS}
    times = {m: [] for m in METHODS}
    for seed in range(args.trials):
        truth, odom, scans = simulate(world, seed, compass)
        for m in METHODS:
            err, dt = run_trial(m, truth, odom, scans, compass)
            errors[m].append(err)
            times[m].append(dt)
    steps = len(errors["dead reckoning"][0]) - 1
    firsts = [n for n in (25, 50, 100) if n < steps] + [steps]
    print(f"{args.trials} trials, {steps} steps of {STEP:g} m, 18 beams, {RANGE_ERROR:.0%} range error, "
          f"{'compass' if compass else 'no compass'}; mean localisation error (m) over the first n steps, "
          "mean ± std over trials\n")
    print("| method | " + " | ".join(f"n = {n}" for n in firsts) + " | time per step (ms) |")
    print("|---|" + "---|" * len(firsts) + "---|")
    for m in METHODS:
        e = np.array(errors[m])[:, 1:]  # step 0 is the known start
        cells = [f"{e[:, :n].mean(1).mean():.3f} ± {e[:, :n].mean(1).std():.3f}" for n in firsts]
        print(f"| {m} | " + " | ".join(cells) + f" | {1000 * np.mean(times[m]):.2f} |")


if __name__ == "__main__":
    main()
