"""GTSAM factors for each measurement type on Pose2 keyframes.

Odometry and scan matching are ``BetweenFactorPose2``; the compass is a
``PoseRotationPrior2D`` (absolute yaw); GPS a ``PoseTranslationPrior2D``.
GTSAM has no relative-yaw factor on Pose2, so the gyro's integrated yaw
increment is a small :class:`gtsam.CustomFactor` with analytic Jacobians.
"""

from __future__ import annotations

import gtsam
import numpy as np

from slam.geometry import wrap_angle


def pose_key(k: int) -> int:
    """GTSAM key of keyframe ``k`` (symbol ``x<k>``)."""
    return gtsam.symbol("x", k)


def gaussian(sigmas: np.ndarray, robust: gtsam.noiseModel.mEstimator.Base | None = None) -> gtsam.noiseModel.Base:
    """Diagonal noise with the given standard deviations, optionally robust."""
    noise = gtsam.noiseModel.Diagonal.Sigmas(np.asarray(sigmas, dtype=float))
    return gtsam.noiseModel.Robust.Create(robust, noise) if robust is not None else noise


def between_factor(k: int, delta: np.ndarray, noise: gtsam.noiseModel.Base) -> gtsam.NonlinearFactor:
    """Relative pose ``delta`` (x, y, yaw) from keyframe k-1 to k."""
    return gtsam.BetweenFactorPose2(pose_key(k - 1), pose_key(k), gtsam.Pose2(*delta), noise)


def yaw_prior_factor(k: int, yaw: float, noise: gtsam.noiseModel.Base) -> gtsam.NonlinearFactor:
    """Absolute yaw of keyframe k (compass), noise of dimension 1."""
    return gtsam.PoseRotationPrior2D(pose_key(k), gtsam.Rot2(yaw), noise)


def position_prior_factor(k: int, xy: np.ndarray, noise: gtsam.noiseModel.Base) -> gtsam.NonlinearFactor:
    """World position of keyframe k (GPS), noise of dimension 2."""
    return gtsam.PoseTranslationPrior2D(pose_key(k), np.asarray(xy, dtype=float), noise)


def yaw_increment_error(measured: float, yaw_i: float, yaw_j: float) -> float:
    """Residual of a relative-yaw measurement: wrap((yaw_j - yaw_i) - measured)."""
    return float(wrap_angle(yaw_j - yaw_i - measured))


def yaw_increment_factor(k: int, measured: float, noise: gtsam.noiseModel.Base) -> gtsam.NonlinearFactor:
    """Relative yaw from keyframe k-1 to k (integrated gyro), noise of dim 1.

    Pose2's retraction adds the tangent's third component to the heading, so
    the Jacobians of the residual are exactly [0, 0, -1] and [0, 0, 1].
    """
    keys = [pose_key(k - 1), pose_key(k)]

    def error(this: gtsam.CustomFactor, values: gtsam.Values, jacobians) -> np.ndarray:
        yaw_i = values.atPose2(this.keys()[0]).theta()
        yaw_j = values.atPose2(this.keys()[1]).theta()
        if jacobians is not None:
            jacobians[0] = np.array([[0.0, 0.0, -1.0]])
            jacobians[1] = np.array([[0.0, 0.0, 1.0]])
        return np.array([yaw_increment_error(measured, yaw_i, yaw_j)])

    return gtsam.CustomFactor(noise, keys, error)
