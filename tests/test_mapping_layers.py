"""Mapping layers: sparse and quadtree storage, the line map, the wall mesh."""

from __future__ import annotations

import numpy as np
import pytest

from slam2d.mapping.grid import OccupancyGrid


def _grid(seed: int = 0) -> OccupancyGrid:
    """A 60 x 90 grid: unknown, free and occupied cells with arbitrary float32 log-odds."""
    rng = np.random.default_rng(seed)
    lo = np.zeros((60, 90), np.float32)
    lo[5:55, 5:85] = rng.uniform(-2.0, -0.1, (50, 80))
    lo[5, 5:85] = lo[54, 5:85] = lo[5:55, 5] = rng.uniform(0.5, 3.5)
    return OccupancyGrid(lo, 0.05, (-1.25, 3.5))


# --------------------------------------------------------------------------- sparse


def test_triplets_and_hash_round_trip_bit_exact():
    from slam2d.mapping.sparse import HashedGrid, Triplets

    grid = _grid()
    for form in (Triplets.from_grid(grid), HashedGrid.from_grid(grid)):
        back = form.to_grid()
        assert back.log_odds.tobytes() == grid.log_odds.tobytes()
        assert back.resolution == grid.resolution and back.origin == grid.origin
        assert len(form) == np.count_nonzero(grid.log_odds)
    t = Triplets.from_grid(grid)
    assert np.array_equal(t.to_scipy().toarray(), grid.log_odds)
    h = HashedGrid.from_grid(grid)
    assert h[5, 5] == grid.log_odds[5, 5] and h[0, 0] == 0.0
    with pytest.raises(IndexError):
        h[60, 0]


def test_sparsity_reports_the_five_percent_rule():
    from slam2d.mapping.sparse import sparsity

    s = sparsity(_grid())
    assert s["nonzero_share"] == pytest.approx(50 * 80 / (60 * 90))
    assert not s["nonzero_sparse"]
    assert s["occupied_share"] == pytest.approx((80 + 80 + 48) / (60 * 90)) and s["occupied_sparse"]


# --------------------------------------------------------------------------- quadtree


def _thesis_tree():
    """Root [-1, 2] x [-1, 2] m (extent 1 m + 200 %), 1024 cells a side; its centre is (0.5, 0.5)."""
    from slam2d.mapping.quadtree import QuadTree

    return QuadTree.from_points([[0.0, 0.0], [1.0, 1.0], [0.5, 1.0]], max_depth=10)


def _cell_centre(tree, ix, iy):
    return tree.corner[0] + (ix + 0.5) * tree.cell, tree.corner[1] + (iy + 0.5) * tree.cell


def test_quadtree_root_and_the_quadrant_boundary():
    from slam2d.mapping.quadtree import Outcome

    tree = _thesis_tree()
    assert tree.corner == (-1.0, -1.0) and tree.side == 3.0 and tree.depth == 10
    # x == xMid, y > yMid: the upper right child, as its region says (the thesis sent it lower right)
    assert tree.quadrants(0.5, 1.0)[0] == 1
    assert tree.quadrants(0.5, 0.5)[0] == 1 and tree.quadrants(0.4999, 0.5)[0] == 2
    assert tree.quadrants(0.4999, 0.4999)[0] == 3 and tree.quadrants(0.5, 0.4999)[0] == 4
    assert tree.find(0.5, 1.0) == Outcome.OCCUPIED
    assert tree.find(2.0, 0.0) == Outcome.OUTSIDE and tree.find(-1.0, -1.0) == Outcome.FREE


def test_quadtree_find_has_three_outcomes():
    from slam2d.mapping.quadtree import Outcome

    tree = _thesis_tree()
    ix, iy = (int(v[0]) for v in tree._lattice(np.array([[0.0, 0.0]])))
    assert (ix, iy) == (341, 341)
    assert tree.find(0.0, 0.0) == Outcome.OCCUPIED
    assert tree.find(*_cell_centre(tree, 340, 341)) == Outcome.NEAR  # a sibling of the occupied cell
    assert tree.find(*_cell_centre(tree, 342, 341)) == Outcome.FREE  # the next cell, another parent
    assert tree.find(1.8, -0.8) == Outcome.FREE


