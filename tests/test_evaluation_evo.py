"""slam2d's ATE and RPE equal evo's on the same TUM files: ``evo_ape tum REF EST --align`` and
``evo_rpe tum REF EST --delta 1 --delta_unit m --all_pairs --pairs_from_reference`` (translation part and
rotation angle), on a simulator run and on a Radish log."""

from __future__ import annotations

import copy

import numpy as np
import pytest
from evo.core import metrics as evo_metrics
from evo.core.metrics import APE, RPE, PoseRelation, Unit
from evo.tools import file_interface

from slam2d import config
from slam2d.datasets.registry import open_dataset
from slam2d.evaluation.trajectory import ate, read_tum, rpe, write_tum
from slam2d.pipeline import SlamPipeline
from slam2d.types import Trajectory


def _evo(ref_path, est_path, delta: float) -> dict[str, float]:
    ref = file_interface.read_tum_trajectory_file(str(ref_path))
    est = file_interface.read_tum_trajectory_file(str(est_path))
    aligned = copy.deepcopy(est)
    aligned.align(ref, correct_scale=False)
    ape = APE(PoseRelation.translation_part)
    ape.process_data((ref, aligned))
    out = {f"ate_{k}": v for k, v in ape.get_all_statistics().items()}
    for relation, name in ((PoseRelation.translation_part, "trans"), (PoseRelation.rotation_angle_deg, "rot")):
        rel = RPE(relation, delta=delta, delta_unit=Unit.meters, all_pairs=True, pairs_from_reference=True)
        rel.process_data((ref, est))
        out[f"{name}_rmse"], out[f"{name}_mean"], out["pairs"] = (rel.get_statistic(evo_metrics.StatisticsType.rmse),
                                                                  rel.get_statistic(evo_metrics.StatisticsType.mean),
                                                                  len(rel.error))  # fmt: skip
    return out


def _agree(tmp_path, stamps, estimate, reference, delta=1.0):
    est_path = write_tum(tmp_path / "est.tum", Trajectory(stamps, estimate))
    ref_path = write_tum(tmp_path / "ref.tum", Trajectory(stamps, reference))
    est, ref = read_tum(est_path).poses, read_tum(ref_path).poses
    mine_ate, mine_rpe, theirs = ate(est, ref), rpe(est, ref, delta), _evo(ref_path, est_path, delta)
    for key in ("rmse", "mean", "median", "max", "std"):
        assert mine_ate[key] == pytest.approx(theirs[f"ate_{key}"], abs=1e-9), key
    assert mine_rpe["pairs"] == theirs["pairs"] > 10
    for mine, key in (("trans_rmse", "trans_rmse"), ("trans_mean", "trans_mean"), ("rot_rmse_deg", "rot_rmse"),
                      ("rot_mean_deg", "rot_mean")):
        assert mine_rpe[mine] == pytest.approx(theirs[key], abs=1e-9), mine
    return mine_ate, mine_rpe


def _slam(overrides):
    cfg = config.load(None, overrides)
    return SlamPipeline(cfg).run(open_dataset(cfg.dataset, seed=cfg.seed))


def test_ate_and_rpe_equal_evo_on_the_simulator(tmp_path):
    result = _slam(["dataset.max_scans=300"])
    ate_, _ = _agree(tmp_path, result.stamps, result.poses, result.ground_truth)
    assert 0 < ate_["rmse"] < 0.05
    _agree(tmp_path, result.stamps, result.odometry, result.ground_truth, delta=2.0)


def test_ate_and_rpe_equal_evo_on_a_radish_log(tmp_path, data_file):
    """ACES has relations, not a ground-truth trajectory: the SLAM estimate is scored against the wheel odometry,
    which checks the metrics' arithmetic on real trajectories (pauses and turns in place included)."""
    result = _slam(["dataset.kind=rosbag", f"dataset.path={data_file('radish/aces.bag')}", "dataset.max_scans=400"])
    assert len(result.stamps) == 400 and np.ptp(result.odometry[:, :2], axis=0).max() > 5.0
    _agree(tmp_path, result.stamps, result.poses, result.odometry)
