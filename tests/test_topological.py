"""Region graph (topological map) from a room segmentation."""

from __future__ import annotations

import numpy as np
import pytest

from slam2d.errors import InputError
from slam2d.mapping.topological import cell_to_world, draw_graph, load_graph, region_graph, save_graph, world_to_cell
from slam2d.segmentation.baselines import voronoi

RES = 0.05
DOOR_ROWS = (51, 69)  # 18 rows: 0.9 m
WALL_COLS = (125, 130)


def two_rooms() -> np.ndarray:
    """Two 6 m x 6 m rooms side by side, a 0.9 m door in the 0.25 m wall between them."""
    free = np.zeros((130, 255), bool)
    free[5:125, 5:125] = True
    free[5:125, 130:250] = True
    free[DOOR_ROWS[0] : DOOR_ROWS[1], WALL_COLS[0] : WALL_COLS[1]] = True
    return free


@pytest.fixture(scope="module")
def graph():
    return region_graph(voronoi(two_rooms(), RES), RES, origin=(1.0, -2.0))


def test_two_rooms_one_portal_in_the_doorway(graph):
    assert graph.number_of_nodes() == 2 and graph.number_of_edges() == 1
    (a, b, e), = graph.edges(data=True)
    rows, cols = np.array(e["portal"]).T
    assert rows.min() >= DOOR_ROWS[0] and rows.max() < DOOR_ROWS[1]
    assert cols.min() >= WALL_COLS[0] - 1 and cols.max() <= WALL_COLS[1]
    assert e["width"] == pytest.approx(0.9, abs=RES)
    assert e["openings"] == 1
    x, y = e["portal_centre"]
    door_xy = cell_to_world(np.array([[np.mean(DOOR_ROWS) - 0.5, np.mean(WALL_COLS) - 0.5]]), (130, 255), RES,
                            (1.0, -2.0))[0]  # fmt: skip
    assert abs(y - door_xy[1]) <= 2 * RES and abs(x - door_xy[0]) <= 0.2
    ca, cb = np.array(graph.nodes[a]["centre"]), np.array(graph.nodes[b]["centre"])
    assert e["cost"] == pytest.approx(np.hypot(*(ca - (x, y))) + np.hypot(*(cb - (x, y))))


def test_nodes_are_inside_their_rooms(graph):
    labels = voronoi(two_rooms(), RES)
    for n, d in graph.nodes(data=True):
        r, c = d["centre_cell"]
        assert labels[r, c] == n
        assert np.allclose(d["centre"], cell_to_world((r, c), labels.shape, RES, (1.0, -2.0)))
        assert d["cells"] == (labels == n).sum() and d["area"] == pytest.approx(d["cells"] * RES**2)
    xs = sorted(d["centre"][0] for _, d in graph.nodes(data=True))
    assert xs[0] == pytest.approx(1.0 + 3.25, abs=0.3) and xs[1] == pytest.approx(1.0 + 9.5, abs=0.3)


def test_centre_of_a_ring_lies_in_the_ring():
    labels = np.zeros((50, 50), np.int32)
    labels[5:45, 5:45] = 1
    labels[12:38, 12:38] = 0  # a ring-shaped corridor: the centroid is in the hole
    g = region_graph(labels, 0.1)
    r, c = g.nodes[1]["centre_cell"]
    assert labels[r, c] == 1


def test_cell_world_conventions():
    shape, res, origin = (10, 20), 0.5, (2.0, 3.0)
    # image rows (row 0 = top): the bottom-left cell is (9, 0)
    assert np.allclose(cell_to_world((9, 0), shape, res, origin), (2.25, 3.25))
    assert np.allclose(cell_to_world((0, 19), shape, res, origin), (11.75, 7.75))
    # grid rows (row = y up, as OccupancyGrid): the bottom-left cell is (0, 0)
    assert np.allclose(cell_to_world((0, 0), shape, res, origin, row0_top=False), (2.25, 3.25))
    cells = np.array([[0, 0], [3, 7], [9, 19]])
    for top in (True, False):
        xy = cell_to_world(cells, shape, res, origin, row0_top=top)
        assert np.array_equal(world_to_cell(xy, shape, res, origin, row0_top=top), cells)


def test_grid_orientation_matches_occupancy_grid():
    from slam2d.mapping.grid import OccupancyGrid

    grid = OccupancyGrid(np.zeros((10, 20)), 0.5, (2.0, 3.0))
    cells = np.array([[0, 0], [3, 7], [9, 19]])
    assert np.allclose(cell_to_world(cells, grid.shape, 0.5, grid.origin, row0_top=False), grid.cell_to_world(cells))


def test_json_round_trip_is_exact(graph, tmp_path):
    path = save_graph(graph, tmp_path / "g" / "rooms_graph.json")
    back = load_graph(path)
    assert back.graph == graph.graph
    assert dict(back.nodes(data=True)) == dict(graph.nodes(data=True))
    assert sorted(back.edges(data=True)) == sorted(graph.edges(data=True))
    edge = next(iter(back.edges(data=True)))[2]
    assert isinstance(back.nodes[1]["centre"], tuple) and isinstance(edge["portal"][0], tuple)


def test_touching_diagonally_counts_and_bad_input(tmp_path):
    labels = np.array([[1, 1, 0], [1, 1, 0], [0, 0, 2]], np.int32)
    g = region_graph(labels, 0.1)
    assert g.number_of_edges() == 1 and g.edges[1, 2]["width"] == pytest.approx(0.1)
    assert region_graph(np.zeros((4, 4), np.int32), 0.1).number_of_nodes() == 0
    with pytest.raises(InputError):
        region_graph(np.zeros((4, 4)), 0.1)  # float labels
    with pytest.raises(InputError, match="not found"):
        load_graph(tmp_path / "missing.json")
    (tmp_path / "bad.json").write_text("{}")
    with pytest.raises(InputError):
        load_graph(tmp_path / "bad.json")


def test_draw_graph(graph):
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure()
    FigureCanvasAgg(fig)
    ax = fig.add_subplot()
    draw_graph(ax, graph)
    assert len(ax.lines) == 2 * graph.number_of_edges()
    fig.canvas.draw()