def test_quadtree_insert_and_delete_collapse_empty_siblings():
    from slam2d.mapping.quadtree import Outcome, QuadTree

    tree = _thesis_tree()
    n0 = tree.node_count
    sibling = _cell_centre(tree, 340, 341)
    tree.insert(*sibling)
    assert tree.node_count == n0 + 1 and tree.find(*sibling) == Outcome.OCCUPIED  # one leaf beside (0, 0)
    tree.insert(1.8, -0.8)
    assert tree.node_count == n0 + 1 + 10  # an empty root quadrant: a new branch, levels 1 to 10
    assert tree.delete(1.8, -0.8) and tree.node_count == n0 + 1  # the whole branch collapses
    assert tree.delete(0.0, 0.0) and tree.node_count == n0
    assert tree.find(0.0, 0.0) == Outcome.NEAR  # its sibling is still there
    assert tree.delete(*sibling) and not tree.delete(*sibling)
    assert tree.find(0.0, 0.0) == Outcome.FREE and tree.find(*sibling) == Outcome.FREE
    rest = QuadTree(tree.corner, tree.cell, tree.depth, *tree.cells()[:2])
    assert tree.node_count == rest.node_count == QuadTree.from_bytes(tree.to_bytes()).node_count
    capacity = len(tree.children)
    tree.insert(0.0, 0.0)  # freed nodes are reused
    assert tree.find(0.0, 0.0) == Outcome.OCCUPIED and len(tree.children) == capacity
    assert tree.node_count == QuadTree(tree.corner, tree.cell, tree.depth, *tree.cells()[:2]).node_count == n0


def test_quadtree_rebuilds_on_growth_and_keeps_its_cells():
    from slam2d.mapping.quadtree import Outcome

    tree = _thesis_tree()
    before = tree.find_many([[0.0, 0.0], [1.0, 1.0], [0.5, 1.0]])
    assert tree.find(30.0, -5.0) == Outcome.OUTSIDE
    n0 = tree.node_count
    tree.insert(30.0, -5.0)  # a noise point far out
    assert tree.find(30.0, -5.0) == Outcome.OCCUPIED
    assert np.array_equal(tree.find_many([[0.0, 0.0], [1.0, 1.0], [0.5, 1.0]]), before)
    assert tree.cell == 3.0 / 1024 and tree.side >= 3 * 31.0 and tree.depth > 10
    assert tree.node_count < n0 + 3 * tree.depth  # absorbed by a few branches


def test_quadtree_of_a_grid_round_trips_and_batches():
    from slam2d.mapping.quadtree import Outcome, QuadTree

    rng = np.random.default_rng(3)
    mask = rng.random((70, 130)) < 0.03
    tree = QuadTree.from_mask(mask, 0.05, (-2.0, 1.0))
    assert tree.depth == 9 and np.array_equal(tree.to_mask(), mask)
    back = QuadTree.from_bytes(tree.to_bytes())
    assert np.array_equal(back.to_mask(), mask) and back.node_count == tree.node_count
    assert len(tree.to_bytes()) < mask.size // 10
    rows, cols = np.indices(mask.shape)
    assert np.array_equal(tree[rows, cols], mask) and tree[0, 0] == mask[0, 0]
    xy = rng.uniform([-4.0, -1.0], [6.0, 6.0], (20_000, 2))  # inside, around and outside the grid
    col, row = np.floor((xy[:, 0] + 2.0) / 0.05).astype(int), np.floor((xy[:, 1] - 1.0) / 0.05).astype(int)
    inside = (row >= 0) & (row < 70) & (col >= 0) & (col < 130)
    dense = np.zeros(len(xy), bool)
    dense[inside] = mask[row[inside], col[inside]]
    assert np.array_equal(tree.occupied(xy), dense)
    assert np.all(tree.find_many([[np.nan, 0.0], [1e9, 0.0]]) == Outcome.OUTSIDE)
    with pytest.raises(ValueError, match="magic"):
        QuadTree.from_bytes(b"XXXX" + tree.to_bytes()[4:])


