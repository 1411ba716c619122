"""Point-to-line ICP of a 2D scan against a point map, with its information
matrix.

A *point map* holds planar points with a unit normal each, estimated from
their ``normal_neighbours`` nearest neighbours (the direction of least
spread), and a k-d tree. :func:`register` minimises the point-to-line
residuals ``n_m . (R q + t - m)`` of the query points ``q`` against their
nearest map points ``m`` (Gauss-Newton, Cauchy weights, correspondences
farther than ``max_distance_m`` dropped), starting from a guessed pose.

The result carries what verification needs: the fraction of query points
with a correspondence within the final, tight distance (overlap), the RMS
residual of those, and the
information matrix ``J^T W J / sigma^2`` of the pose, with sigma^2 the
weighted residual variance. A corridor shows up there: walls that are all
parallel give no information along them, and the smallest eigenvalue of the
information (in metres, see :func:`weakest_direction`) says how well the
worst direction is pinned. Frames: the query points are in the query frame,
the map points and the returned pose (x, y, yaw; m, rad) in the map frame.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from slam.io.pointcloud import voxel_downsample


@dataclass
class PointMap:
    """Planar points (m, 2), unit normals (m, 2), and a k-d tree over the points."""

    points: np.ndarray
    normals: np.ndarray
    tree: cKDTree

    def __len__(self) -> int:
        return len(self.points)


def estimate_normals(points: np.ndarray, neighbours: int) -> tuple[np.ndarray, np.ndarray]:
    """Unit normals (m, 2) of planar points from their ``neighbours``
    nearest points, and the linearity (m,) of each neighbourhood in [0, 1]:
    1 - (minor / major spread), 1 on a straight wall, 0 on a blob."""
    k = min(neighbours, len(points))
    tree = cKDTree(points)
    _, idx = tree.query(points, k=k)
    nb = points[idx.reshape(len(points), k)]
    d = nb - nb.mean(axis=1, keepdims=True)
    cxx = np.einsum("ij,ij->i", d[..., 0], d[..., 0])
    cyy = np.einsum("ij,ij->i", d[..., 1], d[..., 1])
    cxy = np.einsum("ij,ij->i", d[..., 0], d[..., 1])
    # Major axis of the 2x2 covariance in closed form; the normal is perpendicular.
    major = 0.5 * np.arctan2(2.0 * cxy, cxx - cyy)
    normals = np.column_stack([-np.sin(major), np.cos(major)])
    half_trace = 0.5 * (cxx + cyy)
    root = np.sqrt(np.maximum(0.25 * (cxx - cyy) ** 2 + cxy**2, 0.0))
    lam_major, lam_minor = half_trace + root, np.maximum(half_trace - root, 0.0)
    linearity = np.where(lam_major > 0, 1.0 - lam_minor / np.maximum(lam_major, 1e-12), 0.0)
    return normals, linearity


def build_point_map(points: np.ndarray, voxel_m: float, normal_neighbours: int, min_linearity: float) -> PointMap:
    """A point map of planar points (m, 2): voxel-thinned, with normals;
    points whose neighbourhood is not line-like (linearity below
    ``min_linearity``) are dropped, as a point-to-line residual means nothing
    there."""
    pts = voxel_downsample(np.asarray(points, dtype=np.float64), voxel_m)
    if len(pts) < 3:
        return PointMap(pts, np.zeros_like(pts), cKDTree(pts if len(pts) else np.zeros((1, 2))))
    normals, linearity = estimate_normals(pts, normal_neighbours)
    keep = linearity >= min_linearity
    pts, normals = pts[keep], normals[keep]
    return PointMap(pts, normals, cKDTree(pts) if len(pts) else cKDTree(np.zeros((1, 2))))


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


def _rotation(yaw: float) -> np.ndarray:
    c, s = np.cos(yaw), np.sin(yaw)
    return np.array([[c, -s], [s, c]])


def _residuals(q: np.ndarray, pmap: PointMap, pose: np.ndarray, max_distance_m: float):
    """Correspondences of ``q`` at ``pose`` within ``max_distance_m``: mask
    (n,), point-to-line residuals and Jacobians (m,), (m, 3) of the matched."""
    r_mat = _rotation(pose[2])
    rq = q @ r_mat.T
    qw = rq + pose[:2]
    dist, idx = pmap.tree.query(qw, distance_upper_bound=max_distance_m)
    ok = np.isfinite(dist)
    n = pmap.normals[idx[ok]]
    res = np.einsum("ij,ij->i", n, qw[ok] - pmap.points[idx[ok]])
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
    tolerance: float = 1e-4,
) -> Registration:
    """Align ``query`` points (n, 2) to ``pmap`` from the pose ``guess``
    (x, y, yaw); see the module docstring.

    The correspondence distance starts at ``max_distance_m`` and shrinks by
    a third per iteration down to ``inlier_distance_m`` (coarse to fine: a
    wide basin first, then only close points); ``kernel_m`` is the Cauchy
    scale of the point-to-line residual. ``overlap``, ``rms_m`` and the
    information are taken at the end with ``inlier_distance_m``.
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
        gate = max(gate * (2.0 / 3.0), inlier_distance_m)
    ok, res, jac = _residuals(q, pmap, pose, inlier_distance_m)
    if len(res) < 4:
        return empty
    w = 1.0 / (1.0 + (res / kernel_m) ** 2)
    variance = float(np.sum(w * res**2) / max(np.sum(w) - 3.0, 1.0))
    information = jac.T @ (jac * w[:, None]) / max(variance, 1e-12)
    rms = float(np.sqrt(np.mean(res**2)))
    return Registration(pose, information, rms, float(ok.mean()), int(ok.sum()), iteration, converged)


def weakest_direction(information: np.ndarray, length_m: float) -> tuple[float, np.ndarray]:
    """Standard deviation (m) of the worst-constrained direction of a pose
    information matrix, and that direction (3,) in (x, y, yaw * length_m)
    units: yaw is scaled by ``length_m`` (the extent of the scan) so a
    rotation is compared with the displacement it causes at that range."""
    scale = np.array([1.0, 1.0, 1.0 / length_m])
    scaled = information * np.outer(scale, scale)
    values, vectors = np.linalg.eigh(scaled)
    smallest = max(float(values[0]), 1e-300)
    return float(1.0 / np.sqrt(smallest)), vectors[:, 0]
