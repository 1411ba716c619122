"""The field against the gyro: the magnetometer's vector turns as the gyro says."""

from types import SimpleNamespace

import numpy as np
import pytest

from slam.commands.calibrate.runs import CalibrationRun
from slam.commands.calibrate.select import calibrate_field_gyro
from validation.observers.checks import FieldGyroCheck, unary_checks
from validation.observers.config import FieldGyroCheckConfig, field_gyro_stream, observers_config
from validation.streams import fixed_rate_steps, resample_streams, validation_streams
from validation.streams.field_gyro import field_change

EARTH = np.array([15e-6, 0.0, -40e-6])  # horizontal 15 uT north-ish, dipping down


def turning_sensor(disturbance=None, rate_hz=100.0, duration_s=10.0):
    """A level sensor turning back and forth in the Earth field: times, the
    field in its frame and its heading; ``disturbance(t)`` (n, 3) T is added
    in the world frame."""
    t = np.arange(0.0, duration_s, 1.0 / rate_hz)
    psi = 2.0 * np.sin(1.5 * t)
    world = np.tile(EARTH, (len(t), 1))
    if disturbance is not None:
        world = world + disturbance(t)
    c, s = np.cos(psi), np.sin(psi)
    field = np.column_stack([c * world[:, 0] + s * world[:, 1], -s * world[:, 0] + c * world[:, 1], world[:, 2]])
    return t, field, psi


def test_an_undisturbed_field_turns_as_the_gyro_says():
    t, field, psi = turning_sensor()
    change = field_change(t, field, t, psi, window_s=1.0, smooth_s=0.1)
    assert np.isnan(change[t < 1.1 - 1e-9]).all()  # the window reaches before the data
    assert np.nanmax(change) < 1e-12


def test_a_passing_magnet_is_seen_and_a_gyro_that_disagrees_too():
    def magnet(t):
        d = np.zeros((len(t), 3))
        d[(t >= 5.0) & (t < 5.6)] = [0.0, 6e-6, 3e-6]
        return d

    t, field, psi = turning_sensor(magnet)
    change = field_change(t, field, t, psi, window_s=1.0, smooth_s=0.1)
    during = (t >= 5.1) & (t < 5.6)
    assert np.all(change[during] > 6e-6)
    assert np.nanmax(change[(t > 1.2) & (t < 4.9)]) < 1e-12
    # A gyro reading 10 % slow: the field no longer stays put as the sensor turns.
    change = field_change(t, turning_sensor()[1], t, 0.9 * psi, window_s=1.0, smooth_s=0.1)
    assert np.nanmax(change) > 2e-6


def test_a_window_may_span_a_gap_in_the_compass_but_needs_a_sample_at_its_start():
    t, field, psi = turning_sensor()
    keep = (t < 3.0) | (t >= 3.5)
    change = field_change(t[keep], field[keep], t, psi, window_s=1.0, smooth_s=0.1)
    after = t[keep]
    starts_in_gap = (after >= 4.06) & (after < 4.5 - 1e-9)
    assert np.isnan(change[starts_in_gap]).all()
    assert np.isfinite(change[(after >= 1.1) & ~starts_in_gap & ~((after > 4.0) & (after < 4.06))]).all()
    assert np.nanmax(change) < 1e-12


def test_the_check_is_off_by_default_and_flags_beyond_its_tolerance():
    assert field_gyro_stream(observers_config({})) is None
    assert not any(isinstance(c, FieldGyroCheck) for c in unary_checks(observers_config({})))
    cfg = observers_config({"field_gyro": {"enabled": True, "window_s": 0.5, "tolerance_T": 4e-6}})
    assert field_gyro_stream(cfg) == (0.5, 0.1)
    (check,) = [c for c in unary_checks(cfg) if isinstance(c, FieldGyroCheck)]
    assert check.component == "IMU_YAW"
    np.testing.assert_array_equal(check.deviant({"mag_field_change": np.array([3e-6, 5e-6])}), [False, True])


def _run(name, disturbance=None):
    t, field, psi = turning_sensor(disturbance, duration_s=60.0)
    rate = np.gradient(psi, t)
    sensors = SimpleNamespace(compass=SimpleNamespace(t=t, yaw=psi, field=field), gyro=SimpleNamespace(t=t, rate=rate),
                              odometry=None, gps=None, extra_odometry={})
    streams = validation_streams(sensors, field_gyro=(1.0, 0.1))
    steps = resample_streams(streams, fixed_rate_steps(0.0, 59.9, 10.0))
    return CalibrationRun(name, streams, steps, [], np.ones(len(steps.t), bool), False)


def test_calibration_sets_the_tolerance_from_the_worst_run_and_a_fault_does_not_widen_it():
    rng = np.random.default_rng(3)
    noise = _run("noisy", lambda t: rng.normal(0.0, 0.5e-6, (len(t), 3)))
    quiet = _run("quiet", lambda t: rng.normal(0.0, 0.1e-6, (len(t), 3)))

    def magnet(t):
        d = rng.normal(0.0, 0.1e-6, (len(t), 3))
        d[(t % 10.0) < 0.6] += [0.0, 20e-6, 0.0]
        return d

    faulty = _run("faulty", magnet)
    cfg = FieldGyroCheckConfig(enabled=True)
    both = calibrate_field_gyro([noise, quiet], cfg, 0.01).config.tolerance_T
    alone = calibrate_field_gyro([quiet], cfg, 0.01).config.tolerance_T
    assert both > 2 * alone  # the worst run sets it
    with_fault = calibrate_field_gyro([quiet, faulty], cfg, 0.01).config.tolerance_T
    assert with_fault < 5e-6  # far below the 20 uT passes: 6 robust sds cap it
    assert calibrate_field_gyro([quiet], cfg.model_copy(update={"enabled": False}), 0.01) is None


@pytest.mark.parametrize("window_s", [0.0, -1.0])
def test_a_window_must_be_positive(window_s):
    from validation.base.errors import ValidationError

    with pytest.raises(ValidationError, match="window_s"):
        observers_config({"field_gyro": {"enabled": True, "window_s": window_s}})