def test_quadtree_stream_prunes_blocks_that_are_all_occupied():
    """A floor plan's dark surroundings are one big occupied region: its blocks are written as
    single codes (lab_ipa's stream was 13.75 % of the dense grid), and read back bit-exact."""
    from slam2d.mapping.quadtree import QuadTree

    rng = np.random.default_rng(5)
    mask = np.ones((300, 260), bool)
    mask[40:260, 30:230] = rng.random((220, 200)) < 0.02  # a building inside a dark background
    tree = QuadTree.from_mask(mask, 0.05)
    data = tree.to_bytes()
    assert data[:4] == b"QT02" and len(data) < mask.size // 10
    back = QuadTree.from_bytes(data)
    assert np.array_equal(back.to_mask(), mask) and back.node_count == tree.node_count
    sparse = QuadTree.from_mask(mask[40:260, 30:230], 0.05)  # no full blocks: the 4-bit masks are smaller
    assert sparse.to_bytes()[:4] == b"QT01"
    for edge in (np.zeros((5, 7), bool), np.ones((5, 7), bool)):
        assert np.array_equal(QuadTree.from_bytes(QuadTree.from_mask(edge, 0.1).to_bytes()).to_mask(), edge)
    with pytest.raises(ValueError, match="truncated"):
        QuadTree.from_bytes(data[:-40])


def test_an_empty_quadtree_has_nothing_near():
    from slam2d.mapping.quadtree import Outcome, QuadTree

    tree = QuadTree.from_mask(np.zeros((4, 4), bool), 0.5)
    assert tree.node_count == 1 and tree.find(1.0, 1.0) == Outcome.FREE and not tree[0, 0]
    tree.insert(1.0, 1.0)
    assert tree.find(1.0, 1.0) == Outcome.OCCUPIED and tree.delete(1.0, 1.0) and tree.node_count == 1


def test_trinary_quadtree_round_trips_and_prunes_uniform_children():
    from slam2d.mapping.quadtree import _TRI_HEADER, decode_trinary, encode_trinary, trinary_values

    rng = np.random.default_rng(5)
    for shape in [(1, 1), (3, 5), (17, 9), (64, 64)]:
        v = rng.integers(0, 3, shape).astype(np.uint8)
        assert np.array_equal(decode_trinary(encode_trinary(v)), v)
    assert len(encode_trinary(np.zeros((64, 64), np.uint8))) == _TRI_HEADER.size + 1  # one leaf: the root
    v = np.full((64, 64), 2, np.uint8)
    v[:32, 32:] = 0  # one free quadrant (lower right), the rest unknown
    assert len(encode_trinary(v)) == _TRI_HEADER.size + 2  # the root (mixed) and its four children
    v[40, 3] = 1
    assert np.array_equal(decode_trinary(encode_trinary(v)), v)
    assert np.array_equal(trinary_values(_grid()), np.where(_grid().occupied_mask(), 1,
                                                            np.where(_grid().free_mask(), 0, 2)))
    with pytest.raises(ValueError):
        encode_trinary(np.full((2, 2), 3, np.uint8))


def test_quadtree_figure_draws(tmp_path):
    from slam2d.mapping.quadtree import draw_tree

    assert draw_tree(_thesis_tree(), tmp_path / "tree.png").stat().st_size > 1000


# --------------------------------------------------------------------------- line map


def test_collinear_overlapping_segments_merge_into_one():
    from slam2d.mapping.geometric import merge_collinear

    seg = np.array([[[0.0, 0.0], [2.0, 0.01]], [[3.0, 0.0], [1.5, 0.0]], [[0.0, 1.0], [1.0, 1.0]]])
    out = merge_collinear(seg, angle_tol_deg=3.0, offset_tol=0.05, gap=0.1)
    assert len(out) == 2  # the parallel one a metre away stays apart
    long = out[np.argmax(np.linalg.norm(out[:, 1] - out[:, 0], axis=1))]
    assert np.allclose(sorted(long[:, 0]), [0.0, 3.0], atol=1e-3) and np.all(np.abs(long[:, 1]) < 0.01)
    touching = merge_collinear([[[0.0, 0.0], [1.0, 0.0]], [[1.08, 0.0], [2.0, 0.0]]], gap=0.1)
    assert len(touching) == 1
    apart = merge_collinear([[[0.0, 0.0], [1.0, 0.0]], [[1.3, 0.0], [2.0, 0.0]]], gap=0.1)
    assert len(apart) == 2


