"""The dead-reckoning chain between keyframes and its uncertainty.

Loop closing needs an estimate of every keyframe before any loop is known,
and the uncertainty of the motion between any two keyframes to judge a loop.
The steps and their covariances come from the graph's between-measurements
(``slam.loops.chain`` fuses them); this module holds the chain and the loop
tests' algebra, so the loop observer needs nothing from the pipeline.

**Uncertainty between keyframes.** Errors of step k (``eps_k``, in the frame
of keyframe k-1) move every later pose. In world axes, with rotation about
the world origin (the left-invariant form), the error of keyframe m relative
to keyframe i is the sum over the steps in (i, m] of ``G_k eps_k`` with
``G_k = [[R_{k-1}, -J p_k], [0, 1]]`` (``R_{k-1}``: rotation of keyframe
k-1, in whose frame the step is measured; ``p_k``: position of keyframe k,
which a yaw error of step k does not move; ``J`` the 90 deg rotation),
independent of m. So the covariance
of any interval is a difference of cumulative sums (:meth:`Chain.covariance`),
and the error of a loop's disagreement with the chain, in the same form
(:func:`world_discrepancy`), can be tested in O(1) per loop or per pair of
loops. Positions are taken about the chain's mean position to keep the
lever arms short.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from validation.base.geometry import between, wrap_angle

J = np.array([[0.0, -1.0], [1.0, 0.0]])


def integrate(start: np.ndarray, deltas: np.ndarray) -> np.ndarray:
    """Poses (n, 3) from ``start`` (3,) and relative poses ``deltas`` (n, 3),
    ``deltas[0]`` unused (keyframe 0 is ``start``)."""
    n = len(deltas)
    yaw = start[2] + np.concatenate([[0.0], np.cumsum(deltas[1:, 2])])
    heading = yaw[:-1]
    c, s = np.cos(heading), np.sin(heading)
    steps = np.column_stack([c * deltas[1:, 0] - s * deltas[1:, 1], s * deltas[1:, 0] + c * deltas[1:, 1]])
    xy = start[:2] + np.vstack([np.zeros((1, 2)), np.cumsum(steps, axis=0)])
    return np.column_stack([xy[:n], wrap_angle(yaw[:n])])


@dataclass
class Chain:
    """Fused relative poses and their uncertainty, per keyframe step.

    ``deltas`` (K, 3): keyframe k-1 -> k in the frame of k-1 (row 0 unused).
    ``step_cov`` (K, 3, 3): covariance of each step (row 0 zero).
    ``poses`` (K, 3): the integrated chain from the anchor pose.
    ``path_m`` (K,): path length along the chain.
    ``cumulative`` (K, 3, 3): running sum of ``G_k step_cov_k G_k^T``.
    ``origin`` (2,): the point the lever arms are taken about.
    """

    deltas: np.ndarray
    step_cov: np.ndarray
    poses: np.ndarray
    path_m: np.ndarray
    cumulative: np.ndarray
    origin: np.ndarray

    def __len__(self) -> int:
        return len(self.deltas)

    def covariance(self, start: np.ndarray | int, end: np.ndarray | int) -> np.ndarray:
        """Covariance (..., 3, 3) of the chain's error from keyframe
        ``start`` to ``end`` (the steps in (start, end]), world axes,
        rotation about ``origin``; zero when end <= start."""
        start, end = np.asarray(start), np.asarray(end)
        cov = self.cumulative[end] - self.cumulative[np.minimum(start, end)]
        return cov

    def lever(self, k: np.ndarray | int) -> np.ndarray:
        """Position of keyframe ``k`` about ``origin`` (..., 2)."""
        return self.poses[np.asarray(k), :2] - self.origin


def chain_from_steps(deltas: np.ndarray, step_cov: np.ndarray, start: np.ndarray) -> Chain:
    """The chain of relative poses ``deltas`` (K, 3) with covariances
    ``step_cov`` (K, 3, 3) from pose ``start`` (3,)."""
    poses = integrate(np.asarray(start, dtype=float), deltas)
    path = np.concatenate([[0.0], np.cumsum(np.hypot(deltas[1:, 0], deltas[1:, 1]))])
    origin = poses[:, :2].mean(axis=0)
    g = np.zeros((len(deltas), 3, 3))
    prev = np.vstack([poses[:1], poses[:-1]])  # keyframe k-1 for step k
    c, s = np.cos(prev[:, 2]), np.sin(prev[:, 2])
    g[:, 0, 0], g[:, 0, 1], g[:, 1, 0], g[:, 1, 1] = c, -s, s, c
    lever = poses[:, :2] - origin
    g[:, :2, 2] = -(lever @ J.T)
    g[:, 2, 2] = 1.0
    contrib = g @ step_cov @ np.transpose(g, (0, 2, 1))
    cumulative = np.cumsum(contrib, axis=0)
    return Chain(deltas, step_cov, poses, path, cumulative, origin)


def world_discrepancy(chain: Chain, i: np.ndarray, j: np.ndarray, delta: np.ndarray) -> np.ndarray:
    """How far loops ``i -> j`` measuring ``delta`` (n, 3) (pose of j in the
    frame of i) are from the chain, (n, 3), in the chain's error form
    (world axes, rotation about ``origin``)."""
    i, j = np.asarray(i), np.asarray(j)
    predicted = between(chain.poses[i], chain.poses[j])
    r = between(np.atleast_2d(predicted), np.atleast_2d(delta))  # right perturbation at j, frame of j
    yaw_j = chain.poses[j, 2]
    c, s = np.cos(yaw_j), np.sin(yaw_j)
    rt = np.column_stack([c * r[:, 0] - s * r[:, 1], s * r[:, 0] + c * r[:, 1]])
    lever = chain.lever(j)
    return np.column_stack([rt - r[:, 2:3] * (np.atleast_2d(lever) @ J.T), r[:, 2]])


def world_covariance(chain: Chain, j: np.ndarray, information: np.ndarray, weak_variance: float) -> np.ndarray:
    """Covariance (n, 3, 3) of loops' own noise in the same form as
    :func:`world_discrepancy`; ``information`` (n, 3, 3) in the frame of j
    (directions without information get ``weak_variance``)."""
    j = np.asarray(j)
    cov = np.linalg.inv(information + np.eye(3) / weak_variance)
    yaw_j = chain.poses[j, 2]
    lever = np.atleast_2d(chain.lever(j))
    g = np.zeros((len(j), 3, 3))
    c, s = np.cos(yaw_j), np.sin(yaw_j)
    g[:, 0, 0], g[:, 0, 1], g[:, 1, 0], g[:, 1, 1] = c, -s, s, c
    g[:, :2, 2] = -(lever @ J.T)
    g[:, 2, 2] = 1.0
    return g @ cov @ np.transpose(g, (0, 2, 1))
