"""Parameters of the ICP frontend (``frontend.name: icp``, ``frontend.options``)."""

from __future__ import annotations

from typing import Literal

from pydantic import Field

from slam2d.config import MAX_RESOLUTION, Resolution, Section
from slam2d.frontends.common import (
    MaxCorrectionThetaDeg,
    MaxCorrectionXY,
    MaxRange,
    MaxSigmaThetaDeg,
    MaxSigmaXY,
    MinRange,
    MinSigmaThetaDeg,
    MinSigmaXY,
    OdomSigmaThetaDeg,
    OdomSigmaXY,
)

__all__ = ["IcpConfig"]


class IcpConfig(Section):
    """ICP frontend parameters; defaults suit 180-beam SICK logs (5-10 Hz) and the 360-beam simulator."""

    method: Literal["point_to_line", "point_to_point"] = Field(
        "point_to_line", description="2D point-to-line Gauss-Newton, or kiss-icp's 3D point-to-point"
    )
    min_range: MinRange = 0.1
    max_range: MaxRange = 30.0
    voxel_size: float = Field(0.0, ge=0, le=MAX_RESOLUTION, description="m; downsampling of the registered points (0: none)")
    map_voxel_size: Resolution = Field(0.2, description="m; voxel of the local map")
    map_max_points_per_voxel: int = Field(20, gt=0, le=10_000, description="points kept per map voxel")
    map_window: int = Field(30, ge=0, description="scans kept in the local map (0: all within map_radius)")
    map_order: Literal["beam", "random"] = Field(
        "beam", description="order a scan's points go into the map's voxels, first come first kept: beam order "
        "turns the map against the scan (-0.5 mdeg a scan in the simulator), random does not (each map_seed one draw)"
    )
    map_seed: int = Field(0, ge=0, description="seed of the random order (map_order random): each seed one draw")
    map_radius: float = Field(30.0, gt=0, description="m; map voxels farther than this from the robot are dropped")
    initial_threshold: float = Field(0.5, gt=0, description="m; correspondence scale before any motion statistics")
    min_motion: float = Field(0.02, ge=0, description="m; odometry deviation that updates the adaptive threshold")
    threshold_range: float = Field(10.0, gt=0, description="m; lever arm turning rotation deviation into m")
    min_threshold: float = Field(0.05, gt=0, description="m; floor of the adaptive threshold")
    max_threshold: float = Field(1.0, gt=0, description="m; cap of the adaptive threshold")
    correspondence_factor: float = Field(3.0, gt=0, description="max correspondence distance / threshold")
    kernel_factor: float = Field(1.0, gt=0, description="Geman-McClure scale / threshold")
    refine_kernel: float = Field(0.05, ge=0, description="m; Geman-McClure scale of a final refinement (0: none)")
    neighbours: int = Field(5, ge=2, description="map points per correspondence (point_to_line)")
    information_neighbours: int = Field(
        15, ge=2, description="map points per line fit for the information and confidence (steadier normals)"
    )
    along_weight: float = Field(0.0, ge=0, le=1, description="weight of the along-line residual (point_to_line)")
    line_ratio: float = Field(0.2, gt=0, le=1, description="max eigenvalue ratio of a line neighbourhood")
    scan_line_gap: float = Field(1.0, gt=0, description="m; max gap between beams fitted to one scan line")
    min_cluster: int = Field(3, ge=1, description="map points near a point on no line for a point-to-point match")
    max_iterations: int = Field(20, gt=0, description="correspondence searches per scan")
    inner_iterations: int = Field(3, gt=0, description="Gauss-Newton steps per correspondence search")
    convergence: float = Field(1e-4, gt=0, description="stop when the update is below this (m and rad)")
    coarse_convergence: float = Field(
        3e-3, gt=0, description="... in the adaptive-kernel pass before a refinement (m and rad)"
    )
    odom_prior: bool = Field(True, description="regularise the match with the odometry delta (point_to_line)")
    degeneracy_ratio: float = Field(
        0.0, ge=0, description="a direction where the scan's information is below this x the odometry's "
        "(odom_sigma_*) is taken from the prediction, not the match (0: never; no Radish log gains from it)"
    )
    moving_margin: float = Field(
        0.0, ge=0, description="m; a point two earlier scans of the local map saw this far through is moving: "
        "matched again without it, kept out of the map (0: never; 0.1 helps the simulator with people walking; "
        "the clinic, ACES, FR079 and MIT-CSAIL lose by it)"
    )
    point_sigma: float = Field(0.03, gt=0, description="m; std of one point residual: prior weight vs points")
    inlier_distance: float = Field(0.1, gt=0, description="m; residual of a point counted as matched")
    retry_below: float = Field(0.6, ge=0, le=1, description="matched fraction below which other guesses are tried")
    retry_beyond_reach: bool = Field(
        False, description="try the constant-velocity and no-motion predictions as starts also when odometry lies "
        "beyond the ICP's reach from them (a match from odometry can stop short with enough points matched)"
    )
    min_points: int = Field(20, ge=3, description="fewer valid points than this -> odometry fallback")
    min_inlier_fraction: float = Field(0.2, ge=0, le=1, description="fewer matched points -> fallback")
    max_correction_xy: MaxCorrectionXY = 0.5
    max_correction_theta_deg: MaxCorrectionThetaDeg = 30.0
    max_planarity_error: float = Field(1e-3, gt=0, description="point_to_point: tolerated z (m) / tilt (rad)")
    odom_sigma_xy: OdomSigmaXY = 0.05  # the prior and the fallback
    odom_sigma_theta_deg: OdomSigmaThetaDeg = 2.0
    min_sigma_xy: MinSigmaXY = 0.002
    min_sigma_theta_deg: MinSigmaThetaDeg = 0.05
    max_sigma_xy: MaxSigmaXY = 1.0
    max_sigma_theta_deg: MaxSigmaThetaDeg = 20.0
    threads: int = Field(1, ge=0, description="kiss-icp registration threads (0: all cores)")
    still_distance: float = Field(
        0.01, ge=0, description="m; odometry motion since the last registered scan below which a scan is skipped"
    )
    still_angle_deg: float = Field(0.5, ge=0, description="... and rotation below which (0 and 0: never skip)")
