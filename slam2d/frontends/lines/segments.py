"""Line segments as point moments, and their total-least-squares fit (metres, radians)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from slam2d import geometry

__all__ = ["Segments", "tls_from_moments", "fit_line"]


@dataclass(frozen=True, eq=False)
class Segments:
    """K line segments with their point moments, all in one frame (metres).

    ends (K, 2, 2) endpoints (scan order); count (K,) points; centroid (K, 2);
    scatter (K, 2, 2) central second moments sum (p - c)(p - c)^T, m^2;
    normal (K, 2) unit, towards the side the segment was seen from; rms (K,)
    TLS residual, m.
    """

    ends: np.ndarray
    count: np.ndarray
    centroid: np.ndarray
    scatter: np.ndarray
    normal: np.ndarray
    rms: np.ndarray

    def __len__(self) -> int:
        return len(self.count)

    @classmethod
    def from_ends(cls, ends, spacing: float = 0.05) -> Segments:
        """Segments (K, 2, 2) as if sampled every ``spacing`` m; normals on the left of p0 -> p1."""
        ends = np.asarray(ends, float).reshape(-1, 2, 2)
        d = ends[:, 1] - ends[:, 0]
        length = np.linalg.norm(d, axis=1)
        u = d / np.maximum(length, 1e-12)[:, None]
        count = np.maximum(length / spacing, 2.0)
        scatter = (count * length**2 / 12.0)[:, None, None] * np.einsum("ki,kj->kij", u, u)
        return cls(ends, count, ends.mean(axis=1), scatter, np.column_stack([-u[:, 1], u[:, 0]]),
                   np.zeros(len(ends)))

    @classmethod
    def empty(cls) -> Segments:
        return cls(np.zeros((0, 2, 2)), np.zeros(0), np.zeros((0, 2)), np.zeros((0, 2, 2)), np.zeros((0, 2)),
                   np.zeros(0))

    @property
    def length(self) -> np.ndarray:
        """(K,) m."""
        return np.linalg.norm(self.ends[:, 1] - self.ends[:, 0], axis=1)

    @property
    def direction(self) -> np.ndarray:
        """(K, 2) unit direction, the normal turned by -90 degrees."""
        return np.column_stack([self.normal[:, 1], -self.normal[:, 0]])

    @property
    def alpha(self) -> np.ndarray:
        """(K,) normal angle, rad."""
        return np.arctan2(self.normal[:, 1], self.normal[:, 0])

    @property
    def offset(self) -> np.ndarray:
        """(K,) signed distance d of the line n . p = d, m."""
        return np.einsum("ki,ki->k", self.normal, self.centroid)

    @property
    def spread(self) -> np.ndarray:
        """(K,) scatter along the line, sum ((p - c) . u)^2, m^2."""
        u = self.direction
        return np.einsum("ki,kij,kj->k", u, self.scatter, u)

    def transformed(self, pose) -> Segments:
        """The segments mapped from the frame of ``pose`` (3,) to its parent frame."""
        pose = geometry.as_pose(pose)
        c, s = np.cos(pose[2]), np.sin(pose[2])
        rot = np.array([[c, -s], [s, c]])
        return Segments(
            ends=geometry.transform_points(pose, self.ends),
            count=self.count,
            centroid=geometry.transform_points(pose, self.centroid),
            scatter=rot @ self.scatter @ rot.T,
            normal=self.normal @ rot.T,
            rms=self.rms,
        )

    def subset(self, keep) -> Segments:
        return Segments(self.ends[keep], self.count[keep], self.centroid[keep], self.scatter[keep],
                        self.normal[keep], self.rms[keep])


def tls_from_moments(count, centroid, scatter) -> tuple[np.ndarray, np.ndarray]:
    """Unit normals (K, 2) and rms residuals (K,) of total-least-squares lines through point moments."""
    sxx, syy, sxy = scatter[:, 0, 0], scatter[:, 1, 1], scatter[:, 0, 1]
    phi = 0.5 * np.arctan2(2.0 * sxy, sxx - syy)  # direction of largest spread
    normal = np.column_stack([-np.sin(phi), np.cos(phi)])
    lam_min = 0.5 * (sxx + syy) - np.hypot(0.5 * (sxx - syy), sxy)
    return normal, np.sqrt(np.maximum(lam_min, 0.0) / np.maximum(count, 1))


def fit_line(points) -> tuple[np.ndarray, np.ndarray, float]:
    """Total-least-squares line of points (N, 2): centroid (2,), unit normal (2,), rms distance (m)."""
    p = np.asarray(points, float).reshape(-1, 2)
    c = p.mean(axis=0)
    d = p - c
    normal, rms = tls_from_moments(np.array([len(p)]), c[None], (d.T @ d)[None])
    return c, normal[0], float(rms[0])
