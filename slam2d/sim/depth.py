"""A Kinect-like depth camera: a pinhole depth image ray cast against the floor, the walls, the
moving obstacles and the world's 3D objects (:mod:`slam2d.sim.objects3d`), with depth noise.

The camera sits ``height`` m above the floor at the robot's centre plus ``forward`` m, looking
along the robot's heading, pitched down by ``pitch_deg``. Robot base frame: x forward, y left,
z up from the floor. Walls and moving obstacles stand from the floor to above anything the camera
sees within its range, so each pixel's wall distance is the 2D ray cast along its azimuth
(one cast per distinct azimuth, quantised to ``_AZIMUTH_STEP``).

Depth noise (axial, Gaussian): the Kinect v1 model of Nguyen, Izadi & Lovell, "Modeling Kinect
sensor noise for improved 3D reconstruction and tracking", 3DIMPVT 2012, eq. for angles below
60 degrees: sigma_z(z) = 0.0012 + 0.0019 (z - 0.4)^2 m (z the depth in m): 1.2 mm at 0.4 m,
1.9 mm at 1 m, 8 mm at 2 m, 26 mm at 4 m; ``noise_scale`` multiplies it.
"""

from __future__ import annotations

from typing import Annotated

import numpy as np
from pydantic import Field, model_validator

from slam2d.config import Section
from slam2d.sim.world import World

__all__ = ["CameraGeometry", "DepthCamera", "DepthCameraConfig", "depth_noise_sd"]

_AZIMUTH_STEP = np.deg2rad(0.1)  # rad, azimuths of pixels cast as one 2D ray
_Angle = Annotated[float, Field(gt=0, lt=180)]
_Positive = Annotated[float, Field(gt=0)]
_Pixels = Annotated[int, Field(ge=2, le=2000)]


class DepthCameraConfig(Section):
    """A depth camera on the robot and the processing of its clouds into an obstacle layer of the
    local costmap (``navigation.options.depth_camera``; :mod:`slam2d.navigation.depth_layer`)."""

    enabled: bool = Field(False, description="render a depth cloud at every control step and avoid what it sees")
    height: float = Field(0.45, gt=0, le=5, description="m, the camera's optical centre above the floor")
    forward: float = Field(0.1, ge=-1, le=1, description="m, the camera ahead of the robot's centre")
    pitch_deg: float = Field(20.0, ge=0, lt=90, description="degrees the optical axis points below the horizon")
    fov_deg: tuple[_Angle, _Angle] = Field(
        (57.5, 43.5), description="horizontal, vertical field of view, degrees (Kinect v1: 57.5 x 43.5)")
    range: tuple[_Positive, _Positive] = Field((0.5, 4.0), description="m, nearest and farthest depth returned")
    resolution: tuple[_Pixels, _Pixels] = Field((80, 60), description="pixels, width x height (Kinect: 640 x 480)")
    noise_scale: float = Field(1.0, ge=0, description="x the Kinect depth noise of Nguyen et al. 2012; 0: none")
    voxel: float = Field(0.02, gt=0, le=1, description="m, voxel size of the down-sampling (open3d)")
    plane_threshold: float = Field(0.01, gt=0, le=0.2, description="m, RANSAC floor-plane inlier distance")
    band: tuple[_Positive, _Positive] = Field(
        (0.02, 0.45), description="m above the floor plane: points in this band are obstacles (the robot's height)")
    mark_range: float = Field(3.0, gt=0, description="m, farthest an obstacle point is marked (noise grows with z^2)")
    laser_overlap: float = Field(
        0.1, ge=0, description="m; an obstacle point this near a laser point is left to the laser (what it "
        "sees may move, the layer's points stay)")
    persistence: float = Field(30.0, gt=0, description="s an obstacle no longer seen is kept (out of view)")
    look_around: bool = Field(
        True, description="before driving off, turn on the spot until the camera has swept every bearing (what "
        "stands beside or behind the start is marked before the robot turns into it), ending facing the path")
    clear_margin: float = Field(
        0.05, ge=0, description="m; a kept obstacle the camera sees through by this (+3 sigma of the noise) is cleared")

    @model_validator(mode="after")
    def _ordered(self):
        for key in ("range", "band"):
            lo, hi = getattr(self, key)
            if not lo < hi:
                raise ValueError(f"{key} must be (low, high) with low < high, got ({lo}, {hi})")
        return self


def depth_noise_sd(depth) -> np.ndarray:
    """Axial depth noise sd (m) of a Kinect v1 at ``depth`` (m): Nguyen et al. 2012."""
    z = np.asarray(depth, dtype=np.float64)
    return 0.0012 + 0.0019 * (z - 0.4) ** 2


