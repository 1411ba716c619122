"""Synthetic validation streams with known trends and injected faults.

The robot's true yaw follows a yaw-rate profile made of turns (start s,
end s, rate rad/s) on a straight drive; each sensor sees it at its own rate
with jitter and noise, and a fault adds its own error over an interval.
Everything is seeded, so tests get the same streams every run.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from validation.base.geometry import wrap_angle
from validation.streams import Stream

Turn = tuple[float, float, float]  # start s, end s, yaw rate rad/s
Interval = tuple[float, float]

DEFAULT_TURNS: tuple[Turn, ...] = ((20.0, 30.0, 0.3), (40.0, 50.0, -0.3), (170.0, 180.0, 0.3))


def sample_times(duration_s: float, rate_hz: float, rng: np.random.Generator, jitter: float = 0.2) -> np.ndarray:
    """Irregular stamps from 0 to ``duration_s``: nominal period +-``jitter``."""
    n = int(duration_s * rate_hz)
    dt = (1.0 + rng.uniform(-jitter, jitter, n)) / rate_hz
    t = np.concatenate(([0.0], np.cumsum(dt)))
    return t[t <= duration_s]


def yaw_rate(t: np.ndarray, turns: tuple[Turn, ...]) -> np.ndarray:
    """True yaw rate (rad/s) at ``t``."""
    rate = np.zeros_like(t)
    for start, end, r in turns:
        rate[(t >= start) & (t < end)] += r
    return rate


def true_yaw(t: np.ndarray, turns: tuple[Turn, ...], yaw0: float = 0.0) -> np.ndarray:
    """Exact integral of :func:`yaw_rate` (rad, not wrapped)."""
    yaw = np.full_like(t, yaw0)
    for start, end, r in turns:
        yaw += r * (np.clip(t, start, end) - start)
    return yaw


def ramp_error(t: np.ndarray, interval: Interval, rate: float) -> np.ndarray:
    """An error growing at ``rate`` per s inside ``interval`` and held after."""
    return rate * (np.clip(t, *interval) - interval[0])


def bump_error(t: np.ndarray, interval: Interval, rate: float) -> np.ndarray:
    """An error growing at ``rate`` per s over the first half of ``interval``
    and shrinking back to 0 over the second: a disturbance passed by."""
    a, b = interval
    return rate * np.clip(0.5 * (b - a) - np.abs(t - 0.5 * (a + b)), 0.0, None)


@dataclass
class YawScenario:
    """Raw streams (``compass_yaw``, ``gyro_yaw``, ``sm_yaw``) and their truth."""

    streams: dict[str, Stream]
    step_t: np.ndarray
    faults: dict[str, list[Interval]] = field(default_factory=dict)
    turns: tuple[Turn, ...] = DEFAULT_TURNS


def yaw_scenario(
    duration_s: float = 220.0,
    step_hz: float = 10.0,
    compass_drift: Interval | None = (70.0, 150.0),
    drift_rad_s: float = 0.1,
    turns: tuple[Turn, ...] = DEFAULT_TURNS,
    yaw0: float = 3.0,
    seed: int = 0,
) -> YawScenario:
    """A run whose compass drifts away at ``drift_rad_s`` during ``compass_drift``.

    Compass at 20 Hz (noise 0.02 rad, wrapped to (-pi, pi], so it crosses
    +-pi), gyro at 100 Hz (rate noise 0.005 rad/s, integrated as
    :mod:`validation.streams` does), scan matching at 10 Hz (noise 0.005 rad).
    """
    rng = np.random.default_rng(seed)
    streams: dict[str, Stream] = {}

    t = sample_times(duration_s, 20.0, rng)
    compass = true_yaw(t, turns, yaw0) + rng.normal(0.0, 0.02, len(t))
    if compass_drift is not None:
        compass += ramp_error(t, compass_drift, drift_rad_s)
    streams["compass_yaw"] = Stream(t, wrap_angle(compass), angular=True)

    t = sample_times(duration_s, 100.0, rng)
    rate = yaw_rate(t, turns) + rng.normal(0.0, 0.005, len(t))
    streams["gyro_yaw"] = Stream(t, np.concatenate(([0.0], np.cumsum(0.5 * (rate[1:] + rate[:-1]) * np.diff(t)))))

    t = sample_times(duration_s, 10.0, rng)
    streams["sm_yaw"] = Stream(t, wrap_angle(true_yaw(t, turns, yaw0) + rng.normal(0.0, 0.005, len(t))), angular=True)

    step_t = np.arange(0.0, duration_s - 0.5, 1.0 / step_hz)
    faults = {"IMU_YAW": [compass_drift]} if compass_drift is not None else {}
    return YawScenario(streams, step_t, faults, turns)


def field_body(yaw: np.ndarray, strength_T, dip_rad, declination_rad: float = 0.0) -> np.ndarray:
    """(n, 3) Earth field in the body frame of a level robot at world ``yaw``.

    Magnetic north lies ``declination_rad`` east of +y (true north); the
    field dips ``dip_rad`` below the horizon, so its body z is negative.
    ``strength_T`` and ``dip_rad`` may be scalars or (n,) arrays.
    """
    north = np.pi / 2.0 - declination_rad  # world direction of magnetic north
    rel = north - yaw  # that direction in the body frame
    h = strength_T * np.cos(dip_rad)
    return np.column_stack([h * np.cos(rel), h * np.sin(rel), -strength_T * np.sin(dip_rad) * np.ones_like(yaw)])


def wall_ranges(walls: list[tuple[float, float, float]], n: int = 360) -> tuple[np.ndarray, np.ndarray]:
    """Ranges (n,) and beam angles (n,) of a laser at the origin to infinite
    lines ``n_x x + n_y y = d`` (inf where a beam hits none)."""
    angles = np.linspace(-np.pi, np.pi, n, endpoint=False)
    r = np.full(n, np.inf)
    for nx, ny, d in walls:
        along = nx * np.cos(angles) + ny * np.sin(angles)
        with np.errstate(divide="ignore"):
            r = np.minimum(r, np.where(along > 1e-6, d / along, np.inf))
    return r, angles
