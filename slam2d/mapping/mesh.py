"""3D wall model from a line map (Tian 2016, section 6.6.3): walls of height h and a floor, an open3d mesh.

Each segment (p1, p2) is the thesis's quad (eq. 42) with vertices
``(p1, 0), (p2, 0), (p2, h), (p1, h)`` in that order, split into the triangles
(0, 1, 2) and (0, 2, 3): by the right-hand rule its normal is the segment
direction crossed with z, pointing to the right of p1 -> p2. With a
``thickness`` each segment is instead a closed box (12 triangles, normals out),
so every wall is a watertight solid. The floor is one rectangle at z = 0 over
the map's extent, normal +z (the thesis's ground grid is a drawing aid).

Checks: :func:`solids_watertight` (open3d's ``is_watertight`` of each connected
piece: boxes that touch at a corner intersect, so the whole mesh is never
watertight) and :func:`footprint_hausdorff` (the walls' outline at z = 0 against
the line map).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

__all__ = ["WALL_HEIGHT", "wall_arrays", "floor_arrays", "wall_mesh", "save_mesh", "render_mesh", "solids_watertight",
           "footprint_edges", "footprint_hausdorff"]

WALL_HEIGHT = 2.5
"""Default wall height h, m (the thesis gives none)."""

_QUAD = np.array([[0, 1, 2], [0, 2, 3]])
_BOX = np.array([[0, 1, 5], [0, 5, 4], [1, 2, 6], [1, 6, 5], [2, 3, 7], [2, 7, 6], [3, 0, 4], [3, 4, 7],
                 [0, 3, 2], [0, 2, 1], [4, 5, 6], [4, 6, 7]])  # sides, bottom, top of a box whose base runs CCW


def wall_arrays(segments, height: float = WALL_HEIGHT, thickness: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Vertices (V, 3) m and triangles (T, 3) of walls on segments (K, 2, 2) m: 4 vertices and 2 triangles a
    segment (eq. 42), or with ``thickness`` m a closed box of 8 vertices and 12 triangles."""
    seg = np.asarray(segments, float).reshape(-1, 2, 2)
    k = len(seg)
    if thickness > 0:
        d = seg[:, 1] - seg[:, 0]
        n = np.column_stack([d[:, 1], -d[:, 0]]) / np.maximum(np.linalg.norm(d, axis=1), 1e-12)[:, None]
        off = 0.5 * thickness * n[:, None]
        base = np.stack([seg[:, 0] + off[:, 0], seg[:, 1] + off[:, 0], seg[:, 1] - off[:, 0], seg[:, 0] - off[:, 0]], 1)
        xy, faces = np.concatenate([base, base], axis=1), _BOX  # (K, 8, 2): bottom ring then top ring
        z = np.repeat([[0.0] * 4 + [height] * 4], k, axis=0)
    else:
        xy, faces = seg[:, [0, 1, 1, 0]], _QUAD
        z = np.repeat([[0.0, 0.0, height, height]], k, axis=0)
    per = xy.shape[1]
    vertices = np.concatenate([xy, z[..., None]], axis=2).reshape(-1, 3)
    triangles = (faces[None] + per * np.arange(k)[:, None, None]).reshape(-1, 3)
    return vertices, triangles


def floor_arrays(extent) -> tuple[np.ndarray, np.ndarray]:
    """Vertices (4, 3) and triangles (2, 3) of the floor rectangle ``extent`` (x0, x1, y0, y1) m at z = 0, normal +z."""
    x0, x1, y0, y1 = extent
    return np.array([[x0, y0, 0.0], [x1, y0, 0.0], [x1, y1, 0.0], [x0, y1, 0.0]]), _QUAD.copy()


def wall_mesh(segments, height: float = WALL_HEIGHT, thickness: float = 0.0, floor_extent=None):
    """open3d ``TriangleMesh`` of the walls (and the floor over ``floor_extent`` (x0, x1, y0, y1) m when given),
    triangle and vertex normals computed."""
    import open3d as o3d

    v, t = wall_arrays(segments, height, thickness)
    if floor_extent is not None:
        fv, ft = floor_arrays(floor_extent)
        v, t = np.concatenate([v, fv]), np.concatenate([t, ft + len(v)])
    mesh = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(v), o3d.utility.Vector3iVector(t.astype(np.int32)))
    mesh.compute_triangle_normals()
    mesh.compute_vertex_normals()
    return mesh


def solids_watertight(mesh) -> tuple[int, int]:
    """(watertight, all) connected pieces of the mesh, each tested by open3d's ``is_watertight`` on its own."""
    import open3d as o3d

    cluster = np.asarray(mesh.cluster_connected_triangles()[0])
    v, t = np.asarray(mesh.vertices), np.asarray(mesh.triangles)
    order = np.argsort(cluster, kind="stable")
    pieces = np.split(t[order], np.flatnonzero(np.diff(cluster[order])) + 1) if len(t) else []
    good = 0
    for tri in pieces:
        used, local = np.unique(tri, return_inverse=True)
        piece = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(v[used]),
                                          o3d.utility.Vector3iVector(local.reshape(-1, 3).astype(np.int32)))
        good += piece.is_watertight()
    return good, len(pieces)


