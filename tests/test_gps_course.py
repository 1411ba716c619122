"""The GPS course stream (validation/streams/course.py) and the compass's offset
relation against it with a level of 0 (validation/observers/quantitative.py), learnt
by calibrate (slam/commands/calibrate)."""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
import yaml

from slam.commands.calibrate.runs import CalibrationRun
from slam.commands.calibrate.select import calibrate_relation
from slam.commands.calibrate.write import _flow
from validation.config import ValidationConfig
from validation.diagnosis.model import Observation, load_model
from validation.diagnosis.reiter import Diagnoser
from validation.observers import ObserverBank, run_observers
from validation.observers.config import RelationConfig
from validation.streams import Stream, fixed_rate_steps, resample_streams, validation_streams

FIX_SIGMA_M = 0.5
WINDOW_S = 8.0


def drive(seed: int = 0) -> SimpleNamespace:
    """A skid-steer drive at 10 Hz: east at 1 m/s for 40 s, a 90 degree turn
    left over 10 s, north for 40 s, a stop of 15 s, backing up (heading
    north, travelling south) at 0.8 m/s for 30 s. GPS fixes at 2.5 Hz with
    ``FIX_SIGMA_M`` of white noise per axis."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, 135.0, 0.1)
    rate = np.where((t >= 40) & (t < 50), np.radians(9.0), 0.0)
    speed = np.select([t < 90, t < 105], [1.0, 0.0], -0.8)
    yaw = np.concatenate(([0.0], np.cumsum(rate[1:] * 0.1)))
    x = np.concatenate(([0.0], np.cumsum(speed[1:] * np.cos(yaw[1:]) * 0.1)))
    y = np.concatenate(([0.0], np.cumsum(speed[1:] * np.sin(yaw[1:]) * 0.1)))
    fix = slice(None, None, 4)
    n = len(t[fix])
    gps = SimpleNamespace(t=t[fix], x=x[fix] + rng.normal(0, FIX_SIGMA_M, n), y=y[fix] + rng.normal(0, FIX_SIGMA_M, n),
                          sigma=np.full(n, FIX_SIGMA_M), status=np.zeros(n, int))
    return SimpleNamespace(t=t, yaw=yaw, odometry=_Poses(t, x, y, yaw), gps=gps, compass=None, gyro=None, extra_odometry={})


class _Poses(SimpleNamespace):
    def __init__(self, t, x, y, yaw):
        super().__init__(t=t, x=x, y=y, yaw=yaw)

    def __len__(self) -> int:
        return len(self.t)


def course_of(run: SimpleNamespace, window: str = "centred", min_speed: float = 0.5) -> Stream:
    return validation_streams(run, None, WINDOW_S, window, course=(min_speed, np.radians(15.0)))["gps_course"]


def angle_error(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.abs(np.angle(np.exp(1j * (a - b))))


@pytest.mark.parametrize("window", ["centred", "trailing"])
def test_course_is_the_heading_where_it_is_given(window):
    run = drive()
    c = course_of(run, window)
    heading = np.interp(c.t, run.t, run.yaw)
    err = np.degrees(angle_error(c.values, heading))
    # Regression slope sd 0.5 m * sqrt(12 / 20) / 8 s = 0.048 m/s: 2.8 deg at
    # 1 m/s; next to the turn, a window may hold up to 15 deg of it.
    assert np.percentile(err, 95) < 7.0 and err.max() < 15.0
    # Backing up: the course is the heading (north), not the travel (south).
    back = c.t > 112
    assert back.sum() > 30
    assert np.degrees(angle_error(c.values[back], np.pi / 2)).max() < 12.0
    # Both straight stretches are covered away from their ends.
    assert ((c.t > 10) & (c.t < 35)).sum() > 50 and ((c.t > 60) & (c.t < 85)).sum() > 50


@pytest.mark.parametrize("window", ["centred", "trailing"])
def test_course_is_left_out_when_standing_turning_or_without_odometry(window):
    run = drive()
    c = course_of(run, window)
    lag = WINDOW_S if window == "trailing" else 0.5 * WINDOW_S
    # Standing (below the minimum speed over the whole window) and in windows holding the turn.
    assert not ((c.t > 90 + lag) & (c.t < 105)).any()
    assert not ((c.t > 45) & (c.t < 45 + lag - 2.0)).any()
    # A higher minimum speed leaves out the backing up at 0.8 m/s.
    assert not (course_of(run, window, min_speed=0.9).t > 112).any()
    # Without odometry, forward and backward cannot be told: no course at all.
    run.odometry = None
    assert "gps_course" not in validation_streams(run, None, WINDOW_S, window)


def headings(offset_rad: float, seed: int = 1) -> tuple[np.ndarray, dict[str, Stream]]:
    """Compass and GPS course at 10 Hz for 300 s near +-pi (so the difference
    wraps): the compass wanders by 0.05 rad (slow, sd) around the course,
    the course has 0.05 rad of white noise; from 150 to 250 s the compass
    is ``offset_rad`` off."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, 300.0, 0.1)
    truth = np.pi - 0.02 + 0.3 * np.sin(t / 40.0)
    wander = np.convolve(rng.normal(0.0, 0.05 * np.sqrt(30.0), len(t)), np.ones(30) / 30.0, mode="same")
    compass = truth + wander + np.where((t >= 150) & (t < 250), offset_rad, 0.0)
    course = truth + rng.normal(0.0, 0.05, len(t))
    wrap = lambda v: np.angle(np.exp(1j * v))  # noqa: E731
    return t, {"compass_yaw": Stream(t, wrap(compass), angular=True), "gps_course": Stream(t, wrap(course), angular=True)}


