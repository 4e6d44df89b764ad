"""Grid lines as bits: a row (or column) of the padded free mask in 64-cell uint64 words, and the
block-based straight jump of JPS over them (Harabor & Grastien, ICAPS 2014), numba.

A jump along a line stops at the first cell that is blocked, is the target, or has a *forced* side
(a neighbouring line free there and blocked one step back); one word holds 64 cells, so a jump
costs a few word operations instead of a loop over cells.
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["bit_lines"]


@njit(inline="always")
def _ctz(x):
    """Index of the lowest set bit of a non-zero uint64."""
    n = 0
    if (x & np.uint64(0xFFFFFFFF)) == 0:
        n += 32
        x >>= np.uint64(32)
    if (x & np.uint64(0xFFFF)) == 0:
        n += 16
        x >>= np.uint64(16)
    if (x & np.uint64(0xFF)) == 0:
        n += 8
        x >>= np.uint64(8)
    if (x & np.uint64(0xF)) == 0:
        n += 4
        x >>= np.uint64(4)
    if (x & np.uint64(0x3)) == 0:
        n += 2
        x >>= np.uint64(2)
    if (x & np.uint64(0x1)) == 0:
        n += 1
    return n


@njit(inline="always")
def _msb(x):
    """Index of the highest set bit of a non-zero uint64."""
    n = 0
    if x >> np.uint64(32):
        n += 32
        x >>= np.uint64(32)
    if x >> np.uint64(16):
        n += 16
        x >>= np.uint64(16)
    if x >> np.uint64(8):
        n += 8
        x >>= np.uint64(8)
    if x >> np.uint64(4):
        n += 4
        x >>= np.uint64(4)
    if x >> np.uint64(2):
        n += 2
        x >>= np.uint64(2)
    if x >> np.uint64(1):
        n += 1
    return n


@njit(inline="always")
def _scan_line(bits, i, p0, step, target):
    """Block-based straight jump (Harabor & Grastien 2014) along line ``i`` of ``bits`` (64 cells a
    word): from position ``p0`` in ``step`` (+1 or -1), the first position that is the ``target`` (-1:
    none on this line), or has a forced side (free on line ``i - 1`` or ``i + 1``, blocked there one
    step back); -1 if a blocked cell comes first."""
    one = np.uint64(1)
    if step > 0:
        p = p0 + 1
        j = p >> 6
        keep = np.uint64(0xFFFFFFFFFFFFFFFF) << np.uint64(p & 63)
        while True:
            a = bits[i - 1, j]
            b = bits[i + 1, j]
            a_back = a << one
            b_back = b << one
            if j > 0:
                a_back |= bits[i - 1, j - 1] >> np.uint64(63)
                b_back |= bits[i + 1, j - 1] >> np.uint64(63)
            stop = (~bits[i, j] | (a & ~a_back) | (b & ~b_back)) & keep
            if stop != 0:
                x = (j << 6) + _ctz(stop)
                if p0 < target <= x:
                    return target
                return x if (bits[i, j] >> np.uint64(x & 63)) & one else -1
            j += 1
            keep = np.uint64(0xFFFFFFFFFFFFFFFF)
    p = p0 - 1
    j = p >> 6
    r = p & 63
    keep = np.uint64(0xFFFFFFFFFFFFFFFF) if r == 63 else (one << np.uint64(r + 1)) - one
    while True:
        a = bits[i - 1, j]
        b = bits[i + 1, j]
        a_back = (a >> one) | (bits[i - 1, j + 1] << np.uint64(63))
        b_back = (b >> one) | (bits[i + 1, j + 1] << np.uint64(63))
        stop = (~bits[i, j] | (a & ~a_back) | (b & ~b_back)) & keep
        if stop != 0:
            x = (j << 6) + _msb(stop)
            if x <= target < p0:
                return target
            return x if (bits[i, j] >> np.uint64(x & 63)) & one else -1
        j -= 1
        keep = np.uint64(0xFFFFFFFFFFFFFFFF)


def bit_lines(free_padded: np.ndarray) -> np.ndarray:
    """(lines, words) uint64: bit ``b`` of word ``j`` of line ``i`` is ``free_padded[i, 64 j + b]``;
    at least one zero word follows each line's last cell (a backward scan reads one word ahead). The
    mask's blocked border stops every scan inside the line."""
    h, w = free_padded.shape
    words = w // 64 + 2
    bits = np.zeros((h, words * 64), bool)
    bits[:, :w] = free_padded
    return np.packbits(bits, axis=1, bitorder="little").view("<u8").astype(np.uint64)
