"""Room-segmentation baselines, segment_map and its results folder."""

from __future__ import annotations

import json

import numpy as np
import pytest
from PIL import Image

from slam2d.errors import InputError
from slam2d.segmentation.baselines import BASELINES, grow_regions, voronoi
from slam2d.runs.segment import write_segmentation
from slam2d.segmentation.rooms import find_ground_truth, segment_map

RES = 0.05
DOOR = slice(51, 69)  # 18 rows: a 0.9 m door


def two_rooms() -> np.ndarray:
    """Two 6 m x 6 m rooms (0.05 m cells) side by side, a 0.9 m door in the 0.25 m wall between them.

    Together they exceed the morphological method's 47 m² room bound, as real flats do.
    """
    free = np.zeros((130, 255), bool)
    free[5:125, 5:125] = True
    free[5:125, 130:250] = True
    free[DOOR, 125:130] = True
    return free


@pytest.mark.parametrize("name", sorted(BASELINES))
def test_two_rooms_split_at_the_door(name):
    free = two_rooms()
    labels = BASELINES[name](free, RES)
    assert labels.dtype == np.int32 and labels.shape == free.shape
    assert (labels[free] > 0).all() and (labels[~free] == 0).all()
    assert set(np.unique(labels[free])) == {1, 2}
    left, right = labels[60, 60], labels[60, 190]
    assert left != right
    assert (labels[5:125, 5:120] == left).mean() > 0.99
    assert (labels[5:125, 135:250] == right).mean() > 0.99


def test_grow_regions_labels_every_free_cell():
    free = np.zeros((20, 30), bool)
    free[2:18, 2:12] = True
    free[2:18, 15:28] = True  # a second component without a seed
    seeds = np.zeros(free.shape, int)
    seeds[5, 5] = 7
    labels = grow_regions(seeds, free)
    assert (labels[free] > 0).all() and (labels[~free] == 0).all()
    assert set(np.unique(labels[free])) == {1, 2}
    assert (labels[2:18, 2:12] == 1).all()


def test_voronoi_repeats_exactly():
    free = two_rooms()
    free[20:30, 20:30] = False  # an obstacle, so the medial axis has ties to break
    assert np.array_equal(voronoi(free, RES), voronoi(free, RES))


def test_bad_input():
    with pytest.raises(ValueError, match="2-D"):
        BASELINES["morphological"](np.ones((4, 4, 3), bool), RES)
    with pytest.raises(ValueError, match="resolution"):
        BASELINES["distance"](two_rooms(), 0.0)


# Measured on lab_ipa (recall, precision %): morphological 96.8 / 92.8,
# distance 93.6 / 95.8, voronoi 98.4 / 92.2; bounds a little below.
BOUNDS = {"morphological": (95.0, 91.0), "distance": (92.0, 94.0), "voronoi": (97.0, 90.5)}


@pytest.mark.parametrize("name", sorted(BOUNDS))
def test_real_map_reaches_measured_scores(name, data_file):
    from slam2d.segmentation.evaluate import load_floor_plan, load_ground_truth, score

    free, res = load_floor_plan(data_file("rooms/lab_ipa.png"))
    gt = load_ground_truth(data_file("rooms/lab_ipa_gt_segmentation.png"))
    s = score(BASELINES[name](free, res), gt)
    recall, precision = BOUNDS[name]
    assert s["recall"] >= recall and s["precision"] >= precision, s


def _write_plan(tmp_path, stem="plan"):
    """Two-room floor plan PNG (white free, black walls) and its GT image beside it."""
    free = two_rooms()
    Image.fromarray(np.where(free, 255, 0).astype(np.uint8)).save(tmp_path / f"{stem}.png")
    gt = free.copy()
    gt[:, 125:130] = False  # the door line separates the GT rooms
    Image.fromarray(np.where(gt, 255, 0).astype(np.uint8)).save(tmp_path / f"{stem}_gt_segmentation.png")
    return tmp_path / f"{stem}.png"


def test_segment_map_writes_results(tmp_path):
    plan = _write_plan(tmp_path)
    out = tmp_path / "out"
    rooms = segment_map(plan, method="voronoi")
    write_segmentation(rooms, out)
    m = rooms.metrics
    for name in ("rooms.png", "rooms_graph.json", "labels.png", "metrics.json"):
        assert (out / name).is_file(), name
    saved = json.loads((out / "metrics.json").read_text())
    assert saved["rooms"] == 2 and saved["portals"] == 1 and saved["rooms_gt"] == 2
    assert saved["recall"] > 95 and saved["precision"] > 95
    assert m["recall"] == saved["recall"]
    labels = np.asarray(Image.open(out / "labels.png"))
    assert labels.shape == (130, 255) and set(np.unique(labels)) == {0, 1, 2}


def test_segment_map_reads_map_server_yaml(tmp_path):
    free = two_rooms()
    Image.fromarray(np.where(free, 254, 0).astype(np.uint8)).save(tmp_path / "map.pgm")
    (tmp_path / "map.yaml").write_text(
        "image: map.pgm\nresolution: 0.05\norigin: [-1.0, 2.0, 0.0]\nnegate: 0\n"
        "occupied_thresh: 0.65\nfree_thresh: 0.196\n"
    )
    rooms = segment_map(tmp_path / "map.yaml", method="morphological")
    write_segmentation(rooms, tmp_path / "out")
    m = rooms.metrics
    assert m["rooms"] == 2 and "recall" not in m
    labels = np.asarray(Image.open(tmp_path / "out" / "labels.png"))
    assert np.array_equal(labels > 0, free)  # written in the image's orientation
    from slam2d.mapping.topological import load_graph

    g = load_graph(tmp_path / "out" / "rooms_graph.json")
    xs = sorted(d["centre"][0] for _, d in g.nodes(data=True))
    assert -1.0 + 0.25 < xs[0] < -1.0 + 6.25 < xs[1] < -1.0 + 12.5
    assert abs(xs[0] - 2.25) < 0.5 and abs(xs[1] - 8.5) < 0.5
    ys = [d["centre"][1] for _, d in g.nodes(data=True)]
    assert all(abs(y - (2.0 + 3.25)) < 0.5 for y in ys)  # rows 5..124 of 130, y up


def test_find_ground_truth_for_furnished_maps(tmp_path):
    plan = _write_plan(tmp_path, "office")
    furnished = tmp_path / "office_furnitures.png"
    furnished.write_bytes(plan.read_bytes())
    assert find_ground_truth(furnished) == tmp_path / "office_gt_segmentation.png"
    assert find_ground_truth(tmp_path / "other.png") is None


def test_segment_map_rejects_unknown_names(tmp_path):
    plan = _write_plan(tmp_path)
    with pytest.raises(InputError, match="method"):
        segment_map(plan, method="watershed")
    with pytest.raises(InputError, match="similarity"):
        segment_map(plan, method="spectral", similarity="cosine")
    with pytest.raises(InputError, match="not found"):
        segment_map(tmp_path / "missing.png", method="voronoi")


def test_segment_map_spectral(tmp_path):
    plan = _write_plan(tmp_path)
    rooms = segment_map(plan, method="spectral", similarity="nearest_neighbor", params={"k_max": 4})
    write_segmentation(rooms, tmp_path / "out")
    m = rooms.metrics
    assert m["similarity"] == "nearest_neighbour" and m["k"] >= 1 and m["rooms"] >= 1
    saved = json.loads((tmp_path / "out" / "metrics.json").read_text())
    assert "silhouette" in saved and saved["params"] == {"k_max": 4}
