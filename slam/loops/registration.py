"""Point-to-line ICP of planar points against a point map, with its
information matrix.

A *point map* holds planar points with a unit normal each (from the scan
they came from, see :func:`scan_normals`) and a nearest-point lookup grid.
:func:`register` minimises the point-to-line residuals ``n_m . (R q + t - m)``
of the query points ``q`` against their nearest map points ``m`` (Gauss-Newton,
Cauchy weights), starting from a guessed pose; the correspondence distance
halves from ``max_distance_m`` down to ``inlier_distance_m`` (coarse to fine).

The result carries what verification needs: the fraction of query points
with a correspondence within the final, tight distance (overlap), the RMS
residual of those, and the information matrix ``J^T W J / sigma^2`` of the
pose, with sigma^2 the weighted residual variance. A corridor shows up there:
walls that are all parallel give no information along them.

Frames: the query points are in the query frame, the map points and the
returned pose (x, y, yaw; m, rad) in the map frame.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view

from slam.geometry import rotation

_NO_POINT = np.iinfo(np.int64).max
_INDEX_BITS = 24


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


class NearestGrid:
    """Nearest map point of every cell of a grid within ``radius_m`` of
    the points (cells of ``resolution_m``; nearest to the cell's centre), so
    a query is one lookup. The association is approximate (within half a
    cell diagonal); the residual uses the exact point and normal."""

    def __init__(self, points: np.ndarray, resolution_m: float, radius_m: float):
        self.resolution_m = resolution_m
        reach = int(np.ceil(radius_m / resolution_m))
        n = len(points)
        if n == 0:
            self.origin, self.shape = np.zeros(2), (1, 1)
            self.table = np.full(1, -1, dtype=np.int64)
            return
        self.origin = points.min(axis=0) - (reach + 1) * resolution_m
        pos = (points - self.origin) / resolution_m
        cells = np.floor(pos).astype(np.int64)
        self.shape = (int(cells[:, 0].max()) + reach + 2, int(cells[:, 1].max()) + reach + 2)
        r = np.arange(-reach, reach + 1)
        off = np.stack(np.meshgrid(r, r, indexing="ij"), axis=-1).reshape(-1, 2)
        off = off[(off**2).sum(axis=1) <= (reach + 1) ** 2]
        target = cells[:, None, :] + off[None]  # (n, offsets, 2)
        d2 = ((target + 0.5 - pos[:, None, :]) ** 2).sum(axis=2)  # in cells^2
        # Pack (distance, index) in one integer: the minimum is the nearest point.
        key = (np.round(d2 * 1e4).astype(np.int64) << _INDEX_BITS) | np.arange(n)[:, None]
        flat = target[..., 0] * self.shape[1] + target[..., 1]
        table = np.full(self.shape[0] * self.shape[1], _NO_POINT, dtype=np.int64)
        np.minimum.at(table, flat.ravel(), key.ravel())
        self.table = np.where(table == _NO_POINT, -1, table & ((1 << _INDEX_BITS) - 1))

    def lookup(self, queries: np.ndarray) -> np.ndarray:
        """Index of the nearest point for each query (m,), -1 if none near."""
        cells = np.floor((queries - self.origin) / self.resolution_m).astype(np.int64)
        inside = (cells[:, 0] >= 0) & (cells[:, 0] < self.shape[0]) & (cells[:, 1] >= 0) & (cells[:, 1] < self.shape[1])
        flat = np.where(inside, cells[:, 0] * self.shape[1] + cells[:, 1], 0)
        return np.where(inside, self.table[flat], -1)


@dataclass
class PointMap:
    """Planar points (m, 2), their unit normals (m, 2), and a nearest-point grid."""

    points: np.ndarray
    normals: np.ndarray
    grid: NearestGrid

    def __len__(self) -> int:
        return len(self.points)


def build_point_map(points: np.ndarray, normals: np.ndarray, resolution_m: float, radius_m: float) -> PointMap:
    """A point map whose lookups reach ``radius_m`` (the largest
    correspondence distance) on cells of ``resolution_m``."""
    pts = np.asarray(points, dtype=np.float64)
    return PointMap(pts, np.asarray(normals, dtype=np.float64), NearestGrid(pts, resolution_m, radius_m))


@dataclass
class Registration:
    """Outcome of :func:`register`.

    ``pose``: the query frame in the map frame (x, y, yaw). ``information``
    (3, 3): of (x, y, yaw) in the map frame's axes at the pose, from the
    point-to-line Jacobians and the residual variance. ``rms_m``: RMS
    point-to-line residual of the correspondences. ``overlap``: fraction of
    query points with a correspondence. ``n_matched``: their number.
    """

    pose: np.ndarray
    information: np.ndarray
    rms_m: float
    overlap: float
    n_matched: int
    iterations: int
    converged: bool


def _residuals(q: np.ndarray, pmap: PointMap, pose: np.ndarray, max_distance_m: float):
    """Correspondences of ``q`` at ``pose`` within ``max_distance_m``: mask
    (n,), point-to-line residuals (m,) and Jacobians (m, 3) of the matched."""
    rq = q @ rotation(pose[2]).T
    qw = rq + pose[:2]
    idx = pmap.grid.lookup(qw)
    found = idx >= 0
    diff = qw - pmap.points[np.maximum(idx, 0)]
    ok = found & ((diff**2).sum(axis=1) <= max_distance_m**2)
    n = pmap.normals[idx[ok]]
    res = np.einsum("ij,ij->i", n, diff[ok])
    rq = rq[ok]
    jac = np.column_stack([n[:, 0], n[:, 1], n[:, 1] * rq[:, 0] - n[:, 0] * rq[:, 1]])
    return ok, res, jac


def register(
    query: np.ndarray,
    pmap: PointMap,
    guess: np.ndarray,
    max_distance_m: float,
    inlier_distance_m: float,
    kernel_m: float,
    max_iterations: int = 30,
    tolerance: float = 1e-3,
) -> Registration:
    """Align ``query`` points (n, 2) to ``pmap`` from the pose ``guess``
    (x, y, yaw); see the module docstring.

    The correspondence distance starts at ``max_distance_m`` (at most the
    map's lookup radius) and halves each iteration down to
    ``inlier_distance_m``; ``kernel_m`` is the Cauchy scale of the
    point-to-line residual. ``overlap``, ``rms_m`` and the information are
    taken at the end with ``inlier_distance_m``.
    """
    pose = np.asarray(guess, dtype=np.float64).copy()
    q = np.asarray(query, dtype=np.float64)
    empty = Registration(pose, np.zeros((3, 3)), np.inf, 0.0, 0, 0, False)
    if len(q) < 3 or len(pmap) < 3:
        return empty
    converged = False
    gate = max_distance_m
    iteration = 0
    for iteration in range(1, max_iterations + 1):
        ok, res, jac = _residuals(q, pmap, pose, gate)
        if len(res) < 3:
            return empty
        w = 1.0 / (1.0 + (res / kernel_m) ** 2)
        h = jac.T @ (jac * w[:, None])
        try:
            step = -np.linalg.solve(h + 1e-9 * np.eye(3), jac.T @ (w * res))
        except np.linalg.LinAlgError:
            return empty
        pose += step
        small = np.abs(step[:2]).max() < tolerance and abs(step[2]) < tolerance
        if small and gate <= inlier_distance_m:
            converged = True
            break
        gate = max(gate * 0.5, inlier_distance_m)
    ok, res, jac = _residuals(q, pmap, pose, inlier_distance_m)
    if len(res) < 4:
        return empty
    w = 1.0 / (1.0 + (res / kernel_m) ** 2)
    variance = float(np.sum(w * res**2) / max(np.sum(w) - 3.0, 1.0))
    information = jac.T @ (jac * w[:, None]) / max(variance, 1e-12)
    rms = float(np.sqrt(np.mean(res**2)))
    return Registration(pose, information, rms, float(ok.mean()), int(ok.sum()), iteration, converged)
