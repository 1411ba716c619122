"""GTSAM factors for each measurement type on Pose2 keyframes.

Odometry and scan matching are ``BetweenFactorPose2``; the compass is a
``PoseRotationPrior2D`` (absolute yaw); GPS a ``PoseTranslationPrior2D``.
GTSAM has no relative-yaw factor on Pose2; the gyro's integrated yaw
increment is a ``BetweenFactorPose2`` whose noise has zero precision on x
and y, which is exact: the yaw residual of a Pose2 between factor is
wrap(yaw_j - yaw_i - measured), whatever the translation. Unlike a Python
``CustomFactor`` it runs in C++ and can be cloned (GTSAM's GNC needs that).
"""

from __future__ import annotations

import gtsam
import numpy as np

from validation.base.geometry import wrap_angle


def pose_key(k: int) -> int:
    """GTSAM key of keyframe ``k`` (symbol ``x<k>``)."""
    return gtsam.symbol("x", k)


def gaussian(sigmas: np.ndarray, robust: gtsam.noiseModel.mEstimator.Base | None = None) -> gtsam.noiseModel.Base:
    """Diagonal noise with the given standard deviations, optionally robust.

    An infinite sigma gives that component zero precision: the factor says
    nothing about it (validation excluded that degree of freedom)."""
    sigmas = np.asarray(sigmas, dtype=float)
    if np.all(np.isfinite(sigmas)):
        noise = gtsam.noiseModel.Diagonal.Sigmas(sigmas)
    else:
        noise = gtsam.noiseModel.Diagonal.Precisions(np.where(np.isfinite(sigmas), 1.0 / sigmas**2, 0.0))
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


def yaw_only_noise(sigma_yaw: float, robust: gtsam.noiseModel.mEstimator.Base | None = None) -> gtsam.noiseModel.Base:
    """Pose2 noise that weighs only the yaw: precisions (0, 0, 1/sigma^2)."""
    noise = gtsam.noiseModel.Diagonal.Precisions(np.array([0.0, 0.0, 1.0 / sigma_yaw**2]))
    return gtsam.noiseModel.Robust.Create(robust, noise) if robust is not None else noise


def yaw_increment_factor(k: int, measured: float, noise: gtsam.noiseModel.Base) -> gtsam.NonlinearFactor:
    """Relative yaw from keyframe k-1 to k (integrated gyro); ``noise`` from
    :func:`yaw_only_noise`."""
    return gtsam.BetweenFactorPose2(pose_key(k - 1), pose_key(k), gtsam.Pose2(0.0, 0.0, measured), noise)
