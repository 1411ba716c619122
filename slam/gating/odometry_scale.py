"""The odometry's distance scale, learnt from the stretches validation clears.

Track and wheel odometry reports distance with a scale error: a track's
circumference off by some tenths of a percent, and slip that adds a few
percent on loose ground. Where the diagnosis clears both the odometry's
distance (``ODO_DIST``) and the scan matcher's (``SM_DIST``), the two
measure the same motion, and their ratio is that scale. Where the scan
matcher is then excluded (an open yard, a corridor), the odometry carries
the estimate alone, and its scale error becomes the map's.

The ratio is taken over windows of at least ``window_m`` of odometry travel
made of consecutive steps whose forward degree of freedom is kept for both
(the scan matcher's own small errors average out over a window); the scale
is the median of the windows' ratios, so a window the diagnosis missed does
not move it. With fewer than ``min_windows`` windows nothing is learnt.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from slam.graph.backend import FactorWeights, dof_weights
from slam.graph.measurements import Measurements

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class ScaleEstimate:
    """``scale`` multiplies the odometry's translation (1 when nothing was
    learnt); ``windows`` is how many windows it came from, ``spread`` the
    median absolute deviation of their ratios."""

    scale: float
    windows: int
    spread: float


def odometry_scale(
    meas: Measurements, weights: FactorWeights, window_m: float = 2.0, min_windows: int = 5
) -> ScaleEstimate:
    """The scan matcher's forward travel over the odometry's, on the steps
    where both are kept (module docstring)."""
    odo, sm = meas.odometry, meas.scan_matching
    if odo is None or sm is None:
        return ScaleEstimate(1.0, 0, 0.0)
    w_odo = dof_weights(weights.get("odometry", np.ones(len(meas))), "odometry")
    w_sm = dof_weights(weights.get("scan_matching", np.ones(len(meas))), "scan_matching")
    kept = odo.valid & sm.valid & (w_odo[:, 0] <= 1.0) & (w_sm[:, 0] <= 1.0)
    ratios = []
    sum_odo = sum_sm = 0.0
    for k in range(1, len(meas)):
        if not kept[k]:
            sum_odo = sum_sm = 0.0
            continue
        sum_odo += odo.delta[k, 0]
        sum_sm += sm.delta[k, 0]
        if abs(sum_odo) >= window_m:
            ratios.append(sum_sm / sum_odo)
            sum_odo = sum_sm = 0.0
    if len(ratios) < min_windows:
        return ScaleEstimate(1.0, len(ratios), 0.0)
    r = np.asarray(ratios)
    scale = float(np.median(r))
    spread = float(np.median(np.abs(r - scale)))
    log.info("odometry scale %.4f from %d windows (spread %.4f)", scale, len(r), spread)
    return ScaleEstimate(scale, len(r), spread)