class CameraGeometry:
    """The camera's pixel rays and projection in the robot base frame (x forward, y left, z up)."""

    def __init__(self, cfg: DepthCameraConfig):
        self.cfg = cfg
        w, h = cfg.resolution
        p = np.deg2rad(cfg.pitch_deg)
        self.origin = np.array([cfg.forward, 0.0, cfg.height])  # optical centre (3,)
        self.axis = np.array([np.cos(p), 0.0, -np.sin(p)])  # optical axis
        self.right = np.array([0.0, -1.0, 0.0])  # image x
        self.down = np.array([-np.sin(p), 0.0, -np.cos(p)])  # image y
        self.focal = (w / 2 / np.tan(np.deg2rad(cfg.fov_deg[0]) / 2), h / 2 / np.tan(np.deg2rad(cfg.fov_deg[1]) / 2))
        u = (np.arange(w) + 0.5 - w / 2) / self.focal[0]  # tangent of each column's angle
        v = (np.arange(h) + 0.5 - h / 2) / self.focal[1]
        uu, vv = np.meshgrid(u, v)  # (H, W)
        rays = self.axis + uu[..., None] * self.right + vv[..., None] * self.down  # (H, W, 3), unit depth
        self.rays = rays.reshape(-1, 3)  # along each pixel's ray, depth 1 m (the optical-axis component is 1)

    def points(self, depth: np.ndarray) -> np.ndarray:
        """Points (N, 3) in the base frame of a depth image (H, W) m; pixels without a finite depth dropped."""
        d = np.asarray(depth, dtype=np.float64).reshape(-1)
        ok = np.isfinite(d)
        return self.origin + self.rays[ok] * d[ok, None]

    def project(self, points) -> tuple[np.ndarray, np.ndarray]:
        """Pixel index (N,) into the flattened image (-1 outside it) and depth (N,) m of base-frame ``points`` (N, 3)."""
        rel = np.asarray(points, dtype=np.float64).reshape(-1, 3) - self.origin
        z = rel @ self.axis
        w, h = self.cfg.resolution
        with np.errstate(divide="ignore", invalid="ignore"):
            col = np.floor(rel @ self.right / z * self.focal[0] + w / 2)
            row = np.floor(rel @ self.down / z * self.focal[1] + h / 2)
        inside = (z > 0) & (col >= 0) & (col < w) & (row >= 0) & (row < h)
        return np.where(inside, row * w + col, -1).astype(np.int64), z


class DepthCamera:
    """Renders depth images (H, W) m from a robot pose in a world: ``inf`` where nothing is within the
    far range, NaN nearer than the near range (no return either way), noise as the module says."""

    def __init__(self, cfg: DepthCameraConfig | None = None, seed=0):
        self.cfg = cfg or DepthCameraConfig()
        self.geometry = CameraGeometry(self.cfg)
        self._rng = np.random.default_rng(seed)

    def render(self, world: World, pose, circles=None) -> np.ndarray:
        """Depth image (H, W) m from the robot at true ``pose`` (3,) in ``world`` (its walls, floor and
        ``world.objects``), with ``circles`` (centres (C, 2), radii (C,)) as people standing on the floor."""
        g, (near, far) = self.geometry, self.cfg.range
        c, s = np.cos(pose[2]), np.sin(pose[2])
        rot = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        rays = g.rays @ rot.T  # (R, 3) world frame, unit depth
        origin = np.array([pose[0], pose[1], 0.0]) + rot @ g.origin
        reach = far * np.linalg.norm(g.rays, axis=1).max()  # m along a ray at the far depth
        flat = np.hypot(rays[:, 0], rays[:, 1])
        azimuth = np.arctan2(rays[:, 1], rays[:, 0])
        keys, which = np.unique(np.round(azimuth / _AZIMUTH_STEP).astype(np.int64), return_inverse=True)
        walls = world.raycast_many(origin[None, :2], (keys * _AZIMUTH_STEP)[None], reach, circles)[0]
        with np.errstate(divide="ignore"):
            t = np.where(walls[which] < reach, walls[which] / flat, np.inf)  # depths: the rays have unit depth
            t = np.minimum(t, np.where(rays[:, 2] < 0, origin[2] / -rays[:, 2], np.inf))  # the floor
        if world.objects is not None and len(world.objects):
            length = np.linalg.norm(rays, axis=1)
            t = np.minimum(t, world.objects.raycast(origin, rays / length[:, None], reach) / length)
        if self.cfg.noise_scale > 0:
            t = t + self._rng.normal(0.0, 1.0, t.shape) * self.cfg.noise_scale * depth_noise_sd(np.minimum(t, far))
        t = np.where(t > far, np.inf, t)
        t[t < near] = np.nan
        return t.reshape(self.cfg.resolution[1], self.cfg.resolution[0])
