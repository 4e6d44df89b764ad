"""Grid export: ROS map_server PGM + YAML (save and load) and a PNG figure."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

import numpy as np
import yaml

from slam2d.config import MappingConfig
from slam2d.errors import InputError
from slam2d.mapping.occupancy import OccupancyGrid

__all__ = ["save_map_server", "load_map_server", "save_map_png", "FREE", "OCCUPIED", "UNKNOWN"]

FREE, OCCUPIED, UNKNOWN = 254, 0, 205
"""PGM pixel values written by map_server's map_saver (trinary)."""

LOADED_LOG_ODDS = float(np.log(0.999 / 0.001))
"""|log-odds| given to occupied / free cells of a loaded trinary map (p = 0.999 / 0.001)."""


def save_map_server(grid: OccupancyGrid, path_stem, cfg: MappingConfig) -> tuple[Path, Path]:
    """Write ``STEM.pgm`` (P5) and ``STEM.yaml`` as map_server's map_saver does.

    Pixels: 0 where p > cfg.occupied_thresh, 254 where p < cfg.free_thresh,
    205 otherwise; image row 0 is the top of the map (largest y).
    Returns the (pgm, yaml) paths.
    """
    stem = Path(path_stem)
    pgm, yml = stem.with_name(stem.name + ".pgm"), stem.with_name(stem.name + ".yaml")
    pgm.parent.mkdir(parents=True, exist_ok=True)
    img = np.full(grid.shape, UNKNOWN, np.uint8)
    img[grid.free_mask(cfg.free_thresh)] = FREE
    img[grid.occupied_mask(cfg.occupied_thresh)] = OCCUPIED
    h, w = grid.shape
    header = f"P5\n# CREATOR: slam2d {grid.resolution:.3f} m/pix\n{w} {h}\n255\n".encode("ascii")
    pgm.write_bytes(header + np.flipud(img).tobytes())
    yml.write_text(_map_yaml(pgm.name, grid, cfg))
    return pgm, yml


def _map_yaml(image: str, grid: OccupancyGrid, cfg: MappingConfig) -> str:
    ox, oy = grid.origin
    return (
        f"image: {image}\n"
        f"resolution: {grid.resolution!r}\n"
        f"origin: [{ox!r}, {oy!r}, 0.0]\n"
        f"negate: 0\n"
        f"occupied_thresh: {cfg.occupied_thresh!r}\n"
        f"free_thresh: {cfg.free_thresh!r}\n"
        f"mode: trinary\n"
    )


def load_map_server(yaml_path) -> OccupancyGrid:
    """Read a map_server map (YAML + image) into a grid.

    Modes trinary (default) and scale are supported. Pixel occupancy is
    (255 - v) / 255, or v / 255 with ``negate: 1``. Trinary: cells above
    occupied_thresh get log-odds +LOADED_LOG_ODDS, cells below free_thresh
    -LOADED_LOG_ODDS, the rest 0 (unknown). Scale: every pixel's occupancy,
    clipped to [0.001, 0.999], as log-odds.
    """
    yaml_path = Path(yaml_path)
    meta = _read_map_yaml(yaml_path)
    occ = _read_occupancy(yaml_path, meta)
    if meta["mode"] == "trinary":
        occupied, free = occ > meta["occupied_thresh"], occ < meta["free_thresh"]
        lo = np.where(occupied, LOADED_LOG_ODDS, np.where(free, -LOADED_LOG_ODDS, 0.0))
    else:
        p = np.clip(occ, 0.001, 0.999)
        lo = np.log(p / (1.0 - p))
    return OccupancyGrid(np.flipud(lo), meta["resolution"], meta["origin"][:2])


def _read_map_yaml(path: Path) -> dict:
    if not path.is_file():
        raise InputError(path, "map YAML not found")
    try:
        meta = yaml.safe_load(path.read_text())
    except yaml.YAMLError as err:
        raise InputError(path, f"malformed YAML ({err})") from None
    if not isinstance(meta, dict):
        raise InputError(path, "a map YAML must be a mapping")
    for key in ("image", "resolution", "origin", "occupied_thresh", "free_thresh"):
        if key not in meta:
            raise InputError(path, f"missing key '{key}'")
    meta.setdefault("negate", 0)
    meta.setdefault("mode", "trinary")
    if meta["mode"] not in ("trinary", "scale"):
        raise InputError(path, f"key 'mode': unsupported mode '{meta['mode']}' (trinary or scale)")
    origin = meta["origin"]
    if not isinstance(origin, list) or len(origin) != 3:
        raise InputError(path, f"key 'origin': expected [x, y, yaw], got {origin!r}")
    if float(origin[2]) != 0.0:
        raise InputError(path, f"key 'origin': a rotated map (yaw {origin[2]}) is not supported")
    return meta


def _read_occupancy(yaml_path: Path, meta: dict) -> np.ndarray:
    """Occupancy in [0, 1] per pixel, image rows (row 0 = top), as map_server computes it."""
    from PIL import Image

    image = Path(meta["image"])
    image = image if image.is_absolute() else yaml_path.parent / image
    if not image.is_file():
        raise InputError(yaml_path, f"key 'image': file not found: {image}")
    with Image.open(image) as im:
        px = np.asarray(im.convert("L"), dtype=np.float64)
    return px / 255.0 if meta["negate"] else (255.0 - px) / 255.0


def save_map_png(
    grid: OccupancyGrid,
    path,
    trajectories: Mapping[str, np.ndarray] | None = None,
    title: str | None = None,
) -> Path:
    """Figure of the map (grey: black occupied, white free) with trajectories (N, 3) overlaid.

    Axes in metres, equal aspect, one colour per trajectory and a legend.
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    x0, x1, y0, y1 = grid.extent
    aspect = (y1 - y0) / max(x1 - x0, 1e-9)
    fig = Figure(figsize=(8.0, float(np.clip(8.0 * aspect, 3.0, 16.0))), dpi=150)
    FigureCanvasAgg(fig)
    ax = fig.add_subplot()
    ax.imshow(1.0 - grid.probability(), cmap="gray", vmin=0.0, vmax=1.0, origin="lower",
              extent=grid.extent, interpolation="nearest")  # fmt: skip
    for name, poses in (trajectories or {}).items():
        p = np.asarray(poses, dtype=np.float64).reshape(-1, 3)
        ax.plot(p[:, 0], p[:, 1], linewidth=1.0, label=name)
    if trajectories:
        ax.legend(loc="best", fontsize="small")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_aspect("equal")
    if title:
        ax.set_title(title)
    fig.savefig(path, bbox_inches="tight")
    return path
