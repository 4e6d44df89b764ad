"""g2o / TORO pose graphs: real files, round trip, TORO information order, bad lines."""

from __future__ import annotations

import numpy as np
import pytest

from slam2d.datasets.g2o import PoseGraphFile, read_g2o, write_g2o
from slam2d.errors import InputError

FIELDS = ("ids", "poses", "i", "j", "measurements", "information")


@pytest.mark.parametrize("name, n_poses, n_edges",
                         [("intel", 1728, 2512), ("MIT", 808, 827), ("CSAIL", 1045, 1172), ("M3500", 3500, 5453)])
def test_real_counts(data_file, name, n_poses, n_edges):
    g = read_g2o(data_file(f"posegraphs/{name}.g2o"))
    assert (len(g.ids), len(g.poses), len(g.i), len(g.information)) == (n_poses, n_poses, n_edges, n_edges)
    assert np.all(np.isfinite(g.poses))
    np.testing.assert_array_equal(g.information, g.information.transpose(0, 2, 1))


def test_round_trip(tmp_path):
    rng = np.random.default_rng(0)
    a = rng.normal(size=(4, 3, 3))
    graph = PoseGraphFile(
        ids=np.array([0, 1, 2, 7]),
        poses=rng.normal(size=(4, 3)) * [100, 100, 1],
        i=np.array([0, 1, 2, 7]),
        j=np.array([1, 2, 7, 0]),
        measurements=rng.normal(size=(4, 3)) / 3,
        information=a @ a.transpose(0, 2, 1) + np.eye(3),
    )
    write_g2o(tmp_path / "g.g2o", graph)
    back = read_g2o(tmp_path / "g.g2o")
    for f in FIELDS:
        np.testing.assert_array_equal(getattr(back, f), getattr(graph, f), err_msg=f)


def test_toro_information_order(tmp_path):
    path = tmp_path / "tiny.graph"
    path.write_text("# TORO\nVERTEX2 0 0 0 0\nVERTEX2 1 1 0 0\n\nFIX 0\n"
                    "EDGE2 0 1 1.0 0.5 0.1 10 1 20 30 2 3\n")
    g = read_g2o(path)
    np.testing.assert_array_equal(g.information[0], [[10, 1, 2], [1, 20, 3], [2, 3, 30]])
    np.testing.assert_array_equal(g.measurements[0], [1.0, 0.5, 0.1])
    assert (g.i[0], g.j[0]) == (0, 1)


def test_edges_only_chain_poses(tmp_path):
    path = tmp_path / "edges.g2o"
    info = "1 0 0 1 0 1"
    path.write_text(f"EDGE_SE2 0 1 1 0 1.5707963267948966 {info}\n"
                    f"EDGE_SE2 2 1 1 0 0 {info}\n")  # pose 1 seen from pose 2
    g = read_g2o(path)
    np.testing.assert_array_equal(g.ids, [0, 1, 2])
    np.testing.assert_allclose(g.poses, [[0, 0, 0], [1, 0, np.pi / 2], [1, -1, np.pi / 2]], atol=1e-12)


def test_the_chain_of_an_edges_only_file_is_scipys_breadth_first_tree(data_file):
    """The breadth-first tree that chains an edges-only file's poses (numpy, no scipy import) is scipy's, vertex
    for vertex and predecessor for predecessor: on CSAIL's edges and on random graphs with repeated edges, loops
    and unreached vertices (the file's poses, hence the start's error and the figure, do not change)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import breadth_first_order

    from slam2d.datasets import g2o

    csail = read_g2o(data_file("posegraphs/CSAIL.g2o"))
    rng = np.random.default_rng(0)
    cases = [(len(csail.ids), np.searchsorted(csail.ids, csail.i), np.searchsorted(csail.ids, csail.j))]
    cases += [(n, rng.integers(0, n, m), rng.integers(0, n, m)) for n, m in rng.integers(1, 40, (200, 2)) * [1, 2]]
    for n, a, b in cases:
        order, pred = breadth_first_order(coo_matrix((np.ones(len(a)), (a, b)), shape=(n, n)).tocsr(), 0, directed=False)
        mine = g2o._breadth_first(n, a, b)
        assert np.array_equal(mine[0], order) and np.array_equal(mine[1], pred), (n, a, b)


GOOD = "VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 1 0 0\n"


@pytest.mark.parametrize("line, what", [
    ("EDGE_SE2 0 1 1 0 0 1 0 0 1 0", "needs 11 values, got 10"),
    ("VERTEX_SE2 2 1 x 0", "non-numeric"),
    ("EDGE_SE2 0 5 1 0 0 1 0 0 1 0 1", "unknown vertex"),
    ("EDGE_SE2 0 1 1 0 0 1 2 0 1 0 1", "not positive definite"),
    ("EDGE_SE2 0 1 1 0 0 1 0 0 1 0 0", "not positive definite"),
    ("VERTEX_SE2 1 0 0 0", "duplicate vertex 1"),
    ("VERTEX_XY 3 1 1", "unsupported line type"),
    ("EDGE_SE2 0 1 1 0 nan 1 0 0 1 0 1", "non-finite"),
])
def test_malformed_lines(tmp_path, line, what):
    path = tmp_path / "bad.g2o"
    path.write_text(GOOD + line + "\nVERTEX_SE2 9 0 0 0\n")
    with pytest.raises(InputError, match=what) as err:
        read_g2o(path)
    assert str(err.value).startswith(f"{path}:3: ")


def test_missing_file(tmp_path):
    with pytest.raises(InputError, match="file not found"):
        read_g2o(tmp_path / "none.g2o")
