"""Factors and the back-end on small hand-built graphs with known answers."""

import gtsam
import numpy as np
import pytest

from slam.graph.backend import optimise, unit_weights
from slam.config import BackendConfig
from slam.graph.factors import pose_key, yaw_increment_error, yaw_increment_factor, yaw_only_noise
from slam.graph.measurements import BetweenMeasurement, Measurements, PositionMeasurement, ScalarMeasurement
from slam.recording import relative_poses


def _between(deltas, sigma=(0.1, 0.1, 0.01)):
    k = len(deltas)
    return BetweenMeasurement(
        delta=np.asarray(deltas, float), sigma=np.tile(sigma, (k, 1)), valid=np.r_[False, np.ones(k - 1, bool)]
    )


def _scalar(values, sigma, valid=None):
    values = np.asarray(values, float)
    valid = np.ones(len(values), bool) if valid is None else np.asarray(valid)
    return ScalarMeasurement(value=values, sigma=np.full(len(values), sigma), valid=valid)


def test_three_poses_odometry_only_reproduce_the_chain():
    deltas = [[0, 0, 0], [1.0, 0, np.pi / 2], [1.0, 0, 0]]
    meas = Measurements(t=np.arange(3.0), scan_index=None, odometry=_between(deltas))
    res = optimise(meas, np.zeros(3), BackendConfig())
    traj = res.trajectory
    np.testing.assert_allclose(traj.x, [0, 1, 1], atol=1e-6)
    np.testing.assert_allclose(traj.y, [0, 0, 1], atol=1e-6)
    np.testing.assert_allclose(traj.yaw, [0, np.pi / 2, np.pi / 2], atol=1e-6)
    assert res.factor_counts["odometry"] == 2


def test_two_between_sources_are_fused_by_their_information():
    # Odometry says 1.0 m (sigma 0.1), scan matching 1.3 m (sigma 0.2):
    # the weighted mean is (1.0/0.01 + 1.3/0.04) / (1/0.01 + 1/0.04) = 1.06.
    odo = _between([[0, 0, 0], [1.0, 0, 0]], sigma=(0.1, 0.1, 0.01))
    sm = _between([[0, 0, 0], [1.3, 0, 0]], sigma=(0.2, 0.2, 0.01))
    meas = Measurements(t=np.arange(2.0), scan_index=None, odometry=odo, scan_matching=sm)
    cfg = BackendConfig(initial_sigma_xy_m=1e-4)
    x1 = optimise(meas, np.zeros(3), cfg).trajectory.x[1]
    assert x1 == pytest.approx(1.06, abs=1e-4)


def test_compass_prior_and_gyro_increment_fuse_yaw():
    # Anchor yaw 0 (sigma 0.5 deg), gyro says +0.1 rad (sigma 0.01), compass
    # says 0.2 rad at keyframe 1 (sigma 0.01): yaw1 is near the mean 0.15.
    meas = Measurements(
        t=np.arange(2.0),
        scan_index=None,
        odometry=_between([[0, 0, 0], [0.5, 0, 0.1]], sigma=(0.05, 0.05, 10.0)),
        gyro=_scalar([0.0, 0.1], 0.01, valid=[False, True]),
        compass=_scalar([0.0, 0.2], 0.01, valid=[False, True]),
    )
    cfg = BackendConfig(initial_sigma_yaw_deg=1e-3)
    yaw1 = optimise(meas, np.zeros(3), cfg).trajectory.yaw[1]
    assert yaw1 == pytest.approx(0.15, abs=1e-3)


