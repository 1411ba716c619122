"""Loop constraints as GTSAM factors.

A loop is a ``BetweenFactorPose2`` between two non-consecutive keyframes.
Its noise is the loop's information matrix as a square-root information
``diag(sqrt(lambda)) V^T`` (from its eigen-decomposition): a direction the
loop does not measure (a corridor's axis, the yaw of a position-only loop)
has zero weight, so the factor does not pin it.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import gtsam
import numpy as np

from slam.graph.factors import pose_key
from validation.loops.constraint import LoopConstraint


@dataclass
class LoopFactors:
    """The loops the back-end adds, and how.

    ``robust``: an M-estimator for every loop factor (or None); ``gnc``:
    batch optimisation by graduated non-convexity with every other factor a
    known inlier; ``inflation``: per loop id, a sigma multiplier decided by
    gating (missing: 1).
    """

    loops: list[LoopConstraint]
    robust: object | None = None
    gnc: bool = False
    inflation: dict[int, float] = field(default_factory=dict)

    def by_keyframe(self) -> dict[int, list[LoopConstraint]]:
        """Loops grouped by their later keyframe (the step that adds them)."""
        out: dict[int, list[LoopConstraint]] = {}
        for lp in self.loops:
            out.setdefault(lp.j, []).append(lp)
        return out


def loop_noise(information: np.ndarray, robust=None) -> gtsam.noiseModel.Base:
    """Square-root information noise of a (possibly singular) information matrix."""
    values, vectors = np.linalg.eigh(0.5 * (information + information.T))
    sqrt_info = np.diag(np.sqrt(np.maximum(values, 0.0))) @ vectors.T
    noise = gtsam.noiseModel.Gaussian.SqrtInformation(sqrt_info, False)
    return gtsam.noiseModel.Robust.Create(robust, noise) if robust is not None else noise


def loop_factor(loop: LoopConstraint, robust=None, inflation: float = 1.0) -> gtsam.NonlinearFactor:
    """The between factor of ``loop`` (keyframe i to j)."""
    noise = loop_noise(loop.information / inflation**2, robust)
    return gtsam.BetweenFactorPose2(pose_key(loop.i), pose_key(loop.j), gtsam.Pose2(*loop.delta), noise)
