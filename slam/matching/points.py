"""Point maps for 2D matching: planar points thinned to one per voxel,
each with the normal of the wall it lies on, and a nearest-point index.

Frames: the points, their normals and the queries are in one frame (m).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view

NEAR_TIE = 1e-9
"""Relative difference of squared distances below which :meth:`PointMap.nearest`
asks the k-d tree (whose distances may differ from the grid's in the last bits)."""


def voxel_first(points: np.ndarray, voxel_m: float) -> np.ndarray:
    """Indices (sorted) of the first point in each occupied voxel."""
    if len(points) == 0:
        return np.zeros(0, dtype=np.int64)
    cells = np.floor(points / voxel_m).astype(np.int64)
    cells -= cells.min(axis=0)
    key = cells[:, 0] * (int(cells[:, 1].max()) + 1) + cells[:, 1]
    _, first = np.unique(key, return_index=True)
    return np.sort(first)


def scan_normals(
    points: np.ndarray, half_window: int, max_gap_m: float, scan: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Unit normals (m, 2) of a scan's points (m, 2) in beam order, from the
    ``2 * half_window + 1`` consecutive points around each, and the
    linearity (m,) of that stretch in [0, 1]: 1 - minor / major spread, 1
    on a straight wall; 0 where the stretch is cut (ends of the scan, two
    neighbours more than ``max_gap_m`` apart, or, with ``scan`` (m,) the
    scan of each point for several scans in a row, a change of scan)."""
    m = len(points)
    w = 2 * half_window + 1
    normals = np.zeros((m, 2))
    linearity = np.zeros(m)
    if m < w:
        return normals, linearity
    win = sliding_window_view(points, (w, 2))[:, 0]  # (m - w + 1, w, 2)
    gaps = np.hypot(*np.diff(win, axis=1).transpose(2, 0, 1)).max(axis=1)
    d = win - win.mean(axis=1, keepdims=True)
    cxx = (d[..., 0] ** 2).sum(axis=1)
    cyy = (d[..., 1] ** 2).sum(axis=1)
    cxy = (d[..., 0] * d[..., 1]).sum(axis=1)
    major = 0.5 * np.arctan2(2.0 * cxy, cxx - cyy)  # direction of the line
    half_trace = 0.5 * (cxx + cyy)
    root = np.sqrt(np.maximum(0.25 * (cxx - cyy) ** 2 + cxy**2, 0.0))
    lam_major, lam_minor = half_trace + root, np.maximum(half_trace - root, 0.0)
    lin = np.where(lam_major > 0, 1.0 - lam_minor / np.maximum(lam_major, 1e-12), 0.0)
    lin = np.where(gaps <= max_gap_m, lin, 0.0)
    if scan is not None:
        scan_win = sliding_window_view(np.asarray(scan), w)
        lin = np.where(scan_win[:, 0] == scan_win[:, -1], lin, 0.0)
    centre = slice(half_window, m - half_window)
    normals[centre] = np.column_stack([-np.sin(major), np.cos(major)])
    linearity[centre] = lin
    return normals, linearity


@dataclass(frozen=True)
class PointMap:
    """Map points (m, 2) with unit normals (m, 2), and a k-d tree over the points."""

    points: np.ndarray
    normals: np.ndarray
    _cells: dict = field(default_factory=dict, compare=False, repr=False)

    def __len__(self) -> int:
        return len(self.points)

    @cached_property
    def tree(self):
        """The k-d tree (scipy's cKDTree) over the points, built when first
        asked for: :meth:`nearest` seldom needs it."""
        from scipy.spatial import cKDTree

        return cKDTree(self.points)

    def nearest(self, queries: np.ndarray, within_m: float) -> np.ndarray:
        """Index (q,) of each query's (q, 2) nearest point closer than
        ``within_m``, -1 for none: the k-d tree's answer. Found among the
        points of the 3 x 3 cells (a little wider than ``within_m``) around
        each query, compiled (:func:`slam.matching.kernels.nearest_within`),
        a few times faster than the tree for a scan's few hundred queries;
        where the last bits of a distance decide (two points about as near,
        or the nearest about ``within_m`` away), the tree answers, so the
        answer is always the tree's."""
        from slam.matching import kernels

        queries = np.ascontiguousarray(queries, dtype=np.float64)
        if len(self.points) == 0 or len(queries) == 0:
            return np.full(len(queries), -1, dtype=np.int64)
        grid = self._cells.get(within_m)
        if grid is None:  # cells as wide as the reach: the fewest points to look at
            # A point within reach is at most one cell away, rounding and all;
            # a map much wider than the reach gets coarser cells, not millions.
            cell_m = max(within_m * (1.0 + 1e-6), float(np.ptp(self.points, axis=0).max()) / 1024)
            grid = self._cells[within_m] = (cell_m, *kernels.cell_index(self.points, cell_m))
        cell_m, lo, nx, ny, order, starts = grid
        idx, unsure = kernels.nearest_within(queries, self.points, lo, nx, ny, cell_m, order, starts, within_m,
                                             NEAR_TIE)
        if unsure.any():
            dist, near = self.tree.query(queries[unsure], distance_upper_bound=within_m)
            idx[unsure] = np.where(np.isfinite(dist), near, -1)
        return idx


def point_map(points: np.ndarray, normals: np.ndarray) -> PointMap:
    """The :class:`PointMap` of points (m, 2) and their normals (m, 2)."""
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    return PointMap(pts, np.asarray(normals, dtype=np.float64).reshape(-1, 2))