def test_an_l_corner_becomes_one_polyline_through_the_corner():
    from slam2d.mapping.geometric import link_corners

    lines = link_corners([[[0.0, 0.0], [1.96, 0.0]], [[2.0, 0.05], [2.0, 1.5]]], corner_gap=0.15)
    assert len(lines) == 1
    assert np.allclose(lines[0], [[0.0, 0.0], [2.0, 0.0], [2.0, 1.5]])
    # a square's four sides close into one ring
    square = [[[0.02, 0], [0.98, 0]], [[1, 0.02], [1, 0.98]], [[0.98, 1], [0.02, 1]], [[0, 0.98], [0, 0.02]]]
    ring = link_corners(square, corner_gap=0.1)
    assert len(ring) == 1 and len(ring[0]) == 5 and np.allclose(ring[0][0], ring[0][-1])


def _office_grid(res: float = 0.05):
    from slam2d.sim.world import World

    world = World.office()
    origin = (-1.0, -1.0)
    w, h = int(round(22 / res)), int(round(14 / res))
    x, y = np.meshgrid(origin[0] + (np.arange(w) + 0.5) * res, origin[1] + (np.arange(h) + 0.5) * res)
    return world, world.occupied(np.column_stack([x.ravel(), y.ravel()])).reshape(h, w), res, origin


def test_line_map_of_the_office_finds_its_walls():
    from slam2d.mapping.geometric import extract_line_map
    from slam2d.mapping.line_scores import line_scores

    world, occ, res, origin = _office_grid()
    lines = extract_line_map(occ, res, origin)
    score = line_scores(lines.segments, world.segments, tol=0.05, angle_tol_deg=1.0, occupied=world.occupied)
    assert score["precision"] >= 0.95 and score["recall"] >= 0.95, score
    assert len(lines.to_bytes()) * 100 < occ.size  # far smaller than the grid


def test_binary_line_map_round_trips_losslessly():
    from slam2d.mapping.geometric import extract_line_map
    from slam2d.mapping.line_map import LineMap

    _, occ, res, origin = _office_grid()
    lines = extract_line_map(occ, res, origin)
    data = lines.to_bytes()
    back = LineMap.from_bytes(data)
    assert (back.resolution, back.origin, back.shape) == (res, origin, occ.shape)
    assert len(back.polylines) == len(lines.polylines)
    assert all(np.array_equal(a, b) for a, b in zip(back.polylines, lines.polylines))  # bit for bit
    assert back.to_bytes() == data
    ring = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 0.0]])  # closed: stored without its last vertex
    far = np.array([[-7.5, 3.2], [412.0, -96.3]])  # negative and multi-byte differences
    hand = LineMap([ring, far, np.array([[0.511, 0.0], [0.6, 0.0]])], 0.05, (-1.0, -1.0), (60, 80))
    back = LineMap.from_bytes(hand.to_bytes())
    assert np.allclose(back.polylines[0], ring, atol=1e-9) and np.allclose(back.polylines[1], far, atol=1e-9)
    assert np.allclose(back.polylines[2], [[0.5, 0.0], [0.6, 0.0]])  # off the half-cell lattice: rounded to it
    assert LineMap.from_bytes(LineMap([], 0.1, (0.0, 0.0), (3, 4)).to_bytes()).polylines == []
    with pytest.raises(ValueError, match="magic"):
        LineMap.from_bytes(b"{" + data)