def test_gps_prior_pulls_position_and_weights_exclude_it():
    odo = _between([[0, 0, 0], [1, 0, 0], [1, 0, 0]], sigma=(0.1, 0.1, 0.001))
    gps = PositionMeasurement(xy=np.array([[0, 0], [1, 0], [2.3, 0]]), sigma=np.full(3, 0.1), valid=np.ones(3, bool))
    meas = Measurements(t=np.arange(3.0), scan_index=None, odometry=odo, gps=gps)
    cfg = BackendConfig(initial_sigma_xy_m=1e-4)
    # x2: odometry says 2.0 (sigma 0.1 from x1), GPS says 2.3 (sigma 0.1),
    # x1 also pulled by its own GPS at 1.0; the least-squares answer is 2.2.
    # (x1 = 1 + (x2-2.0)/3..: solve the 2x2 normal equations by hand.)
    a = np.array([[3.0, -1.0], [-1.0, 2.0]])  # rows: x1, x2 (unit information)
    b = np.array([1.0 + 1.0 - 1.0, 1.0 + 2.3])
    x1_exp, x2_exp = np.linalg.solve(a, b)
    traj = optimise(meas, np.zeros(3), cfg).trajectory
    assert traj.x[1] == pytest.approx(x1_exp, abs=1e-4)
    assert traj.x[2] == pytest.approx(x2_exp, abs=1e-4)
    weights = unit_weights(3)
    weights["gps"][:] = np.inf
    res = optimise(meas, np.zeros(3), cfg, weights)
    assert res.trajectory.x[2] == pytest.approx(2.0, abs=1e-4)
    assert res.factor_counts["gps"] == 0


def test_excluding_every_translational_factor_keeps_one_inflated():
    odo = _between([[0, 0, 0], [1, 0, 0], [1, 0, 0]])
    meas = Measurements(t=np.arange(3.0), scan_index=None, odometry=odo)
    weights = unit_weights(3)
    weights["odometry"][2] = np.inf
    res = optimise(meas, np.zeros(3), BackendConfig(), weights)
    assert res.fallback_steps == 1
    assert res.trajectory.x[2] == pytest.approx(2.0, abs=1e-6)


@pytest.mark.parametrize("optimizer", ["batch", "isam2", "gnc_tls", "gnc_gm"])
def test_every_optimizer_solves_a_consistent_graph(optimizer):
    rng = np.random.default_rng(0)
    truth = np.cumsum(np.column_stack([np.full(20, 0.5), np.zeros(20), rng.normal(0, 0.1, 20)]), axis=0)
    truth[:, :2] = 0
    for k in range(1, 20):  # integrate a curvy path
        c, s = np.cos(truth[k - 1, 2]), np.sin(truth[k - 1, 2])
        truth[k, 0] = truth[k - 1, 0] + 0.5 * c
        truth[k, 1] = truth[k - 1, 1] + 0.5 * s
    deltas = np.zeros_like(truth)
    deltas[1:] = relative_poses(truth[:-1], truth[1:])
    meas = Measurements(t=np.arange(20.0), scan_index=None, odometry=_between(deltas))
    traj = optimise(meas, truth[0], BackendConfig(optimizer=optimizer)).trajectory
    np.testing.assert_allclose(np.column_stack([traj.x, traj.y]), truth[:, :2], atol=1e-5)


def test_yaw_increment_factor_weighs_only_the_yaw_with_exact_jacobians():
    factor = yaw_increment_factor(1, 0.3, yaw_only_noise(0.1))
    values = gtsam.Values()
    values.insert(pose_key(0), gtsam.Pose2(0.2, -0.1, 0.4))
    values.insert(pose_key(1), gtsam.Pose2(1.0, 0.5, 0.9))
    # The whitened residual: zero weight on x and y, yaw error / sigma.
    assert factor.whitenedError(values)[2] == pytest.approx(yaw_increment_error(0.3, 0.4, 0.9) / 0.1)
    np.testing.assert_allclose(factor.whitenedError(values)[:2], 0.0)
    # Linearised: the only non-zero row is [0, 0, -1 | 0, 0, 1] / sigma,
    # checked against central differences of the yaw residual.
    a, _ = factor.linearize(values).jacobian()
    rows = a[np.abs(a).sum(axis=1) > 0]
    eps = 1e-6
    numeric = np.zeros(6)
    for j, key in enumerate([pose_key(0), pose_key(1)]):
        for d in range(3):
            for sign in (+1, -1):
                v = gtsam.Values(values)
                xi = np.zeros(3)
                xi[d] = sign * eps
                v.update(key, values.atPose2(key).retract(xi))
                numeric[3 * j + d] += sign * factor.whitenedError(v)[2] / (2 * eps)
    assert rows.shape == (1, 6)
    np.testing.assert_allclose(np.abs(rows[0]), np.abs(numeric), atol=1e-6)
    np.testing.assert_allclose(numeric, [0, 0, -10, 0, 0, 10], atol=1e-6)


