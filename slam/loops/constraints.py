"""A loop constraint: a relative pose between two non-consecutive keyframes."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass
class LoopConstraint:
    """Keyframe ``j`` seen from keyframe ``i`` (i < j - 1).

    ``delta``: pose of j in the frame of i (x, y m; yaw rad).
    ``information`` (3, 3): of the error ``Log(delta^-1 * inverse(x_i) x_j)``
    (GTSAM's BetweenFactorPose2 convention: translation in the frame of j),
    possibly singular (a direction the loop does not pin).
    ``source``: ``scans`` (registration), ``file`` (listed by the
    recording) or ``injected`` (a deliberately wrong loop, for tests and
    benchmarks). ``quality``: the verification's figures (overlap, rms_m,
    weak_sigma_m, descriptor_distance), for the log.
    """

    id: int
    i: int
    j: int
    delta: np.ndarray
    information: np.ndarray
    source: str = "scans"
    quality: dict[str, float] = field(default_factory=dict)