ABSOLUTE = RelationConfig(name="yaw_compass_gps", kind="offset", stream_a="gps_course", stream_b="compass_yaw",
                          window_s=3.0, level_window_s=None, sigma_floor=0.07, k_sigma=4.0, threshold=5,
                          max_counter=25)


@pytest.mark.parametrize("window,offline", [("centred", True), ("trailing", False)])
def test_standing_offset_is_no_match_and_wander_matches(window, offline):
    t, streams = headings(np.radians(30.0))
    log = run_observers(streams, [ABSOLUTE], t, window=window, offline=offline).relations[ABSOLUTE.name]
    assert log.valid.all()
    assert log.no_match[(t > 151) & (t < 249)].all()  # all the 100 s, not only its start
    assert log.no_match[(t < 149) | (t > 252)].mean() < 0.005


def test_streaming_bank_agrees_with_the_batch_observer():
    t, streams = headings(np.radians(30.0))
    batch = run_observers(streams, [ABSOLUTE], t, window="trailing").relations[ABSOLUTE.name].no_match
    bank = ObserverBank([ABSOLUTE])
    values = {name: np.interp(t, s.t, np.unwrap(s.values)) for name, s in streams.items()}
    stream = [bank.update(float(tk), {n: v[k] for n, v in values.items()}).observations[ABSOLUTE.name]
              for k, tk in enumerate(t)]
    assert np.array_equal(batch, np.array([o == Observation.NO_MATCH for o in stream]))


def test_calibrate_learns_the_band_of_the_difference():
    t, streams = headings(np.radians(30.0), seed=2)
    step_t = fixed_rate_steps(t[0], t[-1], 10.0)
    steps = resample_streams(streams, step_t, 0.5)
    run = CalibrationRun("drive", streams, steps, [], step_t <= 140.0, True)
    start = ABSOLUTE.model_copy(update={"sigma_floor": 1.0})
    vcfg = ValidationConfig.model_validate({"mode": "on", "rate_hz": 10.0, "pass": "offline",
                                            "observers": {"relations": [start.model_dump()]}})
    choice = calibrate_relation([run], start, vcfg, target=0.005)
    rel = choice.relation
    # The difference's sd: 0.05 rad of wander and 0.05 rad of course noise.
    assert rel.sigma_floor == pytest.approx(np.hypot(0.05, 0.05), rel=0.25)
    assert choice.met and rel.level_window_s is None and rel.gain == 1.0
    assert choice.offset[0] == pytest.approx(0.0, abs=0.02) and choice.offset[1] > 1000
    # Written back, the level stays 0 (null), not the default running level.
    assert yaml.safe_load(_flow(rel))[0]["level_window_s"] is None
    # What it learnt sees the offset it was not shown.
    seen = run_observers(streams, [rel], t, window="centred", offline=True).relations[rel.name].no_match
    assert seen[(t > 155) & (t < 245)].mean() > 0.95


@pytest.mark.parametrize("speed,first", [(Observation.MATCH, {"IMU_YAW"}), (Observation.NO_MATCH, {"GPS"})])
def test_husky_model_blames_the_compass_when_the_gps_speed_matches(speed, first):
    """Compass against course alone ties IMU_YAW and GPS; a GPS speed that
    matches the odometry's makes the compass the more probable culprit, one
    that does not makes the GPS."""
    model = load_model(Path(__file__).resolve().parents[1] / "configs/validation/husky_model.yaml")
    result = Diagnoser(model).diagnose({"yaw_compass_gps": Observation.NO_MATCH, "speed_gps_odo": speed,
                                        "yaw_compass_gyro": Observation.MATCH})
    assert set(result.diagnoses[0]) == first
    if speed == Observation.MATCH:  # a GPS fault with a coincidental speed match stays a diagnosis
        assert frozenset({"GPS"}) in result.diagnoses
