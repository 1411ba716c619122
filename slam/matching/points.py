"""Point maps for 2D matching: planar points thinned to one per voxel,
each with the normal of the wall it lies on, and a nearest-point index.

Frames: the points, their normals and the queries are in one frame (m).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view


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
    """Map points (m, 2) with unit normals (m, 2) and a k-d tree over the points."""

    points: np.ndarray
    normals: np.ndarray
    tree: object

    def __len__(self) -> int:
        return len(self.points)


def point_map(points: np.ndarray, normals: np.ndarray) -> PointMap:
    """The :class:`PointMap` of points (m, 2) and their normals (m, 2)."""
    from scipy.spatial import cKDTree

    pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    return PointMap(pts, np.asarray(normals, dtype=np.float64).reshape(-1, 2), cKDTree(pts))
