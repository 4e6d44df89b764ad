"""Room segmentation scores against ground truth (Bormann et al. ICRA 2016 definition)."""

from __future__ import annotations

import numpy as np
import pytest
from PIL import Image
from scipy import ndimage

from slam2d.errors import InputError
from slam2d.segmentation.evaluate import contingency, load_floor_plan, load_ground_truth, score


def two_rooms_gt() -> np.ndarray:
    """GT labels: room 1 at [0:20, 0:20] and room 2 at [0:20, 21:41] (400 px each), column 20 a wall."""
    gt = np.zeros((20, 41), dtype=np.int32)
    gt[:, :20] = 1
    gt[:, 21:] = 2
    return gt


def test_perfect_segmentation_scores_100_whatever_the_label_values():
    gt = two_rooms_gt()
    labels = np.where(gt == 1, 42, np.where(gt == 2, 7, 0))
    assert score(labels, gt) == dict(recall=100.0, precision=100.0, rooms_found=2, rooms_gt=2)


def test_one_segment_over_two_rooms_halves_precision():
    gt = two_rooms_gt()
    labels = (gt > 0).astype(int)  # one segment of 800 px
    s = score(labels, gt)
    assert s["recall"] == pytest.approx(100.0)
    assert s["precision"] == pytest.approx(50.0)
    assert (s["rooms_found"], s["rooms_gt"]) == (1, 2)


def test_split_room_halves_its_recall():
    gt = two_rooms_gt()
    labels = gt.copy()
    labels[10:, :20] = 3  # room 1 cut into two segments of 200 px
    s = score(labels, gt)
    assert s["recall"] == pytest.approx((50.0 + 100.0) / 2)
    assert s["precision"] == pytest.approx(100.0)
    assert s["rooms_found"] == 3


def test_segment_pixels_outside_rooms_count_against_precision():
    gt = two_rooms_gt()
    labels = gt.copy()
    labels[:, 20] = 1  # the wall column joins segment 1: 420 px, 400 inside room 1
    s = score(labels, gt)
    assert s["recall"] == pytest.approx(100.0)
    assert s["precision"] == pytest.approx((400 / 420 * 100 + 100) / 2)


def test_segments_and_rooms_of_at_most_100_px_are_ignored():
    gt = two_rooms_gt()
    gt[0:10, 0:10] = 0
    gt = np.where(gt > 0, gt, 0)
    gt[0:10, 0:10] = 3  # a 100 px GT room: dropped
    labels = gt.copy()
    labels[19, 30:40] = 9  # a 10 px segment inside room 2: dropped
    s = score(labels, gt)
    assert s["rooms_gt"] == 2 and s["rooms_found"] == 2
    assert s["recall"] == pytest.approx((300 / 300 * 100 + 390 / 400 * 100) / 2)
    assert s["precision"] == pytest.approx(100.0)


def test_no_segments_scores_zero():
    gt = two_rooms_gt()
    assert score(np.zeros_like(gt), gt) == dict(recall=0.0, precision=0.0, rooms_found=0, rooms_gt=2)


def test_contingency_counts_label_pairs():
    gt = two_rooms_gt()
    labels = np.where(gt == 2, 5, 0)
    c = contingency(labels, gt)
    assert c.shape == (2, 3)
    assert c[1, 2] == 400 and c[0, 1] == 400 and c[0, 0] == 20 and c.sum() == gt.size


def test_shape_mismatch_is_an_input_error():
    with pytest.raises(InputError, match="shape"):
        score(np.zeros((3, 3), int), np.zeros((3, 4), int))


def test_load_ground_truth_synthetic(tmp_path):
    img = np.zeros((40, 60), dtype=np.uint8)
    img[2:20, 2:20] = 255  # room (324 px)
    img[20:38, 20:40] = 255  # touches the first only diagonally -> same 8-connected room
    img[2:20, 45:58] = 251  # a second room (> 250)
    img[30:35, 50:55] = 255  # a 25 px speck: dropped
    img[25:30, 2:20] = 250  # exactly 250 is not a room
    path = tmp_path / "gt.png"
    Image.fromarray(img).save(path)
    gt = load_ground_truth(path)
    assert gt.dtype == np.int32 and gt.shape == img.shape
    assert gt.max() == 2
    assert gt[5, 5] == gt[30, 30] != 0
    assert gt[5, 50] not in (0, gt[5, 5])
    assert gt[32, 52] == 0 and gt[27, 5] == 0


def test_load_floor_plan_threshold(tmp_path):
    img = np.array([[0, 249, 250, 255]], dtype=np.uint8)
    path = tmp_path / "map.png"
    Image.fromarray(img).save(path)
    free, res = load_floor_plan(path)
    assert res == 0.05
    assert free.tolist() == [[False, False, True, True]]


def test_missing_file_is_an_input_error(tmp_path):
    with pytest.raises(InputError, match="not found"):
        load_floor_plan(tmp_path / "nope.png")


def test_load_ground_truth_on_a_real_map(data_file):
    path = data_file("rooms/office_a_gt_segmentation.png")
    gt = load_ground_truth(path)
    rooms = gt.max()
    assert rooms > 1
    sizes = np.bincount(gt.ravel())[1:]
    assert len(sizes) == rooms and sizes.min() > 100  # numbered 1..R, small rooms dropped
    gray = np.asarray(Image.open(path).convert("L"))
    raw, n = ndimage.label(gray > 250, structure=np.ones((3, 3)))
    raw_sizes = np.bincount(raw.ravel())[1:]
    assert rooms == int((raw_sizes > 100).sum()) <= n
    assert score(gt, gt)["recall"] == 100.0
