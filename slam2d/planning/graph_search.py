"""Searches the two hierarchical planners share (numba): A* over a graph in CSR form whose
nodes sit at grid cells (HPA*'s abstract graph, :mod:`~slam2d.planning.hierarchical`; the
room-graph planner's portal graph, :mod:`~slam2d.planning.room_graph`), and the paths back
along a search's parents.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from slam2d.planning.astar import _octile, _pop, _sift_up


@njit(cache=True)
def _relax(v, ng, hv, g, parent, state, hk, hg, hn, hpos, stamp, u, size):
    """Offer ``v`` the cost ``ng`` through ``u``; returns the new heap size (state as in ``_search``)."""
    sv = state[v]
    if sv == 2 * stamp + 1:
        return size
    if sv < 2 * stamp:
        state[v] = 2 * stamp
        g[v] = ng
        parent[v] = u
        _sift_up(hk, hg, hn, hpos, size, ng + hv, ng, v)
        return size + 1
    if ng < g[v] - 1e-12:
        g[v] = ng
        parent[v] = u
        _sift_up(hk, hg, hn, hpos, hpos[v], ng + hv, ng, v)
    return size


@njit(cache=True)
def _abstract_search(indptr, nbr, wt, node_r, node_c, s_nodes, s_w, goal_w, direct, sr, sc, gr, gc,
                     g, parent, state, hk, hg, hn, hpos, stamp):  # fmt: skip
    """A* on the abstract graph; start = node n, goal = node n + 1. Returns (found, expanded)."""
    n = node_r.shape[0]
    S = n
    T = n + 1
    state[S] = 2 * stamp
    g[S] = 0.0
    parent[S] = -1
    _sift_up(hk, hg, hn, hpos, 0, _octile(sr, sc, gr, gc, True), 0.0, S)
    size = 1
    expanded = 0
    while size > 0:
        u, size = _pop(hk, hg, hn, hpos, size)
        state[u] = 2 * stamp + 1
        expanded += 1
        if u == T:
            return True, expanded
        gu = g[u]
        if u == S:
            for i in range(s_nodes.shape[0]):
                v = s_nodes[i]
                if s_w[i] < np.inf:
                    hv = _octile(node_r[v], node_c[v], gr, gc, True)
                    size = _relax(v, gu + s_w[i], hv, g, parent, state, hk, hg, hn, hpos, stamp, u, size)
            if direct < np.inf:
                size = _relax(T, gu + direct, 0.0, g, parent, state, hk, hg, hn, hpos, stamp, u, size)
            continue
        for i in range(indptr[u], indptr[u + 1]):
            v = nbr[i]
            hv = _octile(node_r[v], node_c[v], gr, gc, True)
            size = _relax(v, gu + wt[i], hv, g, parent, state, hk, hg, hn, hpos, stamp, u, size)
        if goal_w[u] < np.inf:
            size = _relax(T, gu + goal_w[u], 0.0, g, parent, state, hk, hg, hn, hpos, stamp, u, size)
    return False, expanded


@njit(cache=True)
def _trace_ids(parent, t):
    n = 0
    v = t
    while v != -1:
        n += 1
        v = parent[v]
    out = np.empty(n, np.int64)
    v = t
    for i in range(n - 1, -1, -1):
        out[i] = v
        v = parent[v]
    return out


@njit(cache=True)
def _trace_from(parent, s, t, width):
    """Padded cells from ``s`` to ``t`` along parents."""
    n = 1
    v = t
    while v != s:
        n += 1
        v = parent[v]
    out = np.empty(n, np.int64)
    v = t
    for i in range(n - 1, -1, -1):
        out[i] = v
        if i > 0:
            v = parent[v]
    return out