def test_compass_priors_say_no_more_than_the_independent_errors_of_their_stretch():
    from slam.config import FactorsConfig
    from slam.graph.measurements import build_measurements
    from slam.recording import Compass, Recording

    t = np.arange(0.0, 20.0, 0.1)
    rec = Recording("r", compass=Compass(t, np.zeros(len(t))))
    keyframes = np.array([0.0, 0.5, 1.0, 2.0, 3.0])  # spacing 0.5, 0.5, 0.75, 1.0, 1.0 s
    white = build_measurements(rec, keyframes, FactorsConfig.model_validate({"compass": {"sigma_yaw_deg": 4.0}}))
    np.testing.assert_allclose(white.compass.information_sigma, np.radians(4.0))
    slow = FactorsConfig.model_validate({"compass": {"sigma_yaw_deg": 4.0, "correlation_s": 2.0}})
    compass = build_measurements(rec, keyframes, slow).compass
    np.testing.assert_allclose(compass.information_sigma,
                               np.radians(4.0) * np.sqrt(4.0 / np.array([0.5, 0.5, 0.75, 1.0, 1.0])))
    np.testing.assert_allclose(compass.sigma, np.radians(4.0))  # one heading's error is what it was
    # Correlated for less than half a keyframe spacing: independent, the sigma as configured.
    short = FactorsConfig.model_validate({"compass": {"sigma_yaw_deg": 4.0, "correlation_s": 0.1}})
    np.testing.assert_allclose(build_measurements(rec, keyframes, short).compass.information_sigma, np.radians(4.0))


def test_a_correlated_compass_pulls_the_heading_less():
    """Forty compass priors 10 deg off a stiff gyro chain whose start is
    held at 0: independent, they move the heading most of the way;
    correlated over the whole stretch, they say no more than one."""
    from slam.config import FactorsConfig
    from slam.graph.measurements import build_measurements
    from slam.recording import Compass, Gyro, Recording

    t = np.arange(0.0, 21.0, 0.1)
    rec = Recording("r", gyro=Gyro(t, np.zeros(len(t))), compass=Compass(t, np.full(len(t), np.radians(10.0))))
    keyframes = np.arange(0.0, 20.0, 0.5)
    cfg = BackendConfig.model_validate({"initial_pose": "origin", "initial_sigma_yaw_deg": 5.0})
    yaw = {}
    for name, corr in (("independent", None), ("correlated", 20.0)):
        factors = FactorsConfig.model_validate({"compass": {"sigma_yaw_deg": 5.0, "correlation_s": corr},
                                                "gyro": {"sigma_yaw_deg": 0.01, "sigma_yaw_per_s_deg": 0.0}})
        meas = build_measurements(rec, keyframes, factors)
        yaw[name] = np.degrees(optimise(meas, np.zeros(3), cfg, unit_weights(len(keyframes))).trajectory.yaw[-1])
    # The start's prior (0 +- 5 deg) against 40 priors of 10 +- 5 deg: 10 * 40 / 41 deg. Correlated over
    # 20 s, each carries 5 * sqrt(2 * 20 / 0.5) deg: together 1/50 of information against 1/25, 10 / 3 deg.
    assert yaw["independent"] == pytest.approx(10.0 * 40 / 41, abs=0.05)
    assert yaw["correlated"] == pytest.approx(10.0 / 3, abs=0.05)