def footprint_edges(mesh, tol: float = 1e-9) -> np.ndarray:
    """The walls' outline (E, 2, 2) m: edges with both ends at z = 0 (within ``tol`` m) of triangles that rise
    above it (box bottoms and the floor left out)."""
    v, t = np.asarray(mesh.vertices), np.asarray(mesh.triangles)
    ground = np.abs(v[:, 2]) <= tol
    t = t[~ground[t].all(axis=1)]
    edges = np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]])
    edges = np.unique(np.sort(edges[ground[edges].all(axis=1)], axis=1), axis=0)
    return v[edges][:, :, :2]


def _dense_points(seg: np.ndarray, step: float) -> np.ndarray:
    """Points (S, 2) m on segments (K, 2, 2) m, ends included, at most ``step`` m apart."""
    n = np.ceil(np.linalg.norm(seg[:, 1] - seg[:, 0], axis=1) / step).astype(int) + 1
    start = np.cumsum(n) - n
    k = np.repeat(np.arange(len(seg)), n)
    f = (np.arange(n.sum()) - start[k]) / np.maximum(n[k] - 1, 1)
    return seg[k, 0] + f[:, None] * (seg[k, 1] - seg[k, 0])


def footprint_hausdorff(mesh, line_map, step: float = 0.005) -> tuple[float, float, float]:
    """Hausdorff distance (m) between the mesh's outline at z = 0 (:func:`footprint_edges`) and the line map
    (a ``LineMap`` or segments (K, 2, 2) m), both sampled every ``step`` m (error < step / 2): (max, outline
    to lines, lines to outline); NaN when either is empty."""
    from scipy.spatial import cKDTree

    seg = np.asarray(getattr(line_map, "segments", line_map), float).reshape(-1, 2, 2)
    outline = footprint_edges(mesh)
    if len(seg) == 0 or len(outline) == 0:
        return (float("nan"),) * 3
    a, b = _dense_points(outline, step), _dense_points(seg, step)
    ab, ba = float(cKDTree(b).query(a)[0].max()), float(cKDTree(a).query(b)[0].max())
    return max(ab, ba), ab, ba


def save_mesh(mesh, path) -> Path:
    """Write the mesh as PLY or OBJ (by the suffix); OSError when open3d cannot."""
    import open3d as o3d

    path = Path(path)
    with o3d.utility.VerbosityContextManager(o3d.utility.VerbosityLevel.Error):  # OBJ drops triangle normals
        ok = o3d.io.write_triangle_mesh(str(path), mesh)
    if not ok:
        raise OSError(f"open3d could not write {path}")
    return path


def render_mesh(mesh, path, title: str | None = None, max_triangles: int = 20000) -> Path:
    """PNG view of the mesh (matplotlib 3D, shaded by the triangle normals; walls drawn over the floor)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    v, t = np.asarray(mesh.vertices), np.asarray(mesh.triangles)[:max_triangles]
    normals = np.asarray(mesh.triangle_normals)[: len(t)]
    light = np.array([0.4, -0.6, 0.7]) / np.linalg.norm([0.4, -0.6, 0.7])
    shade = 0.35 + 0.6 * np.abs(normals @ light)
    floor = (normals[:, 2] > 0.99) & (v[t][:, :, 2].max(1) <= 1e-9)
    fig = Figure(figsize=(9, 7), dpi=120)
    FigureCanvasAgg(fig)
    ax = fig.add_subplot(projection="3d")
    ax.computed_zorder = False  # the floor under every wall; walls depth-sorted among themselves
    for part, colour, z in ((floor, (0.85, 0.85, 0.8), 1), (~floor, (0.55, 0.6, 0.75), 2)):
        faces = np.clip(np.asarray(colour) * shade[part, None], 0, 1)
        ax.add_collection3d(Poly3DCollection(v[t[part]], facecolors=faces, linewidths=0, zorder=z))
    lo, hi = v.min(0), v.max(0)
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])
    ax.set_zlim(0, max(hi[2], 1e-3))
    ax.set_zticks([0.0, hi[2]])  # the wall height; more ticks crowd a flat box
    ax.set_box_aspect((hi[0] - lo[0], hi[1] - lo[1], max(hi[2] - lo[2], 1e-3)))
    ax.view_init(elev=60, azim=-70)
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_title(title or f"{len(np.asarray(mesh.triangles))} triangles")
    path = Path(path)
    fig.savefig(path, bbox_inches="tight")
    return path
