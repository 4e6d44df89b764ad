"""Room labels for every free cell from labelled observations, and the merging of segments
cut where there is no doorway (steps 4 and 5 of :func:`~slam2d.segmentation.spectral.segment_spectral`).

:func:`label_free_cells` traces each observation's beams on a grid (numba
kernels) and gives every free cell the label of the observations that see it;
:func:`merge_open_boundaries` joins neighbouring elongated segments whose
common boundary is no constriction.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from slam2d.errors import InputError
from slam2d.segmentation.observations import Observations, dda_start, dda_step

__all__ = ["label_free_cells", "merge_open_boundaries"]


@njit(cache=True, nogil=True)
def _march(gx, gy, angle, lim, h, w, cells_r, cells_c, cells_t):
    """Cells (row, col) a ray from (gx, gy) crosses up to distance ``lim`` (cells), with
    the entry distance of each; returns how many were written (exact grid traversal)."""
    dx, dy = np.cos(angle), np.sin(angle)
    c, r = int(np.floor(gx)), int(np.floor(gy))
    step_c, step_r, inv_x, inv_y, tmx, tmy = dda_start(gx, gy, dx, dy)
    t = 0.0
    n = 0
    while t < lim and 0 <= c < w and 0 <= r < h and n < cells_r.shape[0]:
        cells_r[n], cells_c[n], cells_t[n] = r, c, t
        n += 1
        t, tmx, tmy, c, r = dda_step(tmx, tmy, inv_x, inv_y, c, r, step_c, step_r)
    return n


@njit(cache=True, nogil=True)
def _paint_votes(h, w, gxy, table, obs_label, max_t, votes):
    """votes[r, c, l] += 1 for every beam of an observation labelled l that crosses cell (r, c)."""
    nb = table.shape[1]
    cap = int(max_t) * 2 + 4
    cr = np.empty(cap, np.int64)
    cc = np.empty(cap, np.int64)
    ct = np.empty(cap)
    for i in range(gxy.shape[0]):
        lab = obs_label[i]
        for b in range(nb):
            n = _march(gxy[i, 0], gxy[i, 1], 2.0 * np.pi * b / nb, min(table[i, b], max_t), h, w, cr, cc, ct)
            for q in range(n):
                votes[cr[q], cc[q], lab] += 1


@njit(cache=True, nogil=True)
def _paint_seen(h, w, gxy, table, obs_label, max_t, seen):
    """seen[r, c, l] = number of observations labelled l whose beams reach cell (r, c)."""
    nb = table.shape[1]
    cap = int(max_t) * 2 + 4
    cr = np.empty(cap, np.int64)
    cc = np.empty(cap, np.int64)
    ct = np.empty(cap)
    stamp = np.full((h, w), -1, np.int64)
    for i in range(gxy.shape[0]):
        lab = obs_label[i]
        for b in range(nb):
            n = _march(gxy[i, 0], gxy[i, 1], 2.0 * np.pi * b / nb, min(table[i, b], max_t), h, w, cr, cc, ct)
            for q in range(n):
                if stamp[cr[q], cc[q]] != i:
                    stamp[cr[q], cc[q]] = i
                    seen[cr[q], cc[q], lab] += 1


@njit(cache=True, nogil=True)
def _pick_fraction(gxy, obs_label, radius, seen, out):
    """out[r, c] = the label l maximising seen / (near + 1), where ``near`` counts the
    observations labelled l within ``radius`` cells of the cell (seen or not)."""
    h, w, nl = seen.shape
    n = gxy.shape[0]
    bs = max(radius, 1.0)
    nbx = int(np.floor(w / bs)) + 1
    nby = int(np.floor(h / bs)) + 1
    bucket = np.empty(n, np.int64)
    for i in range(n):
        bx = min(max(int(np.floor(gxy[i, 0] / bs)), 0), nbx - 1)
        by = min(max(int(np.floor(gxy[i, 1] / bs)), 0), nby - 1)
        bucket[i] = by * nbx + bx
    order = np.argsort(bucket)
    start = np.zeros(nbx * nby + 1, np.int64)
    for i in range(n):
        start[bucket[i] + 1] += 1
    for j in range(nbx * nby):
        start[j + 1] += start[j]
    near = np.zeros(nl, np.int64)
    r2 = radius * radius
    for r in range(h):
        by = int(np.floor((r + 0.5) / bs))
        for c in range(w):
            any_seen = False
            for l in range(nl):
                if seen[r, c, l] > 0:
                    any_seen = True
                    break
            if not any_seen:
                continue
            for yy in range(max(by - 1, 0), min(by + 2, nby)):
                bx = int(np.floor((c + 0.5) / bs))
                for xx in range(max(bx - 1, 0), min(bx + 2, nbx)):
                    b = yy * nbx + xx
                    for q in range(start[b], start[b + 1]):
                        i = order[q]
                        dx = c + 0.5 - gxy[i, 0]
                        dy = r + 0.5 - gxy[i, 1]
                        if dx * dx + dy * dy <= r2:
                            near[obs_label[i]] += 1
            best, bv = 0, -1.0
            for l in range(nl):
                if seen[r, c, l] > 0:
                    v = seen[r, c, l] / (near[l] + 1.0)
                    if v > bv:
                        bv, best = v, l
                near[l] = 0
            out[r, c] = best


@njit(cache=True, nogil=True)
def _paint_nearest(h, w, gxy, table, obs_label, max_t, out):
    """out[r, c] = label of the nearest observation whose beams cross cell (r, c)."""
    nb = table.shape[1]
    cap = int(max_t) * 2 + 4
    cr = np.empty(cap, np.int64)
    cc = np.empty(cap, np.int64)
    ct = np.empty(cap)
    zbuf = np.full((h, w), np.inf)
    for i in range(gxy.shape[0]):
        for b in range(nb):
            n = _march(gxy[i, 0], gxy[i, 1], 2.0 * np.pi * b / nb, min(table[i, b], max_t), h, w, cr, cc, ct)
            for q in range(n):
                if ct[q] < zbuf[cr[q], cc[q]]:
                    zbuf[cr[q], cc[q]] = ct[q]
                    out[cr[q], cc[q]] = obs_label[i]


@njit(cache=True, nogil=True)
def _bfs_flood(labels, free):
    """Breadth-first flood of labels into unlabelled free cells over 8-neighbours (in place)."""
    h, w = labels.shape
    qr = np.empty(h * w, np.int64)
    qc = np.empty(h * w, np.int64)
    head, tail = 0, 0
    for r in range(h):
        for c in range(w):
            if labels[r, c] > 0:
                qr[tail], qc[tail] = r, c
                tail += 1
    while head < tail:
        r, c = qr[head], qc[head]
        head += 1
        for dr in range(-1, 2):
            for dc in range(-1, 2):
                rr, cc = r + dr, c + dc
                if 0 <= rr < h and 0 <= cc < w and free[rr, cc] and labels[rr, cc] == 0:
                    labels[rr, cc] = labels[r, c]
                    qr[tail], qc[tail] = rr, cc
                    tail += 1


def _fill(labels: np.ndarray, free: np.ndarray) -> np.ndarray:
    """Unlabelled free cells take the label of the nearest labelled cell through the free
    space (breadth-first over 8-neighbours); free components without any label get new
    labels of their own."""
    from scipy import ndimage

    labels = np.where(free, labels, 0).astype(np.int32)
    if not (free & (labels == 0)).any():
        return labels
    _bfs_flood(labels, np.ascontiguousarray(free))
    orphan = free & (labels == 0)
    if orphan.any():
        comp, n = ndimage.label(orphan, structure=np.ones((3, 3), dtype=int))
        labels = np.where(orphan, comp + labels.max(), labels).astype(np.int32)
    return labels


def _clean(labels: np.ndarray, free: np.ndarray, resolution: float, min_segment_m2: float) -> np.ndarray:
    """Keep each label's largest 8-connected piece (and drop segments under ``min_segment_m2``);
    the removed cells are refilled by their neighbours (:func:`_fill`)."""
    from skimage.measure import label as cc

    comp = cc(labels, background=0, connectivity=2)
    n = comp.max()
    if n == 0:
        return labels
    size = np.bincount(comp.ravel(), minlength=n + 1)
    owner = np.zeros(n + 1, dtype=np.int64)
    owner[comp.ravel()] = labels.ravel()
    best = np.zeros(labels.max() + 1, dtype=np.int64)
    order = np.argsort(size[1:], kind="stable") + 1  # ascending, so the largest piece is written last
    best[owner[order]] = order
    keep = np.zeros(n + 1, dtype=bool)
    keep[best[best > 0]] = True
    keep &= size * resolution**2 >= min_segment_m2
    keep[0] = False
    if keep[comp].sum() == (labels > 0).sum():
        return labels
    return _fill(np.where(keep[comp], labels, 0), free)


def label_free_cells(obs: Observations, obs_labels: np.ndarray, free=None, radius_m: float = 2.5,
                     rule: str = "fraction", cell_m: float = 0.1, min_segment_m2: float = 0.0) -> np.ndarray:
    """Room image (H, W) int32 (labels ``obs_labels + 1``, 0 off the free space) from labelled observations.

    Each observation's beams are traced on a grid of ``cell_m`` cells up to
    their range or ``radius_m`` m; an observation sees the cells its beams
    cross. A cell takes the label l that maximises

    - ``rule="fraction"`` (default): seen_l / (near_l + 1), with seen_l the
      observations of label l that see the cell and near_l those of label l
      within ``radius_m`` (seen or not). All viewpoints of a room see its
      cells; of the corridor viewpoints near a door only the few in line with
      it do, so the corridor does not take the cells just inside the door;
    - ``rule="vote"``: beam crossings (one observation's rays cross a cell at
      distance d about 1/d times: a vote weighted 1/d);
    - ``rule="nearest"``: the label of the nearest observation that sees it.

    Free cells no beam reaches, and every piece of a label but its largest,
    take the label of the nearest labelled cell through the free space; free
    components with no label get labels of their own.
    """
    free = obs.free if free is None else np.asarray(free, dtype=bool)
    if free is None or obs.resolution is None:
        raise InputError("label_free_cells", "observations carry no grid; pass free= with a resolution")
    if rule not in ("vote", "nearest", "fraction"):
        raise InputError("label_free_cells", f"rule must be 'fraction', 'vote' or 'nearest', got {rule!r}")
    res = obs.resolution
    f = max(1, int(round(cell_m / res)))
    h, w = -(-free.shape[0] // f), -(-free.shape[1] // f)
    gxy = np.ascontiguousarray((obs.poses[:, :2] - np.asarray(obs.origin)) / (res * f))
    table = np.ascontiguousarray(np.minimum(obs.range_table(), obs.range_max[:, None]) / (res * f))
    lab = np.asarray(obs_labels, dtype=np.int64) + 1
    coarse = np.zeros((h, w), dtype=np.int32)
    if len(lab) and rule == "fraction":
        seen = np.zeros((h, w, int(lab.max()) + 1), dtype=np.uint16)
        _paint_seen(h, w, gxy, table, lab, radius_m / (res * f), seen)
        _pick_fraction(gxy, lab, radius_m / (res * f), seen, coarse)
    elif len(lab) and rule == "vote":
        votes = np.zeros((h, w, int(lab.max()) + 1), dtype=np.uint16)
        _paint_votes(h, w, gxy, table, lab, radius_m / (res * f), votes)
        coarse = np.where(votes.any(axis=2), votes.argmax(axis=2), 0).astype(np.int32)
    elif len(lab):
        _paint_nearest(h, w, gxy, table, lab.astype(np.int32), radius_m / (res * f), coarse)
    cfree = _block_any(free, f)
    coarse = _clean(_fill(coarse, cfree), cfree, res * f, min_segment_m2)
    out = np.repeat(np.repeat(coarse, f, axis=0), f, axis=1)[: free.shape[0], : free.shape[1]]
    return np.where(free, out, 0).astype(np.int32)


def _block_any(mask: np.ndarray, f: int) -> np.ndarray:
    """(ceil(H/f), ceil(W/f)) mask: whether any cell of each f x f block is set."""
    if f == 1:
        return mask.copy()
    h, w = mask.shape
    pad = np.zeros((-(-h // f) * f, -(-w // f) * f), dtype=bool)
    pad[:h, :w] = mask
    return pad.reshape(pad.shape[0] // f, f, pad.shape[1] // f, f).any(axis=(1, 3))


def merge_open_boundaries(labels: np.ndarray, clear: np.ndarray, resolution: float, ratio: float = 0.7,
                          min_contact_m: float = 0.5, elongation: float = 3.0, cell_m: float = 0.1) -> np.ndarray:
    """Merge neighbouring elongated segments whose common boundary is no constriction.

    Free-space width is twice the distance to the nearest obstacle of
    ``clear`` (m). Segments A and B touching along at least ``min_contact_m``
    m are merged when the widest point of their boundary is at least ``ratio``
    times the width of the narrower one (a segment's width: its largest), and
    both are elongated (area >= ``elongation`` * width^2). A corridor cut by
    k-means has a boundary as wide as itself; a door is narrower than the
    spaces it joins; an alcove open to a corridor is not elongated. Merges
    chain (connected components). Computed on ``cell_m`` cells; labels are
    renumbered 1..R.
    """
    labels = np.asarray(labels)
    f = max(1, int(round(cell_m / resolution)))
    k = int(labels.max()) + 1
    if k <= 2:
        return labels.astype(np.int32)
    comp = _merge_map(labels[::f, ::f], clear[::f, ::f], k, resolution * f, ratio, min_contact_m, elongation)
    used = np.unique(comp[np.unique(labels[labels > 0])])
    remap = np.zeros(comp.max() + 1, dtype=np.int32)
    remap[used] = np.arange(1, len(used) + 1, dtype=np.int32)
    return np.where(labels > 0, remap[comp][labels], 0).astype(np.int32)


def _merge_map(labels: np.ndarray, clear: np.ndarray, k: int, resolution: float, ratio: float,
               min_contact_m: float, elongation: float) -> np.ndarray:
    """Component id (k,) per label 0..k-1 of :func:`merge_open_boundaries`' merge graph."""
    from scipy import ndimage
    from scipy.sparse import coo_array
    from scipy.sparse.csgraph import connected_components

    width = ndimage.distance_transform_edt(clear) * (2.0 * resolution)
    key, wide = [], []
    for a, b, wa, wb in (
        (labels[:, :-1], labels[:, 1:], width[:, :-1], width[:, 1:]),
        (labels[:-1, :], labels[1:, :], width[:-1, :], width[1:, :]),
    ):
        m = (a != b) & (a > 0) & (b > 0)
        key.append(np.minimum(a[m], b[m]).astype(np.int64) * k + np.maximum(a[m], b[m]))
        wide.append(np.maximum(wa[m], wb[m]))
    key, wide = np.concatenate(key), np.concatenate(wide)
    contact = np.bincount(key, minlength=k * k) * resolution
    gap = np.zeros(k * k)
    np.maximum.at(gap, key, wide)
    seg = np.zeros(k)
    seg[1:] = ndimage.maximum(width, labels, np.arange(1, k))
    area = np.bincount(labels.ravel(), minlength=k) * resolution**2
    long = area >= elongation * np.maximum(seg, resolution) ** 2
    i, j = np.divmod(np.nonzero(contact)[0], k)
    ok = (contact[i * k + j] >= min_contact_m) & (gap[i * k + j] >= ratio * np.minimum(seg[i], seg[j]))
    ok &= long[i] & long[j]
    g = coo_array((np.ones(int(ok.sum())), (i[ok], j[ok])), shape=(k, k))
    return connected_components(g, directed=False)[1]
