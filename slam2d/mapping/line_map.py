"""A line map: wall polylines of a grid, and its compact binary, JSON, SVG and PNG forms.

``LineMap.segments`` is the thesis's endpoint table (Tian 2016, eq. 12). Coordinates are in
metres; the binary form stores vertices on the :data:`QUANTUM` lattice.
"""

from __future__ import annotations

import json
import struct
import zlib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

__all__ = ["LineMap", "QUANTUM", "to_lattice", "from_lattice"]

QUANTUM = 0.5
"""Vertex lattice step of a line map, in cells: ``geometric.extract_line_map`` snaps its vertices to it (moving
each by at most a quarter cell) and :meth:`LineMap.to_bytes` stores them as integers on it."""


@dataclass(eq=False)
class LineMap:
    """Wall polylines (list of (M, 2) m arrays) of a grid with ``resolution`` m/cell, ``origin`` (x, y) m
    and ``shape`` (H, W) cells."""

    polylines: list[np.ndarray]
    resolution: float
    origin: tuple[float, float]
    shape: tuple[int, int]
    params: dict = field(default_factory=dict)

    @property
    def segments(self) -> np.ndarray:
        """The thesis's endpoint table (K, 2, 2) m: consecutive polyline vertices."""
        parts = [np.stack([p[:-1], p[1:]], axis=1) for p in self.polylines if len(p) > 1]
        return np.concatenate(parts) if parts else np.zeros((0, 2, 2))

    def length(self) -> float:
        """Total wall length, m."""
        s = self.segments
        return float(np.linalg.norm(s[:, 1] - s[:, 0], axis=1).sum())

    def to_json(self) -> str:
        """Compact JSON, coordinates in millimetre-rounded metres."""
        return json.dumps({"format": "slam2d-lines/1", "units": "m", "resolution": self.resolution,
                           "origin": list(self.origin), "shape": list(self.shape), "params": self.params,
                           "polylines": [np.round(p, 3).tolist() for p in self.polylines]}, separators=(",", ":"))

    @classmethod
    def from_json(cls, text: str) -> LineMap:
        d = json.loads(text)
        if d.get("format") != "slam2d-lines/1":
            raise ValueError("not a slam2d line map (format)")
        return cls([np.asarray(p, float).reshape(-1, 2) for p in d["polylines"]], d["resolution"],
                   tuple(d["origin"]), tuple(d["shape"]), d.get("params", {}))

    def save(self, path) -> Path:
        """Write the binary form to a ``.bin`` path, JSON to any other."""
        path = Path(path)
        if path.suffix == ".bin":
            path.write_bytes(self.to_bytes())
        else:
            path.write_text(self.to_json())
        return path

    @classmethod
    def load(cls, path) -> LineMap:
        """Read a line map written by :meth:`save` (binary from ``.bin``, else JSON)."""
        path = Path(path)
        return cls.from_bytes(path.read_bytes()) if path.suffix == ".bin" else cls.from_json(path.read_text())

    def to_bytes(self) -> bytes:
        """Compact binary form: a 5-byte magic, then deflate (raw, filtered) of a header (resolution, origin,
        shape, lattice step m, polyline count), each polyline's vertex count (doubled, + 1 if closed: its last
        vertex is not stored) and every vertex as the difference from the one before on the :data:`QUANTUM`
        lattice, as zigzag varints. Lossless for vertices on the lattice (as :func:`extract_line_map` makes
        them)."""
        quantum = QUANTUM * self.resolution
        k = [to_lattice(p, self.origin, quantum) for p in self.polylines]
        closed = np.array([len(p) > 2 and bool(np.all(p[0] == p[-1])) for p in k], bool)
        kept = [p[:-1] if c else p for p, c in zip(k, closed)]
        n = np.array([len(p) for p in kept], np.int64)
        xy = np.concatenate(kept) if kept else np.zeros((0, 2), np.int64)
        header = _BINARY.pack(self.resolution, *self.origin, *self.shape, quantum, len(n))
        steps = np.diff(xy, axis=0, prepend=np.zeros((1, 2), np.int64))  # the first from the origin
        body = _varints(np.concatenate([2 * n + closed, steps.ravel()]))
        deflate = zlib.compressobj(9, zlib.DEFLATED, -15, 9, zlib.Z_FILTERED)
        return _BINARY_MAGIC + deflate.compress(header + body) + deflate.flush()

    @classmethod
    def from_bytes(cls, data: bytes) -> LineMap:
        if data[: len(_BINARY_MAGIC)] != _BINARY_MAGIC:
            raise ValueError("not a slam2d binary line map (magic)")
        raw = zlib.decompress(data[len(_BINARY_MAGIC) :], -15)
        res, ox, oy, h, w, quantum, count = _BINARY.unpack_from(raw)
        codes = _read_varints(raw[_BINARY.size :])
        n, closed = codes[:count] >> 1, codes[:count] & 1 == 1
        xy = np.cumsum(codes[count:].reshape(-1, 2), axis=0)
        parts = np.split(xy, np.cumsum(n)[:-1]) if count else []
        parts = [np.vstack([p, p[:1]]) if c else p for p, c in zip(parts, closed)]
        return cls([from_lattice(p, (ox, oy), quantum) for p in parts], res, (ox, oy), (h, w))

    def to_svg(self, grid_log_odds: np.ndarray | None = None, px_per_m: float = 20.0) -> str:
        """SVG (metres, y up, ``px_per_m`` px a metre) of the polylines over the grid (log-odds (H, W)) when given."""
        h, w = self.shape
        ox, oy = self.origin
        width, height = w * self.resolution, h * self.resolution
        parts = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{width * px_per_m:.0f}" '
                 f'height="{height * px_per_m:.0f}" viewBox="{ox} {-oy - height} {width} {height}">',
                 '<g transform="scale(1 -1)">']  # y up; the grid image (row 0 = lowest y) is mirrored with it
        if grid_log_odds is not None:
            png = _grid_png_base64(grid_log_odds)
            parts.append(f'<image x="{ox}" y="{oy}" width="{width}" height="{height}" preserveAspectRatio="none" '
                         f'style="image-rendering:pixelated" href="data:image/png;base64,{png}"/>')
        parts.append(f'<g fill="none" stroke="#d62728" stroke-width="{2 * self.resolution}" stroke-linejoin="round">')
        parts += [f'<polyline points="{" ".join(f"{x:.3f},{y:.3f}" for x, y in p)}"/>' for p in self.polylines]
        return "\n".join(parts + ["</g>", "</g>", "</svg>", ""])

    def save_png(self, path, grid_log_odds: np.ndarray | None = None, title: str | None = None) -> Path:
        """PNG figure of the polylines (one colour each) over the grid, axes in metres."""
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.collections import LineCollection
        from matplotlib.figure import Figure

        h, w = self.shape
        ox, oy = self.origin
        fig = Figure(figsize=(8.0, float(np.clip(8.0 * h / max(w, 1), 3.0, 16.0))), dpi=150)
        FigureCanvasAgg(fig)
        ax = fig.add_subplot()
        if grid_log_odds is not None:
            ax.imshow(1.0 / (1.0 + np.exp(grid_log_odds.astype(float))), cmap="gray", vmin=0, vmax=1, origin="lower",
                      interpolation="nearest", extent=(ox, ox + w * self.resolution, oy, oy + h * self.resolution))
        ax.add_collection(LineCollection(self.polylines, colors=[f"C{i % 10}" for i in range(len(self.polylines))],
                                         linewidths=1.2))
        ax.set_xlim(ox, ox + w * self.resolution)
        ax.set_ylim(oy, oy + h * self.resolution)
        ax.set_aspect("equal")
        ax.set_xlabel("x (m)")
        ax.set_ylabel("y (m)")
        ax.set_title(title or f"{len(self.polylines)} polylines, {len(self.segments)} segments, {self.length():.0f} m")
        path = Path(path)
        fig.savefig(path, bbox_inches="tight")
        return path


