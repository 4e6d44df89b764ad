"""One loader for every map file: a map_server ``map.yaml``, a results folder holding one, a floor-plan
image or a Moving AI ``.map``, as one :class:`~slam2d.mapping.occupancy.OccupancyGrid`.

Rows go up in y (row 0 is the bottom of the map): a map.yaml's and a floor plan's image rows are
flipped (image row 0 is the top). A Moving AI map keeps its file's rows, as its ``.scen`` files count
them (row = the scenario's y, column = its x), at 1 m per cell. Free cells get log-odds
-:data:`~slam2d.mapping.export.LOADED_LOG_ODDS`, occupied +, unknown 0. Errors name the file (and line).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from slam2d.config import MAX_RESOLUTION, MIN_RESOLUTION
from slam2d.errors import InputError, not_a_file
from slam2d.mapping.export import LOADED_LOG_ODDS, load_map_server
from slam2d.mapping.grid import OccupancyGrid
from slam2d.mapping.image import read_grey

__all__ = ["load_map", "read_movingai_map", "FLOOR_PLAN_RESOLUTION", "FLOOR_PLAN_FREE_MIN", "FLOOR_PLAN_OCCUPIED_MAX",
           "MOVINGAI_PASSABLE"]

FLOOR_PLAN_RESOLUTION = 0.05
"""m per pixel of a floor-plan image unless a resolution is given."""
FLOOR_PLAN_FREE_MIN = 250
"""Grey level (0-255) from which a floor-plan pixel is free (white)."""
FLOOR_PLAN_OCCUPIED_MAX = 127
"""Grey level up to which a floor-plan pixel is occupied; between the two it is unknown."""
MOVINGAI_PASSABLE = frozenset(".GS")
"""Passable terrain of Moving AI octile maps; ``@ O T W`` are blocked."""

_MOVINGAI_KNOWN = frozenset(".GS@OTW")
_MAP_YAML = (".yaml", ".yml")


def load_map(path, resolution: float | None = None) -> OccupancyGrid:
    """The map at ``path``: a map.yaml, a folder holding one (a results folder), a Moving AI ``.map``, or a
    floor-plan image at ``resolution`` m/px (default :data:`FLOOR_PLAN_RESOLUTION`, origin its lower-left
    corner; grey >= :data:`FLOOR_PLAN_FREE_MIN` free, <= :data:`FLOOR_PLAN_OCCUPIED_MAX` occupied)."""
    path = Path(path)
    if path.is_dir() and (path / "map.yaml").is_file():
        path = path / "map.yaml"
    if not path.is_file():
        raise InputError(path, not_a_file(path) or "map file not found (a map.yaml, a results folder, a floor-plan "
                         "image or a .map)")
    suffix = path.suffix.lower()
    if suffix in _MAP_YAML:
        return load_map_server(path)
    if suffix == ".map":
        free = read_movingai_map(path)
        return OccupancyGrid(np.where(free, -LOADED_LOG_ODDS, LOADED_LOG_ODDS).astype(np.float32), 1.0, (0.0, 0.0))
    if resolution is not None and not MIN_RESOLUTION <= resolution <= MAX_RESOLUTION:
        raise InputError("resolution", f"expected {MIN_RESOLUTION:g} to {MAX_RESOLUTION:g} m/px, got {resolution}")
    grey = read_grey(path)[::-1]  # rows up in y
    lo = np.where(grey <= FLOOR_PLAN_OCCUPIED_MAX, LOADED_LOG_ODDS,
                  np.where(grey >= FLOOR_PLAN_FREE_MIN, -LOADED_LOG_ODDS, 0.0))  # fmt: skip
    return OccupancyGrid(lo.astype(np.float32), resolution or FLOOR_PLAN_RESOLUTION, (0.0, 0.0))


def is_map_yaml(path) -> bool:
    """Whether ``path`` names a map_server YAML (or a folder holding one)."""
    path = Path(path)
    return path.suffix.lower() in _MAP_YAML or (path.is_dir() and (path / "map.yaml").is_file())


def _header_value(lines: list[str], i: int, key: str, path: Path) -> int:
    if i >= len(lines):
        raise InputError(f"{path}:{i + 1}", f"expected '{key} N', got end of file")
    parts = lines[i].split()
    if len(parts) != 2 or parts[0] != key or not parts[1].isdigit() or int(parts[1]) <= 0:
        raise InputError(f"{path}:{i + 1}", f"expected '{key} N' with N > 0, got {lines[i]!r}")
    return int(parts[1])


def read_movingai_map(path) -> np.ndarray:
    """Passable cells (H, W) bool of a Moving AI ``.map``: header ``type``, ``height``, ``width``, ``map``,
    then the rows (row 0 the file's first).

    Passable terrain ``. G S``; ``@ O T W`` are blocked; anything else is an error.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(path, "map file not found")
    lines = path.read_text(errors="replace").splitlines()
    if not lines or not lines[0].startswith("type"):
        raise InputError(f"{path}:1", f"expected 'type octile', got {lines[0] if lines else ''!r}")
    h = _header_value(lines, 1, "height", path)
    w = _header_value(lines, 2, "width", path)
    if len(lines) < 4 or lines[3].strip() != "map":
        raise InputError(f"{path}:4", f"expected 'map', got {lines[3] if len(lines) > 3 else ''!r}")
    rows = lines[4 : 4 + h]
    if len(rows) < h:
        raise InputError(f"{path}:{4 + len(rows) + 1}", f"expected {h} map rows, file ends after {len(rows)}")
    for k, row in enumerate(rows):
        if len(row) != w:
            raise InputError(f"{path}:{k + 5}", f"expected {w} characters, got {len(row)}")
    text = np.frombuffer("".join(rows).encode("latin-1", "replace"), dtype=np.uint8).reshape(h, w)
    known = np.isin(text, np.frombuffer("".join(sorted(_MOVINGAI_KNOWN)).encode(), dtype=np.uint8))
    if not known.all():
        r, c = np.argwhere(~known)[0]
        raise InputError(f"{path}:{r + 5}", f"unknown terrain {chr(text[r, c])!r} at column {c + 1}")
    free = np.isin(text, np.frombuffer("".join(sorted(MOVINGAI_PASSABLE)).encode(), dtype=np.uint8))
    return free