def test_a_jagged_slanted_wall_stays_a_few_segments():
    from slam2d.mapping.geometric import extract_line_map
    from slam2d.mapping.line_scores import chamfer

    rows, cols = np.mgrid[:80, :200]
    across = (rows - 20) * np.cos(np.radians(10)) - (cols - 10) * np.sin(np.radians(10))  # cells from the centre line
    noise = np.random.default_rng(0).normal(0.0, 0.4, rows.shape)
    occ = (np.abs(across + noise) < 1.0) & (cols >= 10) & (cols < 190)  # 2 cells thick, 9 m long, ragged faces
    lines = extract_line_map(occ, 0.05)
    assert len(lines.segments) <= 20, len(lines.segments)  # 60 when every one-cell jag is a vertex
    assert chamfer(lines.segments, occ, 0.05) < 0.03


def test_line_map_json_and_svg(tmp_path):
    from slam2d.mapping.line_map import LineMap

    lines = LineMap([np.array([[0.0, 0.0], [2.0, 0.0], [2.0, 1.5]]), np.array([[1.0, 1.0], [1.5, 1.0]])],
                    0.05, (-0.5, -0.5), (60, 80), {"method": "contour"})
    back = LineMap.load(lines.save(tmp_path / "lines.json"))
    assert len(back.polylines) == 2 and all(np.allclose(a, b) for a, b in zip(back.polylines, lines.polylines))
    assert back.segments.shape == (3, 2, 2) and back.length() == pytest.approx(4.0)
    svg = lines.to_svg(np.zeros((60, 80), np.float32))
    assert svg.count("<polyline") == 2 and "data:image/png;base64," in svg and svg.startswith("<svg")
    assert lines.save_png(tmp_path / "lines.png").stat().st_size > 1000


# --------------------------------------------------------------------------- wall mesh


def test_wall_of_one_segment_has_two_triangles_facing_right():
    from slam2d.mapping.mesh import wall_arrays, wall_mesh

    v, t = wall_arrays([[[1.0, 1.0], [1.0, 3.0]]], height=2.0)  # p1 -> p2 along +y
    assert np.allclose(v, [[1, 1, 0], [1, 3, 0], [1, 3, 2], [1, 1, 2]]) and t.tolist() == [[0, 1, 2], [0, 2, 3]]
    mesh = wall_mesh([[[1.0, 1.0], [1.0, 3.0]]], height=2.0)
    assert len(mesh.triangles) == 2
    assert np.allclose(np.asarray(mesh.triangle_normals), [1.0, 0.0, 0.0])  # direction x z: the right side
    with_floor = wall_mesh([[[1.0, 1.0], [1.0, 3.0]]], height=2.0, floor_extent=(0.0, 4.0, 0.0, 4.0))
    assert len(with_floor.triangles) == 4 and np.allclose(np.asarray(with_floor.triangle_normals)[2:], [0, 0, 1])


def test_thick_walls_are_watertight_solids(tmp_path):
    import open3d as o3d

    from slam2d.mapping.mesh import render_mesh, save_mesh, wall_mesh

    mesh = wall_mesh([[[0.0, 0.0], [2.0, 0.0]], [[2.5, 0.0], [2.5, 1.0]]], height=2.5, thickness=0.1)
    assert len(mesh.triangles) == 24 and mesh.is_watertight()
    assert mesh.get_volume() == pytest.approx(2.5 * 0.1 * 3.0)
    centres = np.asarray(mesh.vertices)[np.asarray(mesh.triangles)].mean(1)
    box = np.repeat(np.asarray(mesh.vertices).reshape(2, 8, 3).mean(1), 12, axis=0)
    assert np.all(((centres - box) * np.asarray(mesh.triangle_normals)).sum(1) > 0)  # normals point out
    for name in ("walls.ply", "walls.obj"):
        back = o3d.io.read_triangle_mesh(str(save_mesh(mesh, tmp_path / name)))
        assert len(back.triangles) == 24
    assert render_mesh(mesh, tmp_path / "walls.png").stat().st_size > 1000