_BINARY_MAGIC = b"SL2L\x01"
_BINARY = struct.Struct("<3d2Id I")  # resolution m, origin (x, y) m, shape (H, W), lattice step m, polylines


def to_lattice(xy, origin, quantum: float) -> np.ndarray:
    """Integer lattice coordinates (..., 2) of points ``xy`` (..., 2) m on the grid of step ``quantum`` m
    through ``origin``."""
    return np.round((np.asarray(xy, float) - np.asarray(origin, float)) / quantum).astype(np.int64)


def from_lattice(k, origin, quantum: float) -> np.ndarray:
    """Points (..., 2) m of integer lattice coordinates ``k`` (the inverse of :func:`to_lattice`)."""
    return np.asarray(origin, float) + np.asarray(k, np.int64) * quantum


def _varints(values) -> bytes:
    """LEB128 bytes of the zigzag codes of int64 ``values`` (one byte for |v| < 64, two below 8192)."""
    v = np.asarray(values, np.int64)
    z = ((v << 1) ^ (v >> 63)).astype(np.uint64)
    shift = np.arange(10, dtype=np.uint64) * np.uint64(7)
    n = 1 + ((z[:, None] >> shift[1:]) > 0).sum(axis=1)
    more = np.arange(10) < (n - 1)[:, None]
    byte = ((z[:, None] >> shift) & np.uint64(0x7F)) | (more.astype(np.uint64) << np.uint64(7))
    return byte.astype(np.uint8)[np.arange(10) < n[:, None]].tobytes()


def _read_varints(data: bytes) -> np.ndarray:
    """int64 values of the zigzag LEB128 bytes ``data`` (the inverse of :func:`_varints`)."""
    b = np.frombuffer(data, np.uint8)
    last = b < 0x80
    which = np.cumsum(last) - last  # value index of each byte
    first = np.concatenate([[0], np.flatnonzero(last)[:-1] + 1])
    shift = (7 * (np.arange(len(b)) - first[which])).astype(np.uint64)
    z = np.zeros(int(last.sum()), np.uint64)
    np.add.at(z, which, (b & 0x7F).astype(np.uint64) << shift)
    return (z >> np.uint64(1)).astype(np.int64) ^ -(z & np.uint64(1)).astype(np.int64)


def _grid_png_base64(log_odds: np.ndarray) -> str:
    """Base64 PNG of a grid (image row 0 = grid row 0), grey 255 (1 - p)."""
    import base64
    import io

    from PIL import Image

    grey = np.round(255.0 / (1.0 + np.exp(np.asarray(log_odds, float)))).astype(np.uint8)
    buf = io.BytesIO()
    Image.fromarray(grey).save(buf, format="PNG", optimize=True)
    return base64.b64encode(buf.getvalue()).decode("ascii")
