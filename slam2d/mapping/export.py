"""Grid export: ROS map_server PGM + YAML (save and load) and a PNG figure."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

import numpy as np

from slam2d.config import MAX_RESOLUTION, MIN_RESOLUTION, MappingConfig, read_yaml, short_repr
from slam2d.errors import InputError, not_a_file
from slam2d.mapping.grid import OccupancyGrid, logit
from slam2d.mapping.image import read_grey

__all__ = ["save_map_server", "load_map_server", "save_map_png", "downsample", "FREE", "OCCUPIED", "UNKNOWN"]

FREE, OCCUPIED, UNKNOWN = 254, 0, 205
"""PGM pixel values written by map_server's map_saver (trinary)."""

LOADED_LOG_ODDS = float(np.log(0.999 / 0.001))
"""|log-odds| given to occupied / free cells of a loaded trinary map (p = 0.999 / 0.001)."""

CHUNK_CELLS = 1 << 22
"""Cells classified and written at a time by :func:`save_map_server` (a few MB of temporaries)."""

MAX_FIGURE_PX = 2000
"""Longest side, px, of the grid image drawn by :func:`save_map_png` (it never exceeds the axes either)."""


def save_map_server(grid: OccupancyGrid, path_stem, cfg: MappingConfig) -> tuple[Path, Path]:
    """Write ``STEM.pgm`` (P5) and ``STEM.yaml`` as map_server's map_saver does.

    Pixels: 0 where p > cfg.occupied_thresh, 254 where p < cfg.free_thresh,
    205 otherwise; image row 0 is the top of the map (largest y). The image
    is classified and streamed :data:`CHUNK_CELLS` cells at a time.
    Returns the (pgm, yaml) paths.
    """
    stem = Path(path_stem)
    pgm, yml = stem.with_name(stem.name + ".pgm"), stem.with_name(stem.name + ".yaml")
    pgm.parent.mkdir(parents=True, exist_ok=True)
    h, w = grid.shape
    occupied, free = np.float64(logit(cfg.occupied_thresh)), np.float64(logit(cfg.free_thresh))
    with pgm.open("wb") as f:
        f.write(f"P5\n# CREATOR: slam2d {grid.resolution:.3f} m/pix\n{w} {h}\n255\n".encode("ascii"))
        step = max(1, CHUNK_CELLS // max(w, 1))
        for top in range(h, 0, -step):  # image rows top first: grid rows from the last
            block = grid.log_odds[max(top - step, 0) : top]
            f.write(_trinary(block, occupied, free)[::-1].tobytes())
    yml.write_text(_map_yaml(pgm.name, grid, cfg))
    return pgm, yml


def _trinary(log_odds: np.ndarray, occupied: np.float64, free: np.float64) -> np.ndarray:
    """PGM values (uint8, same shape) of log-odds cells given the thresholds as log-odds."""
    img = np.full(log_odds.shape, UNKNOWN, np.uint8)
    img[log_odds < free] = FREE
    img[log_odds > occupied] = OCCUPIED
    return img


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
    pixels = _read_pixels(yaml_path, meta)
    return OccupancyGrid(_pixel_log_odds(meta)[pixels[::-1]], meta["resolution"], meta["origin"][:2])


def _pixel_log_odds(meta: dict) -> np.ndarray:
    """Log-odds (256,) float32 of each 8-bit pixel value under the YAML's mode and thresholds."""
    v = np.arange(256, dtype=np.float64)
    occ = v / 255.0 if meta["negate"] else (255.0 - v) / 255.0
    if meta["mode"] == "trinary":
        occupied, free = occ > meta["occupied_thresh"], occ < meta["free_thresh"]
        lo = np.where(occupied, LOADED_LOG_ODDS, np.where(free, -LOADED_LOG_ODDS, 0.0))
    else:
        p = np.clip(occ, 0.001, 0.999)
        lo = np.log(p / (1.0 - p))
    return lo.astype(np.float32)


def map_yaml_free_thresh(path) -> float:
    """The ``free_thresh`` of the map_server YAML at ``path`` (or in the folder ``path``)."""
    path = Path(path)
    return float(_read_map_yaml(path / "map.yaml" if path.is_dir() else path)["free_thresh"])


def _read_map_yaml(path: Path) -> dict:
    if not path.is_file():
        raise InputError(path, not_a_file(path) or "map YAML not found")
    meta = read_yaml(path)
    if not isinstance(meta, dict):
        raise InputError(path, "a map YAML must be a mapping")
    for key in ("image", "resolution", "origin", "occupied_thresh", "free_thresh"):
        if key not in meta:
            raise InputError(path, f"missing key '{key}'")
    meta.setdefault("negate", 0)
    meta.setdefault("mode", "trinary")
    if meta["mode"] not in ("trinary", "scale"):
        raise InputError(path, f"key 'mode': unsupported mode {short_repr(meta['mode'])} (trinary or scale)")
    if not isinstance(meta["image"], str) or not meta["image"]:
        raise InputError(path, f"key 'image': expected a file name, got {short_repr(meta['image'])}")
    if meta["negate"] not in (0, 1):
        raise InputError(path, f"key 'negate': expected 0 or 1, got {short_repr(meta['negate'])}")
    _check_numbers(path, meta)
    return meta


def _number(path: Path, key: str, value) -> float:
    """``value`` as a finite float; an InputError naming ``key`` otherwise."""
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not np.isfinite(value):
        raise InputError(path, f"key '{key}': expected a finite number, got {short_repr(value)}")
    return float(value)


def _check_numbers(path: Path, meta: dict) -> None:
    """Resolution > 0, origin [x, y, 0] finite, 0 <= free_thresh < occupied_thresh <= 1."""
    if _number(path, "resolution", meta["resolution"]) <= 0:
        raise InputError(path, f"key 'resolution': must be > 0 m per pixel, got {meta['resolution']}")
    if not MIN_RESOLUTION <= meta["resolution"] <= MAX_RESOLUTION:
        raise InputError(path, f"key 'resolution': expected {MIN_RESOLUTION:g} to {MAX_RESOLUTION:g} m per pixel, "
                         f"got {meta['resolution']:g}")
    origin = meta["origin"]
    if not isinstance(origin, list) or len(origin) != 3:
        raise InputError(path, f"key 'origin': expected [x, y, yaw], got {short_repr(origin)}")
    meta["origin"] = [_number(path, "origin", v) for v in origin]
    if meta["origin"][2] != 0.0:
        raise InputError(path, f"key 'origin': a rotated map (yaw {origin[2]}) is not supported")
    free, occupied = (_number(path, key, meta[key]) for key in ("free_thresh", "occupied_thresh"))
    if not 0.0 <= free < occupied <= 1.0:
        raise InputError(path, f"keys 'free_thresh' {free} and 'occupied_thresh' {occupied}: "
                         "expected 0 <= free_thresh < occupied_thresh <= 1")


def _read_pixels(yaml_path: Path, meta: dict) -> np.ndarray:
    """8-bit grey value (uint8) per pixel, image rows (row 0 = top)."""
    image = Path(meta["image"])
    image = image if image.is_absolute() else yaml_path.parent / image
    if not image.is_file():
        raise InputError(yaml_path, f"key 'image': file not found: {image}")
    return read_grey(image)


def save_map_png(
    grid: OccupancyGrid,
    path,
    trajectories: Mapping[str, np.ndarray] | None = None,
    title: str | None = None,
) -> Path:
    """Figure of the map (grey: black occupied, white free) with trajectories (N, 3) overlaid.

    Axes in metres, equal aspect, one colour per trajectory and a legend; each trajectory is drawn
    above those after it, and thinner, so the first (the estimate) lies on the others and a trajectory
    it covers (the ground truth) still shows at its edges (:func:`draw_trajectories`). The
    grid is drawn :func:`downsample`-d to no more pixels than the axes have
    and at most :data:`MAX_FIGURE_PX` on its long side.
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
    _draw_grid(ax, grid)
    draw_trajectories(ax, trajectories or {})
    if trajectories:
        ax.legend(loc="best", fontsize="small")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_aspect("equal")
    if title:
        ax.set_title(title)
    fig.savefig(path, bbox_inches="tight")
    return path


def draw_trajectories(ax, trajectories: Mapping[str, np.ndarray]) -> list:
    """Plot the trajectories (N, 3) on ``ax`` in their order of the mapping (the legend's), each above
    and thinner than those after it; return the lines."""
    lines = []
    n = len(trajectories)
    for i, (name, poses) in enumerate(trajectories.items()):
        p = np.asarray(poses, dtype=np.float64).reshape(-1, 3)
        (line,) = ax.plot(p[:, 0], p[:, 1], linewidth=1.0 + 0.6 * i, zorder=2.0 + (n - i) / (n + 1), label=name)
        lines.append(line)
    return lines


def _draw_grid(ax, grid: OccupancyGrid) -> None:
    """Draw the grid downsampled to the axes' pixels, grey 255 (1 - p), in metres."""
    k = _block_size(grid.shape, ax.get_window_extent())
    shown = downsample(grid.log_odds, k)
    ox, oy = grid.origin
    size = k * grid.resolution  # m per image pixel
    rgba = np.full((*shown.shape, 4), 255, np.uint8)  # opaque uint8 RGBA: Agg resamples it with the fewest copies
    rgba[..., :3] = np.round(255.0 / (1.0 + np.exp(shown.astype(np.float64))))[..., None]
    ax.imshow(rgba, origin="lower", interpolation="nearest",
              extent=(ox, ox + shown.shape[1] * size, oy, oy + shown.shape[0] * size))  # fmt: skip


def _block_size(shape: tuple[int, int], box) -> int:
    """Cells per side of the square blocks drawn as one pixel in the axes ``box`` (display px)."""
    h, w = shape
    fit = max(h / max(box.height, 1.0), w / max(box.width, 1.0), max(h, w) / MAX_FIGURE_PX)
    return max(1, int(np.ceil(fit)))


def downsample(log_odds: np.ndarray, k: int) -> np.ndarray:
    """Log-odds (ceil(H / k), ceil(W / k)) of the k x k blocks of ``log_odds`` (H, W).

    A block takes its largest log-odds when that is positive (occupied wins, so
    one-cell walls stay visible), else its smallest (free wins over unknown).
    """
    if k <= 1:
        return log_odds
    hi = _reduce_rows(np.maximum, _reduce_rows(np.maximum, log_odds, k).T, k).T
    lo = _reduce_rows(np.minimum, _reduce_rows(np.minimum, log_odds, k).T, k).T
    return np.where(hi > 0, hi, lo)


def _reduce_rows(ufunc, a: np.ndarray, k: int) -> np.ndarray:
    """``ufunc`` (np.maximum or np.minimum) over each run of k rows of ``a`` (H, W): (ceil(H / k), W)."""
    out = a[::k].copy()
    for i in range(1, k):
        part = a[i::k]
        ufunc(out[: len(part)], part, out=out[: len(part)])
    return out
