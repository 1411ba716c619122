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

    ``stack`` (levels, nx, ny) uint8: level ``h`` is ``stack[h]``, the
    field in 255ths (a quarter of the memory of floats, and as fast to
    gather); ``stack[0]`` is the field itself.
    """

    stack: np.ndarray
    origin: np.ndarray
    resolution_m: float
    pad: int = 0
    """Empty cells on each side: cells clipped into ``[0, shape - 1 - w]``
    and then shifted by up to ``w <= pad - 2^depth`` stay inside the grid
    and read 0 where the truth is 0 or outside."""

    @property
    def levels(self) -> tuple[np.ndarray, ...]:
        """The levels (nx, ny), finest first."""
        return tuple(self.stack)

    @property
    def depth(self) -> int:
        """The coarsest level's index."""
        return len(self.stack) - 1

    @property
    def field(self) -> np.ndarray:
        return self.stack[0]

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
        grid = self.stack[level]
        ix = np.clip(cells[..., 0], 0, grid.shape[0] - 1)
        iy = np.clip(cells[..., 1], 0, grid.shape[1] - 1)
        return grid[ix, iy]

    def lookup_flat(self, level: int, flat: np.ndarray) -> np.ndarray:
        """Values of ``level`` (in 255ths) at flat cell indices (``x * ny + y``), unchecked."""
        return self.stack[level].ravel().take(flat)


def _hits(points: np.ndarray, origin: np.ndarray, resolution_m: float,
          shape: tuple[int, int]) -> tuple[np.ndarray, tuple[int, int, int, int] | None]:
    """:func:`hit_cells`, and the first and last row and column holding a
    hit (None for no hit)."""
    hits = np.zeros(shape, dtype=bool)
    c = np.floor((points - origin) / resolution_m).astype(np.int64)
    inside = (c[:, 0] >= 0) & (c[:, 0] < shape[0]) & (c[:, 1] >= 0) & (c[:, 1] < shape[1])
    cx, cy = c[inside, 0], c[inside, 1]
    hits[cx, cy] = True
    if len(cx) == 0:
        return hits, None
    return hits, (int(cx.min()), int(cx.max()), int(cy.min()), int(cy.max()))


def hit_cells(points: np.ndarray, origin: np.ndarray, resolution_m: float, shape: tuple[int, int]) -> np.ndarray:
    """Boolean grid (shape) of the cells holding at least one of ``points`` (n, 2)."""
    return _hits(points, origin, resolution_m, shape)[0]


def likelihood_field(hits: np.ndarray, resolution_m: float, sigma_m: float) -> np.ndarray:
    """``exp(-d^2 / (2 sigma^2))`` per cell, ``d`` (m) its distance to the
    nearest hit cell, cut to 0 beyond 3 sigma (float32).

    The maximum over hits of a Gaussian of the distance is separable (a
    max-product convolution with ``g(dx) g(dy)``), so it is two passes of
    maxima along each axis, over the box of rows and columns that hold hits
    or lie within reach of one (compiled: :func:`slam.matching.kernels.spread_hits`)."""
    field = np.zeros(hits.shape, dtype=np.float32)
    if not hits.any():
        return field
    rows = np.nonzero(hits.any(axis=1))[0]
    cols = np.nonzero(hits.any(axis=0))[0]
    _spread(hits, (rows[0], rows[-1], cols[0], cols[-1]), resolution_m, sigma_m, field)
    return field


def _spread(hits: np.ndarray, hit_box: tuple[int, int, int, int], resolution_m: float, sigma_m: float,
            field: np.ndarray) -> tuple[int, int, int, int]:
    """Into ``field`` (zeros), the likelihood field of ``hits``, whose hits
    lie in rows and columns ``hit_box`` (first and last of each); returns
    the box (x0, x1, y0, y1, ends excluded) outside which it stays 0."""
    reach = int(np.ceil(3.0 * sigma_m / resolution_m))
    g = np.exp(-0.5 * (np.arange(-reach, reach + 1) * resolution_m / sigma_m) ** 2).astype(np.float32)
    x0, x1 = max(hit_box[0] - reach, 0), min(hit_box[1] + reach + 1, hits.shape[0])
    y0, y1 = max(hit_box[2] - reach, 0), min(hit_box[3] + reach + 1, hits.shape[1])
    from slam.matching import kernels

    kernels.spread_hits(np.ascontiguousarray(hits), g, x0, x1, y0, y1, field)
    return x0, x1, y0, y1


def max_pool_stack(field: np.ndarray, depth: int) -> np.ndarray:
    """``field`` (nx, ny) and its levels 1..``depth`` stacked (depth + 1, nx,
    ny): level h at (x, y) is the maximum of ``field`` over [x, x + 2^h) x
    [y, y + 2^h) (cells beyond the edge count as 0)."""
    stack = np.empty((depth + 1,) + field.shape, dtype=field.dtype)
    stack[0] = field
    rows = np.empty_like(field)
    for h in range(1, depth + 1):
        prev, cur, half = stack[h - 1], stack[h], 1 << (h - 1)
        # Along x, then along y; numpy's maxima of uint8 run wider than a compiled loop's.
        np.maximum(prev[:-half], prev[half:], out=rows[:-half])
        rows[-half:] = prev[-half:]
        np.maximum(rows[:, :-half], rows[:, half:], out=cur[:, :-half])
        cur[:, -half:] = rows[:, -half:]
    return stack


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
    stack = np.zeros((depth + 1,) + shape, dtype=np.uint8)
    hits, hit_box = _hits(pts, origin, resolution_m, shape) if len(points) else (None, None)
    if hit_box is None:
        return ScorePyramid(stack, origin, resolution_m, pad_low)
    field = np.zeros(shape, dtype=np.float32)
    x0, x1, y0, y1 = _spread(hits, hit_box, resolution_m, sigma_m, field)
    # The padding stays empty: the field's tail reaches into it only as far
    # as margin_m allows, and the low pad must read 0 for clipped indices.
    field[:pad_low] = 0.0
    field[:, :pad_low] = 0.0
    field[-pad_low - 1 :] = 0.0
    field[:, -pad_low - 1 :] = 0.0
    # Every level is 0 but over the field's box and the 2^depth - 1 cells
    # below it (a level looks up from a cell, never down): pool that crop
    # alone, whose high edge reads 0 as the grid's does beyond the box.
    x0, y0 = max(x0 - (1 << depth) + 1, 0), max(y0 - (1 << depth) + 1, 0)
    # Rounding is monotone, so pooling the rounded field pools the field.
    quantised = np.rint(field[x0:x1, y0:y1] * LEVELS).astype(np.uint8)
    stack[:, x0:x1, y0:y1] = max_pool_stack(quantised, depth)
    return ScorePyramid(stack, origin, resolution_m, pad_low)
