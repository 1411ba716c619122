"""Refinement of a scan's pose in a submap: point-to-line ICP.

The correlative search (:mod:`slam.matching.search`) lands a scan on the
submap's cells; point-to-line ICP against the submap's points, each with the
normal of the wall it lies on, brings it to the centimetre. It minimises
``sum_i rho(n_i . (R q_i + t - m_i))`` over the scan's points ``q_i`` and
their nearest map points ``m_i`` within a gate (Gauss-Newton, Cauchy
weights ``rho``); the gate shrinks from ``max_distance_m`` to
``inlier_distance_m`` as it converges.

The result says how well the pose is determined: the information matrix of
the last step, and its weakest direction relative to the strongest. Along a
corridor the walls pin the cross-track position and the yaw but not the
position along it: that direction is reported so the caller can keep its
prior there instead of the ICP's arbitrary answer.

Frames: the scan's points in the scan frame; the map points, normals and
poses (x, y, yaw; m, rad) in the submap's frame.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from slam.matching.points import PointMap
from validation.base.geometry import rotation


@dataclass(frozen=True)
class Refinement:
    """``pose`` (x, y, yaw); ``information`` (3, 3) of (x, y, yaw) in the
    submap's axes at the end, from the point-to-line Jacobians and the
    residuals' variance, every point counted as independent (they are not:
    scale it before use); ``rms_m`` the RMS
    point-to-line residual of the inliers; ``inliers`` their share of the
    scan's points; ``converged``."""

    pose: np.ndarray
    information: np.ndarray
    rms_m: float
    inliers: float
    converged: bool


def _linearise(q: np.ndarray, pmap: PointMap, pose: np.ndarray, gate_m: float):
    rq = q @ rotation(pose[2]).T
    qw = rq + pose[:2]
    idx = pmap.nearest(qw, gate_m)
    from slam.matching import kernels

    return kernels.line_terms(qw, rq, idx, pmap.points, pmap.normals)


def refine(
    points: np.ndarray,
    pmap: PointMap,
    guess: np.ndarray,
    max_distance_m: float = 0.3,
    inlier_distance_m: float = 0.1,
    kernel_m: float = 0.05,
    max_iterations: int = 20,
    tolerance: float = 1e-3,
    max_points: int | None = None,
) -> Refinement:
    """Point-to-line ICP of ``points`` (n, 2) against ``pmap`` from
    ``guess``; see the module docstring. With ``max_points``, a dense scan
    is thinned to that many points, evenly along its beams."""
    pose = np.asarray(guess, dtype=np.float64).copy()
    q = np.asarray(points, dtype=np.float64)
    if max_points is not None and len(q) > max_points:
        q = q[np.linspace(0, len(q) - 1, max_points).astype(int)]
    failed = Refinement(pose, np.zeros((3, 3)), np.inf, 0.0, False)
    if len(q) < 3 or len(pmap) < 3:
        return failed
    gate = max_distance_m
    converged = False
    for _ in range(max_iterations):
        _, res, jac = _linearise(q, pmap, pose, gate)
        if len(res) < 3:
            return failed
        w = 1.0 / (1.0 + (res / kernel_m) ** 2)
        h = jac.T @ (jac * w[:, None])
        step = -np.linalg.lstsq(h + 1e-9 * np.eye(3), jac.T @ (w * res), rcond=None)[0]
        pose += step
        if max(abs(step[0]), abs(step[1])) < tolerance and abs(step[2]) < tolerance:
            if gate <= inlier_distance_m:
                converged = True
                break
        gate = max(0.5 * gate, inlier_distance_m)
    ok, res, jac = _linearise(q, pmap, pose, inlier_distance_m)
    if len(res) < 3:
        return failed
    w = 1.0 / (1.0 + (res / kernel_m) ** 2)
    variance = float(np.sum(w * res**2) / max(np.sum(w) - 3.0, 1.0))
    info = jac.T @ (jac * w[:, None]) / max(variance, 1e-8)
    return Refinement(pose, info, float(np.sqrt(np.mean(res**2))), float(ok.mean()), converged)


def pose_uncertainty(information: np.ndarray, length_m: float, max_sigma_m: float) -> tuple[np.ndarray, np.ndarray]:
    """The covariance (3, 3) of (x, y, yaw) that ``information`` gives,
    without the directions it leaves free, and those directions, unit
    vectors (k, 3).

    Directions are compared as the displacement they cause at ``length_m``
    (a turn by dyaw moves points at that range by ``length_m * dyaw``): a
    direction is free when its standard deviation so measured exceeds
    ``max_sigma_m``. Along a corridor, the walls pin the cross-track position
    and the heading to millimetres and the position along it hardly at all.
    """
    scale = np.array([1.0, 1.0, 1.0 / length_m])
    values, vectors = np.linalg.eigh(information * np.outer(scale, scale))
    pinned = values > max_sigma_m**-2
    cov_u = (vectors[:, pinned] / values[pinned]) @ vectors[:, pinned].T
    free = vectors[:, ~pinned] * scale[:, None]
    free = (free / np.linalg.norm(free, axis=0)).T if free.size else np.zeros((0, 3))
    return cov_u * np.outer(scale, scale), free
