"""An occupancy grid of the mapped run: a log-odds probability grid built by
casting every keyframe's laser beams from its optimised pose.

Each beam says the cells it crosses are free and the cell it ends in is
occupied (the inverse sensor model of Thrun et al., "Probabilistic
Robotics", 9.2): a hit adds ``logit(hit_probability)`` to its cell, a
crossing adds ``logit(miss_probability)``. A beam without a return (``inf``,
or at or beyond the scanner's range) says only that the first
``no_return_m`` are free; a NaN, ``-inf`` or too short beam says nothing.
The updates are summed over the whole run, so the grid does not depend on
the order of the scans (an offline map of a static world).

Vectorised over all beams of a chunk of keyframes at once: the free part of
each beam is sampled every cell length (:func:`crossed_cells`), and hits and
crossings are counted per cell with ``np.bincount``. Near the scanner,
neighbouring beams cross the same cells many times over; a beam is sampled
only from where the coarser fan of beams it belongs to grows wider than a
cell (:func:`free_start`), so that a cell is crossed about as often by one
scan whatever the scanner's angular resolution, and intel's 910 scans take
a fraction of a second.

Frames and layout: ``OccupancyGrid.log_odds[row, col]`` is the cell whose
lower-left corner is ``origin + (col, row) * resolution_m`` in the world
frame (m); row 0 is the lowest y. That is the order of
``nav_msgs/OccupancyGrid.data`` (row-major from the origin); the map_server
image is the same grid flipped upside down (:mod:`slam.outputs.map_server`).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from slam.recording import Trajectory

log = logging.getLogger(__name__)

OCCUPIED, FREE, UNKNOWN = 100, 0, -1
"""Cell values of ``nav_msgs/OccupancyGrid`` (and map_server's trinary mode)."""

OCCUPIED_ABOVE = 0.65
FREE_BELOW = 0.196
"""A cell is occupied above, free below these probabilities, else unknown:
the thresholds of ROS's map_saver, written into ``map.yaml``."""

MAX_CELLS = 200_000_000
"""Larger grids are not built (a fifth of a GB per float32 layer)."""

_CHUNK_SAMPLES = 4_000_000  # samples per batch: bounds memory, not results


@dataclass(frozen=True)
class GridModel:
    """How beams update cells: the probability that a cell a beam ends in
    is occupied (``hit_probability`` > 0.5) or one it crosses
    (``miss_probability`` < 0.5); ``no_return_m``: how far a beam without a
    return is taken as free; ``resolution_m``: the cell size."""

    resolution_m: float = 0.05
    hit_probability: float = 0.7
    miss_probability: float = 0.4
    no_return_m: float = 5.0


@dataclass(frozen=True)
class GridMap:
    """A classified grid as ``nav_msgs/OccupancyGrid`` and map_server hold
    it: ``cells`` (rows, cols) int8 100 occupied, 0 free, -1 unknown, row 0
    at ``origin`` (x, y of cell (0, 0)'s lower-left corner, world frame, m),
    ``resolution_m`` the cell size."""

    cells: np.ndarray
    origin: np.ndarray
    resolution_m: float

    def extent(self) -> tuple[float, float, float, float]:
        """(x_min, x_max, y_min, y_max) of the grid in the world frame, m."""
        rows, cols = self.cells.shape
        x0, y0 = float(self.origin[0]), float(self.origin[1])
        return x0, x0 + cols * self.resolution_m, y0, y0 + rows * self.resolution_m


@dataclass(frozen=True)
class OccupancyGrid:
    """Summed log-odds per cell (rows along y, columns along x; see the
    module docstring), which cells any beam touched, the world position
    of cell (0, 0)'s lower-left corner (m) and the cell size (m)."""

    log_odds: np.ndarray
    observed: np.ndarray
    origin: np.ndarray
    resolution_m: float

    @property
    def shape(self) -> tuple[int, int]:
        """(rows, columns) = (height, width) in cells."""
        return self.log_odds.shape

    def probability(self) -> np.ndarray:
        """Occupancy probability per cell (0.5 where unobserved)."""
        return 1.0 / (1.0 + np.exp(-self.log_odds.astype(np.float64)))

    def classify(self, free_below: float = FREE_BELOW, occupied_above: float = OCCUPIED_ABOVE) -> GridMap:
        """The map: occupied where the probability is above ``occupied_above``,
        free below ``free_below``, unknown elsewhere and where no beam came."""
        p = self.probability()
        cells = np.full(self.shape, UNKNOWN, dtype=np.int8)
        cells[p < free_below] = FREE
        cells[p > occupied_above] = OCCUPIED
        cells[~self.observed] = UNKNOWN
        return GridMap(cells, self.origin, self.resolution_m)


def logit(p: float) -> float:
    return float(np.log(p / (1.0 - p)))


def free_start(n_beams: int, increment_rad: float, resolution_m: float) -> np.ndarray:
    """Range (m) from which each beam's free cells are sampled.

    Beams whose index is a multiple of ``2^k`` are ``2^k`` increments apart,
    so they lie within a cell of each other up to ``resolution_m / (2^k
    increment)``. A beam whose index has exactly ``k`` trailing zero bits is
    therefore needed only beyond half that range: beyond it the beams of the
    coarser fans leave gaps wider than a cell. Beam 0 starts at the scanner."""
    index = np.arange(n_beams)
    reach = resolution_m / max(abs(increment_rad), 1e-9)  # where neighbouring beams are a cell apart
    zeros = np.zeros(n_beams)
    nonzero = index > 0
    zeros[nonzero] = np.log2(index[nonzero] & -index[nonzero])  # trailing zero bits
    start = reach / 2.0 ** (zeros + 1)
    start[0] = 0.0
    return start


def crossed_cells(x0: np.ndarray, y0: np.ndarray, dx: np.ndarray, dy: np.ndarray, counts: np.ndarray,
                  cols: int) -> np.ndarray:
    """Flat cells (row * cols + col, int64) of the samples ``(x0, y0) + j
    (dx, dy)``, ``j < counts``, of every beam (all (n,), in cells from a
    corner below and left of every sample).

    The beams are taken longest first, so that the ones still running at
    sample ``j`` are a prefix: each step is a few operations on contiguous
    slices, without an index per sample."""
    order = np.argsort(-counts, kind="stable")
    counts = counts[order]
    x0, y0 = x0[order].astype(np.float32), y0[order].astype(np.float32)
    dx, dy = dx[order].astype(np.float32), dy[order].astype(np.float32)
    longest = int(counts[0]) if len(counts) else 0
    running = np.searchsorted(-counts, -np.arange(longest), side="left")  # beams with counts > j
    out = np.empty(int(running.sum()), dtype=np.int64)  # bincount's own type: no copy
    at = 0
    for j, m in enumerate(running.tolist()):
        col = (x0[:m] + np.float32(j) * dx[:m]).astype(np.int32)
        row = (y0[:m] + np.float32(j) * dy[:m]).astype(np.int32)
        np.multiply(row, np.int32(cols), out=row)
        np.add(row, col, out=out[at : at + m])
        at += m
    return out


@dataclass(frozen=True)
class BeamCounts:
    """Per cell (rows, cols; laid out as :class:`OccupancyGrid`): how many
    beams ended in it (``hits``) and how many crossed it (``misses``), and
    the world position of cell (0, 0)'s lower-left corner (m)."""

    hits: np.ndarray
    misses: np.ndarray
    origin: np.ndarray
    resolution_m: float

    def cells(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(row, col) of world points (m) inside the grid."""
        return (((y - self.origin[1]) / self.resolution_m).astype(np.int64),
                ((x - self.origin[0]) / self.resolution_m).astype(np.int64))


def build_grid(
    ranges: np.ndarray,
    angles: np.ndarray,
    poses: Trajectory,
    min_range_m: float,
    max_range_m: float,
    model: GridModel,
) -> OccupancyGrid | None:
    """The occupancy grid of scans ``ranges`` (K, beams), m, with beam
    ``angles`` (beams,) rad, taken at ``poses`` (K; world frame, m, rad;
    the laser at the pose). Beams shorter than ``min_range_m`` say nothing;
    beams at or beyond ``max_range_m`` (and ``inf``) are no return. None
    when the grid would exceed :data:`MAX_CELLS`."""
    counts = beam_counts(ranges, angles, poses, min_range_m, max_range_m, model.resolution_m, model.no_return_m)
    if counts is None:
        return None
    hits, misses = counts.hits.ravel(), counts.misses.ravel()
    log_odds = (hits * logit(model.hit_probability) + misses * logit(model.miss_probability)).astype(np.float32)
    observed = (hits + misses) > 0
    return OccupancyGrid(log_odds.reshape(counts.hits.shape), observed.reshape(counts.hits.shape), counts.origin,
                         counts.resolution_m)


def beam_counts(
    ranges: np.ndarray,
    angles: np.ndarray,
    poses: Trajectory,
    min_range_m: float,
    max_range_m: float,
    resolution_m: float,
    no_return_m: float,
) -> BeamCounts | None:
    """The hits and crossings per cell of :func:`build_grid`'s beams (the
    same arguments; a beam without a return is free for ``no_return_m``).
    None when the grid would exceed :data:`MAX_CELLS`."""
    res = resolution_m
    angles = np.asarray(angles, dtype=np.float64)
    with np.errstate(invalid="ignore"):
        hit = np.isfinite(ranges) & (ranges >= min_range_m) & (ranges < max_range_m)
        no_return = (ranges >= max_range_m) | (np.isposinf(ranges))
    free_len = np.where(hit, ranges, np.where(no_return, min(no_return_m, max_range_m), 0.0))
    increment = float(np.median(np.diff(angles))) if len(angles) > 1 else np.pi
    start = free_start(len(angles), increment, res)

    # 1. The grid's extent: every pose and every beam's far end, a cell around.
    heading = poses.yaw[:, None] + angles[None, :]
    cos, sin = np.cos(heading), np.sin(heading)
    far = np.where(hit | no_return, free_len, 0.0)
    xs = np.concatenate([poses.x, (poses.x[:, None] + far * cos).ravel()])
    ys = np.concatenate([poses.y, (poses.y[:, None] + far * sin).ravel()])
    origin = np.round(np.floor(np.array([xs.min(), ys.min()]) / res) * res - res, 6)  # as map.yaml writes it
    cols = int(np.ceil((xs.max() - origin[0]) / res)) + 2
    rows = int(np.ceil((ys.max() - origin[1]) / res)) + 2
    if rows * cols > MAX_CELLS:
        log.warning("occupancy grid not built: %d x %d cells of %g m exceed %d; choose a coarser "
                    "output.grid_resolution_m", cols, rows, res, MAX_CELLS)
        return None

    # 2. Hits: each beam's end cell.
    k, b = np.nonzero(hit)
    end_cell = _cells(poses.x[k] + ranges[k, b] * cos[k, b], poses.y[k] + ranges[k, b] * sin[k, b], origin, res, cols)
    hits = np.bincount(end_cell, minlength=rows * cols)

    # 3. Crossings: one sample per cell length along each beam's free part,
    #    stopping a cell short of its end; in cells from the grid's origin.
    misses = np.zeros(rows * cols, dtype=np.int64)
    stop = np.where(hit, free_len - res, free_len) / res
    first = np.broadcast_to(start / res, ranges.shape)
    counts = np.maximum(np.ceil(stop - first), 0).astype(np.int64)
    x0 = (poses.x[:, None] - origin[0]) / res + first * cos
    y0 = (poses.y[:, None] - origin[1]) / res + first * sin
    batch = max(1, int(_CHUNK_SAMPLES / (counts.sum() / max(len(ranges), 1) + 1.0)))
    for lo in range(0, len(ranges), batch):
        sl = slice(lo, lo + batch)
        y, dy, n = y0[sl].ravel(), sin[sl].ravel(), counts[sl].ravel()
        if not n.any():
            continue
        last = y + np.maximum(n - 1, 0) * dy
        low = max(int(np.floor(min(y.min(), last.min()))), 0)  # the batch's lowest row: count from there
        counted = np.bincount(crossed_cells(x0[sl].ravel(), y - low, cos[sl].ravel(), dy, n, cols))
        misses[low * cols : low * cols + len(counted)] += counted

    return BeamCounts(hits.reshape(rows, cols), misses.reshape(rows, cols), origin, res)


def _cells(x: np.ndarray, y: np.ndarray, origin: np.ndarray, res: float, cols: int) -> np.ndarray:
    """Flat cell index (row * cols + col) of world points."""
    col = ((x - origin[0]) / res).astype(np.int64)
    row = ((y - origin[1]) / res).astype(np.int64)
    return row * cols + col
