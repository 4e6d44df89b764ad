"""Segment one map into rooms and write the results folder (``slam2d segment``).

:func:`segment_map` reads a floor-plan image (free = gray >= 250, 0.05 m/px
unless ``resolution`` is given; row 0 is the top) or a map_server map
(``map.yaml``: free = occupancy probability < ``free_thresh``), runs a method
(``spectral`` with a similarity measure, or a baseline of
:mod:`slam2d.segmentation.baselines`), builds the topological map and writes

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

import json
import time
from pathlib import Path

import numpy as np

from slam2d.errors import InputError
from slam2d.runs.results import json_text

__all__ = [
    "run_segment", "segment_map", "segment_free", "METHODS", "find_ground_truth", "load_map", "save_labels_png",
    "save_rooms_png", "room_colours",
]

METHODS = ("spectral", "morphological", "distance", "voronoi")
"""Method names :func:`segment_map` accepts."""


FURNISHED_SUFFIX = "_furnitures"
GT_SUFFIX = "_gt_segmentation.png"


def load_map(map_path, resolution: float | None = None) -> dict:
    """Free space of a floor-plan image or a map_server YAML.

    Returns ``dict(free (H, W) bool, resolution m, origin (x, y) m, row0_top)``;
    ``row0_top`` is False for YAML maps, whose grid rows run up in y (as
    :class:`slam2d.mapping.occupancy.OccupancyGrid`).
    """
    path = Path(map_path)
    if not path.is_file():
        raise InputError(path, "map file not found")
    if path.suffix.lower() in (".yaml", ".yml"):
        import yaml

        from slam2d.mapping.export import load_map_server

        grid = load_map_server(path)
        free_thresh = float(yaml.safe_load(path.read_text())["free_thresh"])
        return dict(free=grid.free_mask(free_thresh), resolution=grid.resolution, origin=grid.origin, row0_top=False)
    from slam2d.segmentation.evaluate import load_floor_plan

    free, res = load_floor_plan(path)
    if resolution is not None:
        if not resolution > 0:
            raise InputError("resolution", f"must be > 0 m/px, got {resolution}")
        res = float(resolution)
    return dict(free=free, resolution=float(res), origin=(0.0, 0.0), row0_top=True)


def find_ground_truth(map_path) -> Path | None:
    """``<stem>_gt_segmentation.png`` beside the map (the unfurnished stem's for ``*_furnitures``), or None."""
    path = Path(map_path)
    stem = path.stem
    if stem.endswith(FURNISHED_SUFFIX):
        stem = stem[: -len(FURNISHED_SUFFIX)]
    gt = path.with_name(stem + GT_SUFFIX)
    return gt if gt.is_file() else None


def segment_free(free, resolution, method, similarity="visibility", params=None) -> tuple[np.ndarray, dict]:
    """Labels (H, W) int32 of the free space ``free`` (H, W) bool at ``resolution`` m/cell by ``method``
    (with ``similarity`` for spectral, and the method's ``params``), and run facts (seconds, cpu_seconds;
    k, silhouette and similarity for spectral)."""
    cpu0 = time.process_time()
    run = _run_method(free, resolution, method, similarity, params or {})
    run["cpu_seconds"] = time.process_time() - cpu0
    return run.pop("labels"), run


def _run_method(free, resolution, method, similarity, params) -> dict:
    """Labels (H, W) int32 and run facts (seconds; k and silhouette for spectral)."""
    if method == "spectral":
        from slam2d.segmentation.similarity import SIMILARITIES
        from slam2d.segmentation.spectral import segment_spectral

        from slam2d.segmentation.config import SIMILARITY_ALIASES

        similarity = SIMILARITY_ALIASES.get(similarity, similarity)
        if similarity not in SIMILARITIES:
            raise InputError("similarity", f"unknown measure {similarity!r}; choose from {sorted(SIMILARITIES)}")
        res = segment_spectral(free, resolution, similarity=similarity, **params)
        return dict(labels=np.asarray(res.labels, np.int32), seconds=float(res.seconds), k=int(res.k),
                    silhouette=float(res.silhouette), similarity=similarity)  # fmt: skip
    from slam2d.segmentation.baselines import BASELINES

    if method not in BASELINES:
        raise InputError("method", f"unknown method {method!r}; choose from {list(METHODS)}")
    t0 = time.perf_counter()
    try:
        labels = BASELINES[method](free, resolution, **params)
    except TypeError as exc:  # an unknown keyword
        raise InputError("params", f"{method}: {exc}") from None
    return dict(labels=labels, seconds=time.perf_counter() - t0)


def run_segment(cfg) -> Path:
    """Run a :class:`~slam2d.segmentation.config.SegmentConfig` into a new results folder under
    ``cfg.output.root`` (resolved config, labels, figures, metrics, log); return the folder."""
    from slam2d import config as config_mod
    from slam2d.datasets.registry import resolve_data_path
    from slam2d.runs.results import results_folder

    if cfg.map is None:
        raise InputError("map", "no map given (map: FILE in the config, or slam2d segment MAP)")
    map_path = resolve_data_path(cfg.map, key="map")
    gt = resolve_data_path(cfg.ground_truth, key="ground_truth") if cfg.ground_truth else None
    seg = cfg.segmentation
    params = {"seed": cfg.seed, **seg.params} if seg.method == "spectral" else seg.params
    name = cfg.name or f"segment-{map_path.stem}-{seg.method}"
    with results_folder(cfg.output.root, name) as (work, published):
        (work / "config.yaml").write_text(config_mod.dump(cfg))
        segment_map(map_path, seg.method, seg.similarity, work, ground_truth=gt, resolution=cfg.resolution,
                    figures=cfg.output.figures, **params)
    return published[0]


def segment_map(map_path, method="spectral", similarity="visibility", out_dir=None, *, ground_truth=None,
                resolution=None, figures=True, **params) -> dict:
    """Segment the map at ``map_path`` into rooms and write the results into ``out_dir``.

    method: one of :data:`METHODS`; similarity: the spectral measure (ignored by
    the baselines); out_dir: results folder (default ``results/segment-<stem>-<method>-<time>``);
    ground_truth: GT image (default: found beside the map, see :func:`find_ground_truth`);
    resolution: m/px for an image map (default 0.05); figures: write ``rooms.png``; params: the
    method's parameters. Returns the metrics written to ``metrics.json`` (plus ``out_dir``):
    ``seconds`` (wall) and ``cpu_seconds`` of the segmentation itself, ``furnished`` (the map is a
    ``*_furnitures`` variant), rooms, portals, and the scores against a ground truth.
    """
    from slam2d.mapping.topological import region_graph, save_graph

    map_path = Path(map_path)
    if method not in METHODS:
        raise InputError("method", f"unknown method {method!r}; choose from {list(METHODS)}")
    m = load_map(map_path, resolution)
    if not m["free"].any():
        raise InputError(map_path, "no free cell: nothing to segment (check the image, negate and free_thresh)")
    labels, run = segment_free(m["free"], m["resolution"], method, similarity, params)
    graph = region_graph(labels, m["resolution"], m["origin"], row0_top=m["row0_top"])
    out = Path(out_dir) if out_dir is not None else _default_out_dir(map_path, method)
    out.mkdir(parents=True, exist_ok=True)
    image_labels = labels if m["row0_top"] else np.flipud(labels)
    save_labels_png(image_labels, out / "labels.png")
    save_graph(graph, out / "rooms_graph.json")
    if figures:
        title = f"{map_path.stem}: {method}" + (f" ({run['similarity']})" if "similarity" in run else "")
        save_rooms_png(labels, m["free"], graph, m["resolution"], m["origin"], m["row0_top"], out / "rooms.png",
                       title=title)
    metrics = dict(map=str(map_path), furnished=map_path.stem.endswith(FURNISHED_SUFFIX), method=method, **run,
                   rooms=graph.number_of_nodes(), portals=graph.number_of_edges(), params=_params_jsonable(params))
    metrics.update(_score(image_labels, ground_truth, map_path))
    (out / "metrics.json").write_text(json_text(metrics))
    return dict(metrics, out_dir=str(out))


def _score(image_labels, ground_truth, map_path) -> dict:
    """Recall, precision, rooms found / in GT against the given or found GT image; {} without one."""
    gt_path = Path(ground_truth) if ground_truth is not None else find_ground_truth(map_path)
    if gt_path is None:
        return {}
    from slam2d.segmentation.evaluate import load_ground_truth, score

    gt = load_ground_truth(gt_path)
    if gt.shape != image_labels.shape:
        raise InputError(gt_path, f"ground truth is {gt.shape[1]}x{gt.shape[0]} px, the map "
                                  f"{image_labels.shape[1]}x{image_labels.shape[0]}")  # fmt: skip
    return dict(score(image_labels, gt), ground_truth=str(gt_path))


def _default_out_dir(map_path: Path, method: str) -> Path:
    stamp = time.strftime("%Y%m%d-%H%M%S")
    out = Path("results") / f"segment-{map_path.stem}-{method}-{stamp}"
    n = 1
    while out.exists():
        out, n = out.with_name(f"segment-{map_path.stem}-{method}-{stamp}-{n}"), n + 1
    return out


def _params_jsonable(params: dict) -> dict:
    """Parameters with anything JSON cannot hold given as its repr."""
    out = {}
    for k, v in params.items():
        try:
            json.dumps(v)
            out[k] = v
        except TypeError:
            out[k] = repr(v)
    return out


def save_labels_png(labels, path) -> Path:
    """Write labels (H, W) (0..65535) as a 16-bit grayscale PNG; read back with PIL + ``np.asarray``."""
    from PIL import Image

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
    import networkx as nx

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
    from PIL import Image, ImageDraw, ImageFont

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
