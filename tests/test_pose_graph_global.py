"""Batch optimisation of g2o graphs from a global start: chordal initialisation exact on
a noise-free graph, the MIT benchmark at its best-known minimum from the default start,
GNC rejecting injected false loops where plain LM fails, pc_dcs rejecting random false
loops where DCS fails, pairwise consistency through the odometry, every loop edge classified."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import sparse

from slam2d import geometry
from slam2d.backend import certificate, consistency
from slam2d.backend import initialization as ini
from slam2d.backend.batch import loop_metrics, solve_g2o
from slam2d.backend.consistency import CHI2_3DOF_99
from slam2d.backend.factors import (
    elimination_order,
    factor_graph,
    g2o_factor_list,
    g2o_factors,
    g2o_values,
)
from slam2d.backend.sparse import SymmetricFactor
from slam2d.datasets.g2o import PoseGraphFile, inject_outliers, odometry_mask, read_g2o
from slam2d.errors import InputError

MIT_OPTIMUM = 20.603474  # best-known GTSAM error of MIT.g2o (prior on vertex 0 excluded)
INFO = np.diag([400.0, 400.0, 2500.0])  # 1/m^2, 1/m^2, 1/rad^2: sigmas 5 cm, 5 cm, 1.1 deg


def laps(side: int = 5, n_laps: int = 3) -> np.ndarray:
    """Ground truth (4 side n_laps + 1, 3): every metre around a side x side square, n_laps times."""
    lap = []
    for s in range(4):
        corner = np.array([[0, 0], [side, 0], [side, side], [0, side]][s], dtype=float)
        direction = np.array([np.cos(s * np.pi / 2), np.sin(s * np.pi / 2)])
        lap += [[*(corner + t * direction), s * np.pi / 2] for t in range(side)]
    poses = np.array(lap * n_laps + [[0.0, 0.0, 0.0]])
    poses[:, 2] = geometry.wrap_angle(poses[:, 2])
    return poses


def lap_graph(truth: np.ndarray, noise: float, seed: int = 0, start=None) -> PoseGraphFile:
    """Odometry k -> k+1 and a loop from every pose to the same place one lap earlier;
    measurements perturbed by ``noise`` times the INFO sigmas; vertices at dead reckoning
    (or ``start``)."""
    n, per_lap = len(truth), 4 * 5
    i = np.r_[np.arange(n - 1), np.arange(per_lap, n)]
    j = np.r_[np.arange(1, n), np.arange(per_lap, n) - per_lap]
    rng = np.random.default_rng(seed)
    noise_xyt = rng.normal(size=(len(i), 3)) * noise / np.sqrt(np.diag(INFO))
    meas = geometry.compose(geometry.between(truth[i], truth[j]), noise_xyt)
    poses = [truth[0]]
    for d in meas[: n - 1]:
        poses.append(geometry.compose(poses[-1], d))
    poses = np.array(poses) if start is None else start
    return PoseGraphFile(np.arange(n), poses, i, j, meas, np.repeat(INFO[None], len(i), 0))


def pose_error(a, b) -> float:
    """Largest position (m) or wrapped heading (rad) difference."""
    d = np.asarray(a) - np.asarray(b)
    return float(max(np.abs(d[:, :2]).max(), np.abs(geometry.wrap_angle(d[:, 2])).max()))


def rmse(a, b) -> float:
    return float(np.sqrt(np.mean(np.sum((a[:, :2] - b[:, :2]) ** 2, 1))))


def test_chordal_exact_on_noise_free_graph():
    truth = laps()
    graph = lap_graph(truth, noise=0.0, start=np.zeros_like(truth))
    assert pose_error(ini.chordal(graph), truth) < 1e-9
    assert pose_error(ini.spanning_tree(graph), truth) < 1e-9
    result = solve_g2o(graph, verify=True)
    assert result.init == "chordal" and result.verified and result.certified
    assert result.final_error < 1e-12 and result.inlier.all()
    with pytest.raises(InputError, match="unknown initialisation"):
        ini.initial_poses(graph, "lago")


def test_mit_reaches_best_known_minimum_from_default_start(data_file):
    graph = read_g2o(data_file("posegraphs/MIT.g2o"))
    result = solve_g2o(graph, verify=True)
    assert result.init == "chordal"
    assert result.final_error == pytest.approx(MIT_OPTIMUM, rel=1e-6)
    assert result.verified and result.certified
    local = solve_g2o(graph, init="file")
    assert local.final_error > 300  # the file's start ends in a local minimum
    cert = certificate.certify(graph, local.poses)
    assert cert.stationarity < 1e-9 and not cert.certified and cert.negative_pivots > 0
    checked = solve_g2o(graph, init="file", verify=True)  # not certified: the other starts run and win
    assert checked.init != "file" and "verify" in checked.timings
    assert checked.final_error == pytest.approx(MIT_OPTIMUM, rel=1e-6) and checked.verified and checked.certified


def test_gnc_rejects_50_outliers_where_lm_fails():
    truth = laps()
    clean = lap_graph(truth, noise=1.0, seed=3)
    reference = solve_g2o(clean).poses
    graph, injected = inject_outliers(clean, 50, "random", seed=4)
    plain = solve_g2o(graph, init="spanning_tree")
    assert rmse(plain.poses, reference) > 1.0  # least squares is dragged away
    gnc = solve_g2o(graph, robust="gnc")
    assert rmse(gnc.poses, reference) < 0.05
    m = loop_metrics(gnc.inlier, injected)
    assert m["outliers_rejected"] == m["outliers_injected"] == 50 and m["recall"] == 1.0
    assert m["true_rejected"] <= 1  # of 40 true loops; the TLS gate is the chi-square 99 % quantile


@pytest.mark.parametrize("robust", ["none", "cauchy", "dcs", "gnc_gm"])
def test_every_loop_edge_classified(robust):
    graph, injected = inject_outliers(lap_graph(laps(), noise=1.0, seed=5), 10, "local", seed=6)
    result = solve_g2o(graph, robust=robust)
    assert result.inlier.shape == injected.shape and result.inlier.dtype == bool
    assert result.inlier[odometry_mask(graph)].all()  # odometry is a known inlier
    m = loop_metrics(result.inlier, injected)
    assert m["outliers_injected"] == 10 and 0.0 <= m["precision"] <= 1.0


def test_outlier_kinds_are_seeded_and_grouped():
    clean = lap_graph(laps(), noise=0.0)
    a, inj = inject_outliers(clean, 20, "group", seed=1)
    b, _ = inject_outliers(clean, 20, "group", seed=1)
    np.testing.assert_array_equal(a.measurements, b.measurements)
    assert inj.sum() == 20 and np.all(np.diff(a.i[inj][:10]) == 1)
    local, _ = inject_outliers(clean, 20, "local", seed=2)
    assert np.all(np.abs(local.j[-20:] - local.i[-20:]) <= 10)
    with pytest.raises(InputError, match="unknown kind"):
        inject_outliers(clean, 5, "clustered")


def test_optimize_command_writes_results_folder(tmp_path):
    import json

    from typer.testing import CliRunner

    from slam2d.cli import app
    from slam2d.datasets.g2o import write_g2o

    write_g2o(tmp_path / "laps.g2o", lap_graph(laps(), noise=1.0, seed=7))
    out = tmp_path / "results"
    ref = CliRunner().invoke(app, ["optimize", "-q", str(tmp_path / "laps.g2o"), "--out", str(out / "ref")])
    assert ref.exit_code == 0, ref.output
    (ref_graph,) = (out / "ref").glob("*/graph.g2o")
    res = CliRunner().invoke(app, ["optimize", "-q", str(tmp_path / "laps.g2o"), "--robust", "dcs", "--outliers", "8",
                                   "--outlier-kind", "local", "--seed", "2", "--reference", str(ref_graph),
                                   "--out", str(out)])
    assert res.exit_code == 0, res.output
    (folder,) = out.glob("optimize-laps-*")
    written = {p.name for p in folder.iterdir()}
    assert written >= {"config.yaml", "graph.g2o", "edges.csv", "overlay.png", "metrics.json"}
    metrics = json.loads((folder / "metrics.json").read_text())
    assert metrics["init"] == "spanning_tree" and metrics["outliers_rejected"] == 8
    assert metrics["rmse_to_reference"] < 0.05
    bad = CliRunner().invoke(app, ["optimize", "-q", str(tmp_path / "laps.g2o"), "--init", "lago", "--out", str(out)])
    assert bad.exit_code == 2 and "unknown initialisation" in bad.output


def manhattan(n: int = 400, seed: int = 2) -> PoseGraphFile:
    """M3500-like graph: n unit steps on a 6 x 6 m grid (turning at random), a loop from each pose
    to its last two visits of the same cell, noise 2 cm / 0.6 deg against an information of
    1 / 0.15^2 (like M3500, whose information overstates its noise); vertices at dead reckoning."""
    rng = np.random.default_rng(seed)
    steps, cell, heading, truth = np.array([[1, 0], [0, 1], [-1, 0], [0, -1]]), np.zeros(2, int), 0, [[0.0, 0, 0]]
    for _ in range(n - 1):
        if rng.random() < 0.3:
            heading = (heading + rng.choice([1, 3])) % 4
        while not np.all((cell + steps[heading] >= 0) & (cell + steps[heading] < 6)):
            heading = (heading + rng.choice([1, 3])) % 4
        cell = cell + steps[heading]
        truth.append([*cell, heading * np.pi / 2])
    truth = np.array(truth, float)
    truth[:, 2] = geometry.wrap_angle(truth[:, 2])
    i, j = list(range(n - 1)), list(range(1, n))
    for k in range(n):
        for m in np.flatnonzero(np.all(truth[: max(k - 5, 0), :2] == truth[k, :2], axis=1))[-2:]:
            i.append(int(m))
            j.append(k)
    i, j = np.array(i), np.array(j)
    meas = geometry.compose(geometry.between(truth[i], truth[j]), rng.normal(size=(len(i), 3)) * [0.02, 0.02, 0.01])
    poses = [truth[0]]
    for d in meas[: n - 1]:
        poses.append(geometry.compose(poses[-1], d))
    return PoseGraphFile(np.arange(n), np.array(poses), i, j, meas, np.repeat(np.eye(3)[None] / 0.15**2, len(i), 0))


def test_pc_dcs_rejects_random_false_loops_where_dcs_fails():
    clean = manhattan()
    reference = solve_g2o(clean).poses
    graph, injected = inject_outliers(clean, 200, "random", seed=3)
    true_loops = ~odometry_mask(graph) & ~injected
    dcs = solve_g2o(graph, robust="dcs")
    assert rmse(dcs.poses, reference) > 1.0 and np.sum(dcs.inlier & true_loops) < 0.95 * true_loops.sum()
    result = solve_g2o(graph, robust="pc_dcs")
    assert result.init in ("spanning_tree", "chordal_screened")  # the start of the lower DCS cost
    assert rmse(result.poses, reference) < 1e-5  # least squares over the loops kept: the outlier-free optimum
    m = loop_metrics(result.inlier, injected)
    assert m["outliers_rejected"] == 200 and m["true_rejected"] == 0
    supported = consistency.pairwise_support(graph)
    assert np.sum(supported & injected) < 20  # most random false loops have no consistent partner
    assert np.any(~supported & true_loops)  # true loops the screen missed, kept after its second DCS


def with_detour(graph: PoseGraphFile, heading_bias: float = 0.015) -> PoseGraphFile:
    """``graph`` plus a 5 x 5 m square of unit steps off its last vertex, each step's odometry
    turned by ``heading_bias`` rad too much, closed by one true loop back to that vertex (last edge)."""
    steps = np.array([[1.0, 0.0, np.pi / 2 if t == 4 else 0.0] for _ in range(4) for t in range(5)])
    n, k = len(graph.ids), len(steps)
    meas = steps + [0.0, 0.0, heading_bias]
    poses = [graph.poses[-1]]
    for d in meas:
        poses.append(geometry.compose(poses[-1], d))
    return PoseGraphFile(np.arange(n + k), np.vstack([graph.poses, poses[1:]]),
                         np.r_[graph.i, np.arange(n - 1, n + k)], np.r_[graph.j, np.arange(n, n + k), n - 1],
                         np.vstack([graph.measurements, meas, np.zeros(3)]),
                         np.concatenate([graph.information, np.repeat(graph.information[:1], k + 1, 0)]))


def test_pc_dcs_readmits_an_isolated_loop():
    graph = with_detour(manhattan())
    assert not consistency.pairwise_support(graph)[-1]  # no partner, too long for its own odometry
    assert consistency.edge_chi2(graph, graph.poses)[-1] > 2 * CHI2_3DOF_99  # far off at dead reckoning
    result = solve_g2o(graph, robust="pc_dcs")
    assert result.inlier.all()
    assert rmse(result.poses, solve_g2o(graph).poses) < 1e-4


def test_pairwise_support_on_laps():
    clean = lap_graph(laps(), noise=1.0, seed=8)
    assert consistency.pairwise_support(clean).all()
    graph, injected = inject_outliers(clean, 20, "random", seed=9)
    support = consistency.pairwise_support(graph)
    assert support[~injected].all() and not support[injected].any()
    group, injected = inject_outliers(clean, 10, "group", seed=9)
    assert consistency.pairwise_support(group)[injected].all()  # mutually consistent: left to DCS


def test_edge_chi2_is_gtsams_error():
    graph, _ = inject_outliers(lap_graph(laps(), noise=1.0, seed=10), 10, "random", seed=11)
    poses = graph.poses + np.random.default_rng(12).normal(size=graph.poses.shape) * [2.0, 2.0, 2.0]
    fg, values = g2o_factors(graph), g2o_values(graph.ids, poses)
    gtsam_chi2 = [2.0 * fg.at(k).error(values) for k in range(fg.size())]
    np.testing.assert_allclose(consistency.edge_chi2(graph, poses), gtsam_chi2, rtol=1e-9, atol=1e-9)


def test_bad_information_named_by_edge():
    graph = lap_graph(laps(), noise=0.0)
    information = graph.information.copy()
    information[7, 2, 2] = -1.0
    bad = PoseGraphFile(graph.ids, graph.poses, graph.i, graph.j, graph.measurements, information)
    with pytest.raises(InputError, match=r"g2o edge 7 \(7 -> 8\).*not positive definite"):
        solve_g2o(bad)


def test_optimize_command_pc_dcs(tmp_path):
    import json

    from typer.testing import CliRunner

    from slam2d.cli import app
    from slam2d.datasets.g2o import write_g2o

    write_g2o(tmp_path / "grid.g2o", manhattan())
    res = CliRunner().invoke(app, ["optimize", "-q", str(tmp_path / "grid.g2o"), "--robust", "pc_dcs", "--outliers",
                                   "200", "--seed", "3", "--no-verify", "--out", str(tmp_path)])
    assert res.exit_code == 0, res.output
    (folder,) = tmp_path.glob("optimize-grid-*")
    metrics = json.loads((folder / "metrics.json").read_text())
    assert metrics["init"] in ("spanning_tree", "chordal_screened") and metrics["outliers_rejected"] == 200
    assert metrics["kept_edges_error"] <= metrics["all_edges_error"] and metrics["robust_cost"] > 0
    assert metrics["loops_rejected"] == 200 and metrics["true_loops_kept"] == 1.0


def test_certificate_at_the_optimum_of_a_noisy_graph():
    graph = lap_graph(laps(), noise=1.0, seed=13)
    result = solve_g2o(graph, verify=True)
    assert result.certified
    cert = certificate.certify(graph, result.poses)
    assert cert.stationarity < 1e-9 and cert.negative_pivots == 0 and cert.moved < 0.05
    kappa, tau = certificate.isotropic_weights(graph)
    assert np.allclose(kappa, INFO[2, 2]) and np.allclose(tau, INFO[0, 0])  # isotropic information: tau = its value


def test_certificate_in_gtsams_elimination_order(data_file):
    """The chordal start's and the certificate's factorisations in GTSAM's COLAMD order of the poses
    (``factors.elimination_order``): fewer entries than without an order, the same start (also with the ids out
    of order), the same certificate at MIT's optimum and at its local minimum."""
    graph = read_g2o(data_file("posegraphs/MIT.g2o"))
    order = elimination_order(graph.ids, factor_graph(g2o_factor_list(graph)))
    assert sorted(order) == list(range(len(graph.ids)))
    assert elimination_order(graph.ids[:-1], factor_graph(g2o_factor_list(graph))) is None  # a vertex left out
    for poses in (solve_g2o(graph).poses, solve_g2o(graph, init="file").poses):
        plain, ordered = certificate.certify(graph, poses), certificate.certify(graph, poses, order)
        assert (ordered.certified, ordered.negative_pivots > 0) == (plain.certified, plain.negative_pivots > 0)
        assert ordered.cost == pytest.approx(plain.cost, rel=1e-9) and pose_error(ordered.poses, plain.poses) < 1e-9
    for weighted in (False, True):
        assert pose_error(ini.chordal(graph, weighted, order), ini.chordal(graph, weighted)) < 1e-6  # rounding
    rows = np.r_[0, 1 + np.random.default_rng(1).permutation(len(graph.ids) - 1)]  # ids out of order, first kept
    shuffled = PoseGraphFile(graph.ids[rows], graph.poses[rows], graph.i, graph.j, graph.measurements,
                             graph.information)
    assert pose_error(ini.chordal(shuffled, False, elimination_order(shuffled.ids, factor_graph(
        g2o_factor_list(shuffled)))), ini.chordal(graph, False)[rows]) < 1e-6
    matrix = certificate.data_matrix(graph) + 1e-3 * sparse.identity(3 * len(graph.ids))
    perm = np.column_stack([order, len(order) + 2 * order, len(order) + 2 * order + 1]).ravel()
    lu = SymmetricFactor(matrix, perm)
    rhs = np.random.default_rng(0).normal(size=matrix.shape[0])
    assert np.abs(matrix @ lu.solve(rhs) - rhs).max() < 1e-8
    natural = SymmetricFactor(matrix, np.arange(matrix.shape[0]))
    assert lu.lu.L.nnz + lu.lu.U.nnz < 0.5 * (natural.lu.L.nnz + natural.lu.U.nnz)


def test_factors_keyed_and_weighted_as_gtsam_reads_them(data_file):
    """``g2o_factor_list`` (keys without a call into gtsam, one noise model per distinct information) gives
    GTSAM's own reading of the file its error, at the file's poses and at the optimum."""
    import gtsam

    from slam2d.backend.factors import pose_key

    assert [pose_key(k) for k in (0, 7, 2**40)] == [gtsam.symbol("x", k) for k in (0, 7, 2**40)]
    path = data_file("posegraphs/intel.g2o")
    graph = read_g2o(path)
    ours = factor_graph(g2o_factor_list(graph))
    theirs, _ = gtsam.readG2o(str(path), False)  # keyed by the vertex ids themselves
    for poses in (graph.poses, solve_g2o(graph).poses):
        plain = gtsam.Values()
        for k, (x, y, t) in zip(graph.ids.tolist(), poses.tolist()):
            plain.insert(k, gtsam.Pose2(x, y, t))
        assert ours.error(g2o_values(graph.ids, poses)) == pytest.approx(theirs.error(plain), rel=1e-12)
