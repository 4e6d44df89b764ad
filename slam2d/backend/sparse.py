"""Sparse symmetric factorisations in a given elimination order (scipy's SuperLU).

SuperLU's own minimum-degree ordering of a pose graph's 3N unknowns is slow on large graphs (city10000: 3 x
the factorisation in GTSAM's COLAMD order of its N poses, ``factors.elimination_order``). The solvers outside
GTSAM (the chordal start, the certificate) take the poses' order and expand it to their unknowns.
"""

from __future__ import annotations

import numpy as np


class SymmetricFactor:
    """SuperLU of a sparse symmetric matrix with diagonal pivots (an LDL^T: ``pivots()`` holds D), its rows and
    columns taken in the order ``perm`` (indices; None: SuperLU's minimum degree on A + A^T); RuntimeError on
    an exactly singular pivot."""

    def __init__(self, matrix, perm=None) -> None:
        from scipy.sparse.linalg import splu

        self.perm = perm
        matrix = matrix.tocsc() if perm is None else matrix.tocsr()[perm][:, perm].tocsc()
        self.lu = splu(matrix, permc_spec="MMD_AT_PLUS_A" if perm is None else "NATURAL", diag_pivot_thresh=0.0,
                       options={"SymmetricMode": True})

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        if self.perm is None:
            return self.lu.solve(rhs)
        out = np.empty_like(rhs)
        out[self.perm] = self.lu.solve(rhs[self.perm])
        return out

    def pivots(self) -> np.ndarray:
        return self.lu.U.diagonal()


def unknowns(elimination, columns) -> np.ndarray | None:
    """Indices of the vertices' unknowns, vertex by vertex in ``elimination`` (id ranks (N,); None: None);
    ``columns(ranks)`` gives the (K, k) indices of the vertices ``ranks`` (K,)."""
    return None if elimination is None else columns(np.asarray(elimination)).ravel()


def held_first(elimination) -> np.ndarray | None:
    """``elimination`` without vertex 0 (the vertex the solvers hold), the others' ranks less one."""
    return None if elimination is None else np.asarray(elimination)[np.asarray(elimination) != 0] - 1
