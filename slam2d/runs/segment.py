"""``slam2d segment``: a map split into rooms, written as a results folder.

- ``labels.png``: 16-bit grayscale, one value per room (0 = not a room), in the
  map image's orientation (row 0 the top), so it overlays the map;
- ``rooms.png``: the rooms in colour (neighbours differ) with the region graph:
  nodes at room centres, edges through their portals; axes in metres;
- ``rooms_graph.json``: :func:`slam2d.mapping.topological.save_graph`;
- ``metrics.json``: method, rooms, seconds (and k, silhouette for spectral),
  plus recall / precision (%) against the ground truth when one is given or
  found beside the map as ``<stem>_gt_segmentation.png`` (for
  ``<stem>_furnitures.png`` the unfurnished stem's).
"""

from __future__ import annotations

from pathlib import Path

import networkx as nx
import numpy as np
from PIL import Image, ImageDraw, ImageFont

from slam2d import config as config_mod
from slam2d.errors import InputError
from slam2d.mapping.topological import save_graph
from slam2d.paths import resolve_data_path
from slam2d.runs.results import json_text, results_folder
from slam2d.segmentation.rooms import RoomSegmentation, segment_map

__all__ = ["run_segment", "write_segmentation", "save_labels_png", "save_rooms_png", "room_colours"]


def run_segment(cfg, quiet: bool = False) -> Path:
    """Run a :class:`~slam2d.segmentation.config.SegmentConfig` into a new results folder under
    ``cfg.output.root`` (resolved config, labels, figures, metrics, log); return the folder."""
    if cfg.map is None:
        raise InputError("map", "no map given (map: FILE in the config, or slam2d segment MAP)")
    map_path = resolve_data_path(cfg.map, key="map")
    gt = resolve_data_path(cfg.ground_truth, key="ground_truth") if cfg.ground_truth else None
    seg = cfg.segmentation
    name = cfg.name or f"segment-{map_path.stem}-{seg.method}"
    with results_folder(cfg.output.root, name) as (work, published):
        (work / "config.yaml").write_text(config_mod.dump(cfg))
        rooms = segment_map(map_path, seg.method, seg.similarity, ground_truth=gt, resolution=cfg.resolution,
                            params=seg.params, seed=cfg.seed)
        write_segmentation(rooms, work, figures=cfg.output.figures)
    return published[0]


def write_segmentation(rooms: RoomSegmentation, out: Path, figures: bool = True) -> None:
    """labels.png, rooms_graph.json, rooms.png (``figures``) and metrics.json of ``rooms`` into ``out``."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    save_labels_png(rooms.image_labels, out / "labels.png")
    save_graph(rooms.graph, out / "rooms_graph.json")
    if figures:
        save_rooms_png(rooms.labels, rooms.free, rooms.graph, rooms.resolution, rooms.origin, rooms.row0_top,
                       out / "rooms.png", title=rooms.title)
    (out / "metrics.json").write_text(json_text(rooms.metrics))


def save_labels_png(labels, path) -> Path:
    """Write labels (H, W) (0..65535) as a 16-bit grayscale PNG; read back with PIL + ``np.asarray``."""
    labels = np.asarray(labels)
    if labels.size and (labels.min() < 0 or labels.max() > 65535):
        raise InputError(path, f"labels must lie in 0..65535 for a 16-bit PNG, got {labels.min()}..{labels.max()}")
    Image.fromarray(labels.astype(np.uint16)).save(path)
    return Path(path)


PALETTE = np.array([
    (31, 119, 180), (255, 127, 14), (44, 160, 44), (214, 39, 40), (148, 103, 189), (140, 86, 75), (227, 119, 194),
    (188, 189, 34), (23, 190, 207), (174, 199, 232), (255, 187, 120), (152, 223, 138), (255, 152, 150),
    (197, 176, 213), (196, 156, 148), (247, 182, 210), (219, 219, 141), (158, 218, 229)]) / 255.0
"""Room colours (matplotlib's tab20 without its greys, dark shades first), RGB in 0..1."""
FIGURE_MIN_PX = 1000
"""rooms.png is scaled up by a whole factor until it is at least this wide, px."""


def room_colours(labels, graph) -> np.ndarray:
    """RGB (H, W, 3) float: rooms coloured so that neighbours in ``graph`` differ,
    obstacles dark grey, unlabelled cells white."""
    colour = nx.greedy_color(graph, strategy="largest_first")
    lut = np.ones((int(labels.max()) + 1, 3))
    for n, c in colour.items():
        lut[n] = PALETTE[c % len(PALETTE)]
    return lut[labels]


def save_rooms_png(labels, free, graph, resolution, origin, row0_top, path, title=None) -> Path:
    """Image of the rooms (see :func:`room_colours`, unlabelled obstacles dark grey), north up, with the
    region graph over them (room centres as dots with their numbers, edges through portal squares),
    a 1 m / 5 m scale bar and ``title`` with the room count. Drawn with PIL from the label array
    itself (one pixel per cell, scaled up to FIGURE_MIN_PX): no plotting library is loaded."""
    rgb = room_colours(labels, graph)
    rgb[~np.asarray(free, bool) & (labels == 0)] = 0.25
    if not row0_top:
        rgb = rgb[::-1]  # north up
    h, w = labels.shape
    scale = max(1, -(-FIGURE_MIN_PX // max(w, 1)))
    band = 24  # px above the map for the title
    image = Image.new("RGB", (w * scale, h * scale + band), "white")
    image.paste(Image.fromarray((255 * rgb).astype(np.uint8)).resize((w * scale, h * scale), Image.NEAREST), (0, band))
    draw, font = ImageDraw.Draw(image), ImageFont.load_default(size=12)

    def px(xy) -> tuple[float, float]:
        return ((xy[0] - origin[0]) / resolution * scale, (origin[1] + h * resolution - xy[1]) / resolution * scale
                + band)  # fmt: skip

    r = max(2.0, 1.5 * scale)
    for a, b, d in graph.edges(data=True):
        points = [px(graph.nodes[a]["centre"]), px(d["portal_centre"]), px(graph.nodes[b]["centre"])]
        draw.line(points, fill="black", width=max(1, scale))
        x, y = points[1]
        draw.rectangle([x - r, y - r, x + r, y + r], fill="black")
    for n, d in graph.nodes(data=True):
        x, y = px(d["centre"])
        draw.ellipse([x - 2 * r, y - 2 * r, x + 2 * r, y + 2 * r], fill="black", outline="white")
        if graph.number_of_nodes() <= 80:
            draw.text((x + 2 * r + 1, y - 2 * r - 12), str(n), fill="black", font=font)
    metres = 5 if w * resolution >= 20 else 1
    x0, y0 = 10, h * scale + band - 12
    draw.line([(x0, y0), (x0 + metres / resolution * scale, y0)], fill="black", width=3)
    draw.text((x0, y0 - 15), f"{metres} m", fill="black", font=font)
    caption = f"{title}: {graph.number_of_nodes()} rooms" if title else f"{graph.number_of_nodes()} rooms"
    draw.text((6, 5), caption, fill="black", font=font)
    image.save(path, compress_level=1)
    return Path(path)
