"""Per-stream time offsets: ``input.time_offsets_s`` applied when a recording
is read, and learnt by ``gslam calibrate`` (slam/commands/calibrate/lags.py)."""

from __future__ import annotations

import numpy as np
import pytest

from conftest import TELEMAX_CONFIG
from slam.commands.calibrate import calibrate
from slam.commands.calibrate.lags import estimate_lag, learn_lags
from slam.commands.calibrate.runs import CalibrationRun
from slam.config import load_config
from slam.errors import GslamError
from slam.readers.read import read_recording
from validation.streams import Stream, fixed_rate_steps, resample_streams


def turning_yaw(t: np.ndarray) -> np.ndarray:
    """A robot turning now one way, now the other (rad): rates up to 0.5 rad/s."""
    return 0.8 * np.sin(t / 3.0) + 0.5 * np.sin(t / 1.3) + 0.05 * t


def lagged_run(odo_offset_s: float, seed: int = 0, duration_s: float = 120.0) -> CalibrationRun:
    """A gyro at 30 Hz and wheel odometry at 10 Hz whose stamps are
    ``odo_offset_s`` early (stamp + offset = the time the sample was taken),
    with a little noise on each."""
    rng = np.random.default_rng(seed)
    tg = np.arange(0.0, duration_s, 1 / 30)
    to = np.arange(0.0, duration_s, 0.1)
    gyro = Stream(tg, turning_yaw(tg) + rng.normal(0.0, 2e-4, len(tg)))
    odo = Stream(to, np.angle(np.exp(1j * (turning_yaw(to + odo_offset_s) + rng.normal(0.0, 2e-4, len(to))))),
                 angular=True)
    streams = {"gyro_yaw": gyro, "odo_yaw": odo}
    step_t = fixed_rate_steps(0.0, duration_s - 0.1, 10.0)
    return CalibrationRun("lagged", streams, resample_streams(streams, step_t, 0.5), [],
                          np.ones(len(step_t), dtype=bool), False)


@pytest.mark.parametrize("offset", [0.1, -0.05, 0.0])
def test_learns_the_odometry_offset_within_a_step(offset):
    (lag,) = learn_lags([lagged_run(offset)])
    assert lag.stream == "odometry" and lag.reference == "gyro"
    assert lag.grid_s == pytest.approx(0.1)
    assert lag.offset_s == pytest.approx(offset, abs=0.02)
    assert lag.consistent and lag.moving
    assert lag.proposed == (offset != 0.0)
    if offset:
        assert lag.rms_after < 0.2 * lag.rms_before
    else:
        assert "RMS changes by" in lag.why_not()


def test_several_runs_give_one_offset_each_with_its_own_gyro_bias():
    """The offset is a sensor's: learnt over every run's steps, each run's
    rate difference about its own mean (its gyro's bias)."""
    biased = lagged_run(0.1, seed=1)
    gyro = biased.streams["gyro_yaw"]
    biased.streams["gyro_yaw"] = Stream(gyro.t, gyro.values + 0.02 * gyro.t)  # 1.1 deg/s of bias
    straight = lagged_run(0.1, seed=2)
    for name in ("gyro_yaw", "odo_yaw"):  # a run that never turns cannot date the odometry alone
        s = straight.streams[name]
        straight.streams[name] = Stream(s.t, np.zeros(len(s.t)), angular=s.angular)
    (alone,) = learn_lags([straight])
    assert not alone.moving and not alone.proposed
    (lag,) = learn_lags([straight, biased, lagged_run(0.1, seed=3)])
    assert lag.steps == 3 * alone.steps and lag.proposed
    assert lag.offset_s == pytest.approx(0.1, abs=0.02)


def test_reading_the_stream_at_its_offset_removes_the_lag():
    run = lagged_run(0.1)
    odo = run.streams["odo_yaw"]
    moved = Stream(odo.t + 0.1, odo.values, angular=True)  # what input.time_offsets_s.odometry=0.1 reads
    lag = estimate_lag([(moved, run.streams["gyro_yaw"], run.steps.t)], "odometry", "gyro")
    assert abs(lag.offset_s) < 0.01 and not lag.proposed


def test_no_offset_without_turning():
    run = lagged_run(0.1)
    t = run.streams["odo_yaw"].t
    run.streams["odo_yaw"] = Stream(t, 1e-3 * np.random.default_rng(1).normal(size=len(t)), angular=True)
    (lag,) = learn_lags([run])
    assert not lag.proposed and "too little turning" in lag.why_not()


def test_unknown_reference_is_refused():
    with pytest.raises(GslamError, match="--lag-reference wheel: expected one of"):
        learn_lags([lagged_run(0.1)], "wheel")
    assert learn_lags([lagged_run(0.1)], "none") == []


@pytest.mark.parametrize("override, message", [
    ("input.time_offsets_s.odom=0.1", "unknown config key 'input.time_offsets_s.odom'"),
    ("input.time_offsets_s.gyro=.nan", "input.time_offsets_s.gyro"),
    ("input.time_offsets_s.gps=fast", "input.time_offsets_s.gps"),
])
def test_bad_offsets_are_one_line_errors(override, message):
    with pytest.raises(GslamError, match=message) as err:
        load_config(TELEMAX_CONFIG, [override])
    assert "\n" not in str(err.value)


def test_reader_moves_each_stream_by_its_offset(short_run):
    config = load_config(TELEMAX_CONFIG).input
    plain = read_recording(short_run.run_dir, config)
    moved_config = config.model_copy(update={"time_offsets_s": config.time_offsets_s.model_copy(
        update={"odometry": 0.1, "compass": -0.02})})
    moved = read_recording(short_run.run_dir, moved_config)
    np.testing.assert_allclose(moved.odometry.t, plain.odometry.t + 0.1)
    np.testing.assert_allclose(moved.compass.t, plain.compass.t - 0.02)
    np.testing.assert_array_equal(moved.gyro.t, plain.gyro.t)
    assert moved.t0 == plain.t0 and moved.faults == plain.faults


@pytest.mark.slow
def test_calibrate_finds_an_odometry_read_early_and_learns_with_it(short_run, tmp_path):
    # Read 0.1 s early, the simulated odometry is a recording stamped 0.1 s early.
    out = tmp_path / "learnt.yaml"
    res = calibrate([short_run.run_dir], TELEMAX_CONFIG, out, clean="0:end",
                    overrides=["input.time_offsets_s.odometry=-0.1"])
    (applied,) = [lag for lag in res.applied if lag.stream == "odometry"]
    assert applied.offset_s == pytest.approx(0.1, abs=applied.grid_s)
    learnt = load_config(out)
    assert learnt.input.time_offsets_s.odometry == pytest.approx(0.0, abs=applied.grid_s)
    (again,) = [lag for lag in res.lags if lag.stream == "odometry"]
    assert not again.proposed
    assert "Time offsets found in a first pass" in out.read_text()
