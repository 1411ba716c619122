"""Score grids for matching a scan against a submap.

A submap's laser hits become a *likelihood field*: each cell holds
``exp(-d^2 / (2 sigma^2))``, ``d`` the distance from the cell's centre to the
nearest hit cell (0 where no hit lies within 3 sigma along both axes) (Thrun et al., "Probabilistic Robotics", 6.4; Olson 2009
rasterises the same cost). A scan scores a pose by the mean value of the
cells its points fall in: 1 when every point lies on a wall, 0 when none
comes near one.

For the branch-and-bound search (:mod:`slam.matching.search`) the field
comes with a pyramid (Hess et al. 2016, "Real-Time Loop Closure in 2D
LIDAR SLAM", Sec. V-C): level ``h`` holds in cell ``(x, y)`` the maximum of
the field over the ``2^h x 2^h`` cells from ``(x, y)`` on, so the mean of a
scan's points on level ``h`` bounds the score of every translation in that
block from above. The field is padded with ``2^H`` empty cells on its low
sides and one on its high sides, so that any index clipped into the array
reads a value that still bounds the truth (0 outside the data).

Frames: a grid's ``origin`` (2,) is the corner of cell (0, 0) in the frame of
the points it was built from (m); cell ``(i, j)`` spans
``origin + [i, i + 1) * resolution_m`` in x and the same in y.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

LEVELS = 255
"""A field value of 1 is stored as this (uint8)."""


@dataclass(frozen=True)
class ScorePyramid:
    """A likelihood field and its max-pooled levels; see the module docstring.

    ``levels[h]`` (nx, ny) uint8, the field in 255ths (a quarter of the
    memory of floats, and as fast to gather); ``levels[0]`` is the field
    itself.
    """

    levels: tuple[np.ndarray, ...]
    origin: np.ndarray
    resolution_m: float
    pad: int = 0
    """Empty cells on each side: cells clipped into ``[0, shape - 1 - w]``
    and then shifted by up to ``w <= pad - 2^depth`` stay inside the grid
    and read 0 where the truth is 0 or outside."""

    @property
    def depth(self) -> int:
        """The coarsest level's index."""
        return len(self.levels) - 1

    @property
    def field(self) -> np.ndarray:
        return self.levels[0]

    def cells(self, points: np.ndarray) -> np.ndarray:
        """Integer cell indices (..., 2) of points (..., 2) in the grid's frame."""
        return np.floor((points - self.origin) / self.resolution_m).astype(np.int32)

    def score(self, points: np.ndarray) -> float:
        """Mean field value at points (n, 2) in the grid's frame (0 for none)."""
        if len(points) == 0:
            return 0.0
        return float(self.lookup(0, self.cells(points)).mean()) / LEVELS

    def lookup(self, level: int, cells: np.ndarray) -> np.ndarray:
        """Values of ``level`` (in 255ths) at integer cells (..., 2), clipped into the grid."""
        grid = self.levels[level]
        ix = np.clip(cells[..., 0], 0, grid.shape[0] - 1)
        iy = np.clip(cells[..., 1], 0, grid.shape[1] - 1)
        return grid[ix, iy]

    def lookup_flat(self, level: int, flat: np.ndarray) -> np.ndarray:
        """Values of ``level`` (in 255ths) at flat cell indices (``x * ny + y``), unchecked."""
        return self.levels[level].ravel().take(flat)


def hit_cells(points: np.ndarray, origin: np.ndarray, resolution_m: float, shape: tuple[int, int]) -> np.ndarray:
    """Boolean grid (shape) of the cells holding at least one of ``points`` (n, 2)."""
    hits = np.zeros(shape, dtype=bool)
    c = np.floor((points - origin) / resolution_m).astype(np.int64)
    inside = (c[:, 0] >= 0) & (c[:, 0] < shape[0]) & (c[:, 1] >= 0) & (c[:, 1] < shape[1])
    hits[c[inside, 0], c[inside, 1]] = True
    return hits


