"""The odometry's distance scale, learnt where validation keeps both the
odometry and the scan matcher (slam/gating/odometry_scale.py)."""

import numpy as np

from slam.graph.measurements import BetweenMeasurement, Measurements
from slam.gating.odometry_scale import odometry_scale

K = 401  # 0.1 m a step: 40 m of travel


def _meas(sm_forward: np.ndarray) -> Measurements:
    odo = np.tile([0.1, 0.0, 0.0], (K, 1))
    sm = np.column_stack([sm_forward, np.zeros(K), np.zeros(K)])
    valid = np.r_[False, np.ones(K - 1, bool)]
    sigma = np.tile([0.01, 0.01, 0.01], (K, 1))
    return Measurements(
        t=np.arange(K) * 0.1, scan_index=None,
        odometry=BetweenMeasurement(delta=odo, sigma=sigma, valid=valid),
        scan_matching=BetweenMeasurement(delta=sm, sigma=sigma, valid=valid.copy()),
    )


def test_the_scale_is_the_scan_matchers_travel_over_the_odometrys():
    # The odometry reads 2 % long; the scan matcher is right, with noise.
    rng = np.random.default_rng(0)
    meas = _meas(0.1 / 1.02 + rng.normal(0.0, 0.002, K))
    est = odometry_scale(meas, {"odometry": np.ones(K), "scan_matching": np.ones(K)})
    assert est.windows == 20  # 2 m windows over 40 m
    assert abs(est.scale - 1 / 1.02) < 0.002


def test_gated_scan_matching_is_not_learnt_from():
    # The scan matcher reads half the travel over the first 30 m (an open
    # yard) and is excluded there: the scale comes from the last 10 m only.
    sm = np.full(K, 0.1 / 1.02)
    sm[:301] = 0.05
    w_sm = np.ones((K, 3))
    w_sm[:301, 0] = np.inf
    est = odometry_scale(_meas(sm), {"odometry": np.ones(K), "scan_matching": w_sm})
    assert abs(est.scale - 1 / 1.02) < 1e-9
    # Kept, the yard's windows are the majority and the median is theirs.
    kept = odometry_scale(_meas(sm), {"odometry": np.ones(K), "scan_matching": np.ones(K)})
    assert kept.scale == 0.5


def test_too_few_windows_learn_nothing():
    w = np.ones((K, 3))
    w[:390, 0] = np.inf  # 1 m left where both are kept
    est = odometry_scale(_meas(np.full(K, 0.09)), {"odometry": np.ones(K), "scan_matching": w})
    assert est.scale == 1.0 and est.windows == 0