def test_footprint_hausdorff_is_half_the_thickness_and_follows_a_shift():
    from slam2d.mapping.mesh import footprint_edges, footprint_hausdorff, wall_mesh

    seg = [[[0.0, 0.0], [2.0, 0.0]]]
    box = wall_mesh(seg, thickness=0.1, floor_extent=(-1.0, 3.0, -1.0, 1.0))
    assert len(footprint_edges(box)) == 4  # the box's base outline; its bottom diagonal and the floor left out
    assert footprint_hausdorff(box, seg) == pytest.approx((0.05, 0.05, 0.05), abs=1e-4)
    assert footprint_hausdorff(wall_mesh(seg), seg)[0] == pytest.approx(0.0, abs=1e-9)
    shifted = wall_mesh(seg).translate((0.0, 0.3, 0.0))
    assert footprint_hausdorff(shifted, seg)[0] == pytest.approx(0.3, abs=1e-4)
    longer = [[[0.0, 0.0], [2.0, 0.0]], [[0.0, 1.0], [0.0, 1.5]]]  # a wall with no mesh: only lines -> outline sees it
    h, outline_to_lines, lines_to_outline = footprint_hausdorff(wall_mesh(seg), longer)
    assert outline_to_lines == pytest.approx(0.0, abs=1e-9) and h == lines_to_outline == pytest.approx(1.5, abs=1e-4)


def test_touching_boxes_are_watertight_one_by_one_not_as_a_whole():
    from slam2d.mapping.mesh import solids_watertight, wall_mesh

    corner = wall_mesh([[[0.0, 0.0], [2.0, 0.0]], [[2.0, 0.0], [2.0, 1.0]]], thickness=0.1)
    assert solids_watertight(corner) == (2, 2) and not corner.is_watertight()  # the boxes overlap at the corner
    assert solids_watertight(wall_mesh([[[0.0, 0.0], [2.0, 0.0]]])) == (0, 1)  # a quad is open


# --------------------------------------------------------------------------- run outputs and the map command


def test_layers_default_to_the_grid_and_reject_unknown_names():
    from slam2d import config
    from slam2d.errors import InputError

    assert config.load(None, []).mapping.layers == ["grid"]
    assert config.load(None, ["mapping.layers=[grid,quadtree,mesh]"]).mapping.layers == ["grid", "quadtree", "mesh"]
    with pytest.raises(InputError, match="mapping.layers"):
        config.load(None, ["mapping.layers=[grid,octree]"])


def test_run_writes_the_chosen_layers_and_map_makes_them_again(tmp_path):
    import json

    from typer.testing import CliRunner

    from slam2d import config
    from slam2d.cli import app
    from slam2d.runs.run import run_experiment
    from slam2d.mapping.quadtree import QuadTree

    cfg = config.load(None, ["dataset.max_scans=40", "mapping.resolution=0.1", f"output.root={tmp_path / 'r'}",
                             "mapping.layers=[grid,sparse,quadtree,lines,mesh]"])
    folder = run_experiment(cfg, quiet=True)
    for name in ("map.pgm", "map_sparse.npz", "map.quadtree", "map_trinary.quadtree", "quadtree.png", "lines.bin",
                 "lines.json", "lines.svg",
                 "walls.ply", "walls.png", "layers.json"):
        assert (folder / name).is_file(), name
    stats = json.loads((folder / "layers.json").read_text())
    assert stats["quadtree"]["bytes"] < stats["grid"]["dense_uint8_bytes"] / 10
    from slam2d.mapping.line_map import LineMap

    binary, text = LineMap.load(folder / "lines.bin"), LineMap.load(folder / "lines.json")
    assert stats["lines"]["bytes"] == (folder / "lines.bin").stat().st_size < stats["lines"]["json_bytes"]
    assert all(np.allclose(a, b, atol=1e-3) for a, b in zip(binary.polylines, text.polylines))
    from slam2d.mapping.export import load_map_server

    grid = load_map_server(folder / "map.yaml")
    assert np.array_equal(QuadTree.load(folder / "map.quadtree").to_mask(), grid.occupied_mask())
    from slam2d.mapping.quadtree import decode_trinary, trinary_values

    assert np.array_equal(decode_trinary((folder / "map_trinary.quadtree").read_bytes()), trinary_values(grid))

    runner = CliRunner()
    out = runner.invoke(app, ["map", str(folder / "map.yaml"), "--layers", "quadtree,lines", "-o", str(tmp_path / "m"),
                              "--quiet"])
    assert out.exit_code == 0, out.output
    made = next((tmp_path / "m").glob("map-map-*"))
    assert (made / "map.quadtree").read_bytes() == (folder / "map.quadtree").read_bytes()
    assert (made / "lines.json").is_file() and not (made / "walls.ply").exists()
    bad = runner.invoke(app, ["map", str(folder / "map.yaml"), "--layers", "octree", "-o", str(tmp_path / "m")])
    assert bad.exit_code == 2 and "--layers" in bad.output