def likelihood_field(hits: np.ndarray, resolution_m: float, sigma_m: float) -> np.ndarray:
    """``exp(-d^2 / (2 sigma^2))`` per cell, ``d`` (m) its distance to the
    nearest hit cell, cut to 0 beyond 3 sigma (float32).

    The maximum over hits of a Gaussian of the distance is separable (a
    max-product convolution with ``g(dx) g(dy)``), so it is two passes of
    shifted maxima along each axis, on the rows and columns that hold hits
    or lie within reach of one."""
    field = np.zeros(hits.shape, dtype=np.float32)
    if not hits.any():
        return field
    reach = int(np.ceil(3.0 * sigma_m / resolution_m))
    g = np.exp(-0.5 * (np.arange(-reach, reach + 1) * resolution_m / sigma_m) ** 2).astype(np.float32)
    rows = np.nonzero(hits.any(axis=1))[0]
    cols = np.nonzero(hits.any(axis=0))[0]
    x0, x1 = max(rows[0] - reach, 0), min(rows[-1] + reach + 1, hits.shape[0])
    y0, y1 = max(cols[0] - reach, 0), min(cols[-1] + reach + 1, hits.shape[1])
    h = hits[x0:x1, y0:y1].astype(np.float32)
    # Pass along y, then along x: out[x, y] = max_k g[k] * in[x, y + k - reach].
    for axis in (1, 0):
        src, out = h, np.zeros_like(h)
        n = src.shape[axis]
        for k, w in enumerate(g):
            shift = k - reach
            lo, hi = max(0, -shift), min(n, n - shift)
            if lo >= hi:
                continue
            dst = [slice(None), slice(None)]
            from_ = [slice(None), slice(None)]
            dst[axis], from_[axis] = slice(lo, hi), slice(lo + shift, hi + shift)
            np.maximum(out[tuple(dst)], w * src[tuple(from_)], out=out[tuple(dst)])
        h = out
    field[x0:x1, y0:y1] = h
    return field


def max_pool_levels(field: np.ndarray, depth: int) -> tuple[np.ndarray, ...]:
    """``field`` and its levels 1..``depth``: level h at (x, y) is the maximum
    of ``field`` over [x, x + 2^h) x [y, y + 2^h) (cells beyond the edge
    count as 0)."""
    levels = [field]
    for h in range(1, depth + 1):
        prev, half = levels[-1], 1 << (h - 1)
        cur = prev.copy()
        np.maximum(cur[:-half], prev[half:], out=cur[:-half])
        nxt = cur.copy()
        np.maximum(nxt[:, :-half], cur[:, half:], out=nxt[:, :-half])
        levels.append(nxt)
    return tuple(levels)


def score_pyramid(points: np.ndarray, resolution_m: float, sigma_m: float, depth: int, margin_m: float,
                  pad_cells: int = 0) -> ScorePyramid:
    """The :class:`ScorePyramid` of map points (n, 2): a field over their
    bounding box grown by ``margin_m`` (the field's tail), with ``depth``
    max-pooled levels above it, and ``pad_cells`` more empty cells on every
    side (see :attr:`ScorePyramid.pad`)."""
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    if len(pts) == 0:
        pts = np.zeros((1, 2))
    pad_low = (1 << depth) + pad_cells
    lo = pts.min(axis=0) - margin_m
    hi = pts.max(axis=0) + margin_m
    inner = np.ceil((hi - lo) / resolution_m).astype(int) + 1
    origin = lo - pad_low * resolution_m
    shape = (int(inner[0]) + 2 * pad_low + 1, int(inner[1]) + 2 * pad_low + 1)
    if shape[0] * shape[1] >= 2**31:
        raise ValueError(f"a score grid of {shape[0]} x {shape[1]} cells of {resolution_m:g} m: too large")
    hits = hit_cells(pts, origin, resolution_m, shape) if len(points) else np.zeros(shape, dtype=bool)
    field = likelihood_field(hits, resolution_m, sigma_m)
    # The padding stays empty: the field's tail reaches into it only as far
    # as margin_m allows, and the low pad must read 0 for clipped indices.
    field[:pad_low] = 0.0
    field[:, :pad_low] = 0.0
    field[-pad_low - 1 :] = 0.0
    field[:, -pad_low - 1 :] = 0.0
    # Rounding is monotone, so pooling the rounded field pools the field.
    quantised = np.rint(field * LEVELS).astype(np.uint8)
    return ScorePyramid(max_pool_levels(quantised, depth), origin, resolution_m, pad_low)
