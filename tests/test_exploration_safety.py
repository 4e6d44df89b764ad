"""The exploring robot's safety margin: it keeps ``exploration.safety_margin`` (5 cm) between its disc and the
walls, through a doorway with little more room than that, and still explores both rooms."""

import numpy as np
import pytest

from slam2d.exploration import config as explore_config
from slam2d.exploration.loop import explore


def narrow_door_png(tmp_path, door: float = 0.7):
    """Two 4 x 3 m rooms joined by a door ``door`` m wide in a wall 0.2 m thick, 5 cm pixels; a partition in the
    second room (x = 5.5 m, y 1.5-3.5 m) hides most of it from the door."""
    from PIL import Image

    img = np.zeros((80, 180), dtype=np.uint8)
    img[10:70, 10:90] = 255  # room A: x 0.5-4.5, y 0.5-3.5 (rows from the top)
    img[10:70, 94:170] = 255  # room B: x 4.7-8.5
    half = round(door / 0.05) // 2
    img[40 - half:40 + half, 88:96] = 255  # the door, centred at y = 2 m
    img[10:50, 110:113] = 0  # the partition
    path = tmp_path / "narrow_door.png"
    Image.fromarray(img).save(path)
    return path


@pytest.mark.parametrize("strategy", ["nearest_frontier"])
def test_the_margin_holds_through_a_narrow_doorway_and_both_rooms_are_explored(tmp_path, strategy):
    cfg = explore_config.load(None, {
        "dataset.simulator.world": str(narrow_door_png(tmp_path)), "seed": 1, "exploration.strategy": strategy,
        "exploration.start": [1.5, 2.0, 0.0], "exploration.max_time": 200, "exploration.animation": False,
    })  # fmt: skip
    run = explore(cfg)
    m = run.metrics
    assert m["coverage"] >= 0.99 and m["collisions"] == 0 and not m["premature_stop"]
    assert (run.truth[:, 0] > 6.0).any()  # through the door and round the partition
    assert m["min_clearance"] >= cfg.exploration.safety_margin  # 5 cm from every wall, the door's jambs too