def test_chamfer_of_a_wall_and_its_line():
    from slam2d.mapping.line_scores import chamfer

    occ = np.zeros((20, 40), bool)
    occ[10, 5:35] = True  # cells of centres y = 0.525 m, x from 0.275 to 1.725 m at 0.05 m
    line = [[[0.275, 0.525], [1.725, 0.525]]]
    assert chamfer(line, occ, 0.05) < 0.01  # samples every half cell between cell centres
    assert chamfer([[[0.275, 0.575], [1.725, 0.575]]], occ, 0.05) == pytest.approx(0.05, abs=0.01)


def test_map_command_takes_a_floor_plan_image(tmp_path):
    from PIL import Image
    from typer.testing import CliRunner

    from slam2d.cli import app
    from slam2d.mapping.maps import load_map
    from slam2d.mapping.quadtree import QuadTree

    img = np.full((40, 60), 255, np.uint8)
    img[5, 5:55] = img[35, 5:55] = 0  # two walls; image row 0 is the top
    img[10:20, 10:20] = 205  # unknown
    Image.fromarray(img).save(tmp_path / "plan.png")
    grid = load_map(tmp_path / "plan.png")
    assert grid.resolution == 0.05 and np.array_equal(grid.occupied_mask(), img[::-1] == 0)
    assert np.count_nonzero(grid.log_odds == 0) == 100
    out = CliRunner().invoke(app, ["map", str(tmp_path / "plan.png"), "--layers", "quadtree,lines", "-o",
                                   str(tmp_path / "r"), "--quiet"])
    assert out.exit_code == 0, out.output
    made = next((tmp_path / "r").glob("map-plan-*"))
    assert np.array_equal(QuadTree.load(made / "map.quadtree").to_mask(), img[::-1] == 0)


def test_one_loader_reads_every_map_file_with_rows_up(tmp_path):
    """A floor plan, its map_server map, the results folder holding that map and a Moving AI map load
    through one function into one grid type; the image's top row is the grid's last row."""
    from PIL import Image

    from slam2d.config import MappingConfig
    from slam2d.mapping.export import save_map_server
    from slam2d.mapping.maps import load_map
    from slam2d.planning.grid import load_grid

    img = np.full((10, 12), 255, np.uint8)
    img[0, :] = 0  # a wall along the top of the image
    img[5:7, 2:4] = 205  # unknown
    Image.fromarray(img).save(tmp_path / "plan.png")
    plan = load_map(tmp_path / "plan.png", 0.1)
    assert plan.resolution == 0.1 and plan.occupied_mask()[-1].all() and not plan.occupied_mask()[:-1].any()
    save_map_server(plan, tmp_path / "run" / "map", MappingConfig())
    for source in (tmp_path / "run" / "map.yaml", tmp_path / "run"):
        again = load_map(source)
        assert np.array_equal(again.occupied_mask(), plan.occupied_mask())
        assert np.array_equal(again.free_mask(), plan.free_mask())
    assert np.array_equal(load_grid(tmp_path / "run").free, load_grid(tmp_path / "plan.png", resolution=0.1).free)
    (tmp_path / "m.map").write_text("type octile\nheight 2\nwidth 3\nmap\n@..\n..T\n")
    grid = load_map(tmp_path / "m.map")
    assert grid.resolution == 1.0 and grid.free_mask().tolist() == [[False, True, True], [True, True, False]]
