"""The named streams the observers compare, derived from one run's sensors.

Relation streams (trend streams), with the component each one speaks for
(one component per modality, as in the paper's Table 1):

============== ========= ===================================================
name           component values
============== ========= ===================================================
compass_yaw    IMU_YAW   compass heading, rad (angular)
gyro_yaw       IMU_GYRO  gyro yaw rate integrated by trapezoids, rad from 0
sm_yaw         SM_YAW    scan-matching (KISS-ICP) yaw, rad (angular)
odo_yaw        ODO_YAW   odometry yaw, rad (angular)
odo_distance   ODO_DIST  path length of the odometry x/y, m
sm_distance    SM_DIST   path length of the scan-matching x/y, m
odo_forward    ODO_DIST  forward travel: sum of the steps along the heading, m
sm_forward     SM_DIST   the same from scan matching (its own heading), m
odo_lateral    ODO_DIST  sideways travel: sum of the body-frame lateral steps, m
sm_lateral     SM_LAT    the same from scan matching, m
odo_speed      ODO_DIST  derivative of odo_distance, m/s
gps_speed      GPS       speed from the slope of the fixes' x and y over a
                         window, m/s
odo_fix_speed  ODO_DIST  the odometry's speed derived as gps_speed is: the
                         slope of its x and y over the same window, m/s
sm_speed       SM_DIST   derivative of sm_distance, m/s
sm_fix_speed   SM_DIST   scan matching's speed derived as gps_speed is, m/s
gps_course     GPS       direction of travel from the same slopes, rad
                         (angular), only where it is the heading
                         (:mod:`validation.streams.course`)
============== ========= ===================================================

A further odometry source named ``vo`` (``input.extra_odometry``: a visual
odometry, a second wheel odometry) gives the odometry's six streams as
``vo_yaw`` ... ``vo_fix_speed``, with components ``VO_YAW`` and ``VO_DIST``
(:mod:`validation.streams.names`).

The sensors come in as any object with the attributes of
:class:`SensorSet` (``slam.recording.Recording`` is one); this package does
not depend on the pipeline that reads them.

Quality streams for the unary checks: ``mag_strength`` (T) and ``mag_dip``
(rad, positive downward, assuming a level robot) from the raw compass field,
``mag_field_change`` (T; the field's change the gyro's turn does not
explain, :mod:`validation.streams.field_gyro`) when asked for, and ``gps_sigma``
(m). Fixes with a negative status carry no position and are left out.
The scan check's ``scan_degenerate_{dist,lat,yaw}`` (1 where a scan cannot
constrain that motion, else 0) come from the front-end's figures per scan
(:func:`validation.observers.checks.scan_streams`).

Streams are then resampled onto the validation step times by linear
interpolation (angles unwrapped first, so the result is continuous) with a
validity mask that is false where the stream has no data within a max gap.
"""

from __future__ import annotations

import logging
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from validation.base.errors import ValidationError
from validation.streams.course import gps_course
from validation.streams.field_gyro import field_change
from validation.streams.names import (ANGULAR_STREAMS, INTEGRATED_STREAMS, STREAM_COMPONENT, STREAM_NAMES,  # noqa: F401
                                     QualityStreamName, StreamName, is_angular, is_integrated, is_stream_name,
                                     source_stream, stream_component)
from validation.trends import Window, derive_stream

logger = logging.getLogger(__name__)



class PoseSeries(Protocol):
    """Planar poses over time: ``t`` (n,) s, ``x``/``y`` (n,) m, ``yaw`` (n,) rad."""

    t: np.ndarray
    x: np.ndarray
    y: np.ndarray
    yaw: np.ndarray


class RateSeries(Protocol):
    """Yaw rate about the body z axis: ``t`` (n,) s, ``rate`` (n,) rad/s."""

    t: np.ndarray
    rate: np.ndarray


class HeadingSeries(Protocol):
    """Compass heading ``yaw`` (n,) rad, world frame; ``field`` (n, 3) T in the
    body frame when it came from a magnetometer, else None."""

    t: np.ndarray
    yaw: np.ndarray
    field: np.ndarray | None


class FixSeries(Protocol):
    """GPS fixes in the local world frame: ``x``/``y`` (n,) m, ``sigma`` (n,) m,
    ``status`` (n,) int (negative: no position)."""

    t: np.ndarray
    x: np.ndarray
    y: np.ndarray
    sigma: np.ndarray
    status: np.ndarray


class SensorSet(Protocol):
    """The sensors of one run; any may be None. ``extra_odometry``: further
    odometry sources by name (possibly none)."""

    compass: HeadingSeries | None
    gyro: RateSeries | None
    odometry: PoseSeries | None
    gps: FixSeries | None
    extra_odometry: Mapping[str, PoseSeries]


@dataclass(frozen=True)
class Stream:
    """One scalar stream: ``t`` (n,) s strictly increasing, ``values`` (n,)."""

    t: np.ndarray
    values: np.ndarray
    angular: bool = False


def _clean(name: str, t: np.ndarray, values: np.ndarray, angular: bool = False) -> Stream:
    """Drop non-finite samples and repeated stamps (keeping the first)."""
    t = np.asarray(t, dtype=float)
    values = np.asarray(values, dtype=float)
    keep = np.isfinite(t) & np.isfinite(values)
    t, values = t[keep], values[keep]
    if len(t) > 1 and np.any(np.diff(t) < 0.0):
        i = int(np.flatnonzero(np.diff(t) < 0.0)[0]) + 1
        raise ValidationError(f"stream {name}: timestamps go back at sample {i} ({t[i]} s after {t[i - 1]} s)")
    fresh = np.concatenate(([True], np.diff(t) > 0.0)) if len(t) else np.zeros(0, bool)
    if not np.all(fresh):
        logger.debug("stream %s: dropped %d samples with repeated stamps", name, int(np.sum(~fresh)))
    return Stream(t[fresh], values[fresh], angular)


def path_length(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Cumulative planar path length (m) of a polyline, starting at 0."""
    return np.concatenate(([0.0], np.cumsum(np.hypot(np.diff(x), np.diff(y)))))


def _gradient(t: np.ndarray, v: np.ndarray) -> np.ndarray:
    # np.gradient: second-order central differences on irregular stamps.
    return np.gradient(v, t) if len(t) >= 2 else np.zeros(len(t))


def lateral_travel(x: np.ndarray, y: np.ndarray, yaw: np.ndarray) -> np.ndarray:
    """Cumulative sideways travel (m): each step's displacement projected on
    the body's left axis at its start. A tracked or wheeled robot cannot
    move sideways, so a healthy source keeps this flat; a scan matcher that
    slides along a lone wall does not."""
    dx, dy = np.diff(x), np.diff(y)
    step = -np.sin(yaw[:-1]) * dx + np.cos(yaw[:-1]) * dy
    return np.concatenate(([0.0], np.cumsum(step)))


def forward_travel(x: np.ndarray, y: np.ndarray, yaw: np.ndarray) -> np.ndarray:
    """Cumulative forward travel (m): each step's displacement projected on
    the body's forward axis at its start, as a between factor's x. Unlike the
    path length it shrinks when a source moves the right distance the wrong
    way."""
    dx, dy = np.diff(x), np.diff(y)
    step = np.cos(yaw[:-1]) * dx + np.sin(yaw[:-1]) * dy
    return np.concatenate(([0.0], np.cumsum(step)))


def _trajectory_streams(source: str, traj: PoseSeries, streams: dict[str, Stream], speed_window_s: float,
                        window: Window) -> None:
    """The streams of an odometry-like source (:mod:`validation.streams.names`)."""
    name = lambda quantity: source_stream(source, quantity)  # noqa: E731
    streams[name("yaw")] = _clean(name("yaw"), traj.t, traj.yaw, angular=True)
    streams[name("distance")] = d = _clean(name("distance"), traj.t, path_length(traj.x, traj.y))
    streams[name("forward")] = _clean(name("forward"), traj.t, forward_travel(traj.x, traj.y, traj.yaw))
    streams[name("lateral")] = _clean(name("lateral"), traj.t, lateral_travel(traj.x, traj.y, traj.yaw))
    streams[name("speed")] = Stream(d.t, _gradient(d.t, d.values))
    x, y = _clean(f"{source}_x", traj.t, traj.x), _clean(f"{source}_y", traj.t, traj.y)
    if len(x.t) == len(y.t) and len(x.t) >= 2:
        streams[name("fix_speed")] = Stream(x.t, np.hypot(*_window_velocity(x, y, speed_window_s, window)))


def _window_velocity(x: Stream, y: Stream, window_s: float, window: Window) -> tuple[np.ndarray, np.ndarray]:
    """The regression slopes (Algorithm 2) of ``x`` and ``y`` over ``window_s``."""
    return derive_stream(x.t, x.values, window_s, window), derive_stream(y.t, y.values, window_s, window)


def _course_stream(t: np.ndarray, velocity: tuple[np.ndarray, np.ndarray], streams: Mapping[str, Stream],
                   window_s: float, window: Window, course: tuple[float, float]) -> Stream:
    yaw, forward = streams["odo_yaw"], streams["odo_forward"]
    kept, values = gps_course(t, *velocity, (yaw.t, yaw.values), (forward.t, forward.values), window_s, window, *course)
    return Stream(kept, values, angular=True)


def validation_streams(
    recording: SensorSet,
    sm: PoseSeries | None = None,
    gps_speed_window_s: float = 5.0,
    window: Window = "trailing",
    field_gyro: tuple[float, float] | None = None,
    course: tuple[float, float] = (0.5, np.radians(15.0)),
) -> dict[str, Stream]:
    """The named streams available in ``recording`` (plus scan matching).

    ``sm`` is the KISS-ICP trajectory over the scan times (world frame of
    the front-end); streams whose source is absent are simply not returned.
    GPS speed is the norm of the regression slopes (Algorithm 2) of x and y
    over ``gps_speed_window_s``, ``window`` centred or trailing: differences
    of single fixes carry the fixes' metre-level noise divided by 0.2 s, far
    above a robot's speed. ``odo_fix_speed`` is the odometry's speed through
    the same regression over the same window: compared with it, GPS speed
    is compared with a speed that lags and smooths alike (a trailing 8 s
    window reports a stop seconds late; a derivative of the odometry at once).
    """
    streams: dict[str, Stream] = {}
    if recording.compass is not None:
        c = recording.compass
        streams["compass_yaw"] = _clean("compass_yaw", c.t, c.yaw, angular=True)
        if c.field is not None:
            f = np.asarray(c.field, dtype=float)
            streams["mag_strength"] = _clean("mag_strength", c.t, np.linalg.norm(f, axis=1))
            # Body z is up, so a field dipping downward has a negative z.
            streams["mag_dip"] = _clean("mag_dip", c.t, np.arctan2(-f[:, 2], np.hypot(f[:, 0], f[:, 1])))
    if recording.gyro is not None:
        g = _clean("gyro_rate", recording.gyro.t, recording.gyro.rate)
        yaw = np.concatenate(([0.0], np.cumsum(0.5 * (g.values[1:] + g.values[:-1]) * np.diff(g.t))))
        # Already continuous: no unwrapping needed.
        streams["gyro_yaw"] = Stream(g.t, yaw, angular=False)
        c = recording.compass
        if field_gyro is not None and c is not None and c.field is not None:
            change = field_change(c.t, c.field, g.t, yaw, *field_gyro)
            streams["mag_field_change"] = _clean("mag_field_change", c.t, change)
    if sm is not None and len(sm):
        _trajectory_streams("sm", sm, streams, gps_speed_window_s, window)
    if recording.odometry is not None and len(recording.odometry):
        _trajectory_streams("odo", recording.odometry, streams, gps_speed_window_s, window)
    for source, traj in recording.extra_odometry.items():
        if len(traj.t):
            _trajectory_streams(source, traj, streams, gps_speed_window_s, window)
    if recording.gps is not None:
        gps = recording.gps
        fix = np.asarray(gps.status) >= 0
        x = _clean("gps_x", gps.t[fix], gps.x[fix])
        y = _clean("gps_y", gps.t[fix], gps.y[fix])
        if len(x.t) == len(y.t) and len(x.t) >= 2:
            velocity = _window_velocity(x, y, gps_speed_window_s, window)  # for the speed and the course
            streams["gps_speed"] = Stream(x.t, np.hypot(*velocity))
            if "odo_forward" in streams:
                streams["gps_course"] = _course_stream(x.t, velocity, streams, gps_speed_window_s, window, course)
        streams["gps_sigma"] = _clean("gps_sigma", gps.t[fix], gps.sigma[fix])
    logger.info("validation streams: %s", ", ".join(sorted(streams)))
    return streams


def resample(stream: Stream, step_t: np.ndarray, max_gap_s: float) -> tuple[np.ndarray, np.ndarray]:
    """Linear interpolation of ``stream`` at ``step_t`` (s): ``(values, valid)``.

    A step is valid when it lies within the stream's time span and the two
    samples around it are at most ``max_gap_s`` apart (a step on a sample is
    always valid). Angular streams are unwrapped before interpolating, so
    the values come out continuous (not wrapped). Invalid steps hold NaN.
    """
    step_t = np.asarray(step_t, dtype=float)
    n = len(stream.t)
    values = np.full(len(step_t), np.nan)
    if n == 0:
        return values, np.zeros(len(step_t), dtype=bool)
    v = np.unwrap(stream.values) if stream.angular else stream.values
    j = np.searchsorted(stream.t, step_t, side="right") - 1  # last sample <= step
    jc = np.clip(j, 0, n - 1)
    on_sample = (j >= 0) & (stream.t[jc] == step_t)
    nxt = np.minimum(jc + 1, n - 1)
    bracketed = (j >= 0) & (j < n - 1) & (stream.t[nxt] - stream.t[jc] <= max_gap_s)
    valid = on_sample | bracketed
    values[valid] = np.interp(step_t[valid], stream.t, v)
    return values, valid


@dataclass(frozen=True)
class StepStreams:
    """Streams resampled onto the validation steps ``t`` (m,) s; ``max_gap``
    is the largest gap (s) each stream was interpolated across and
    ``period`` its median sample period (s)."""

    t: np.ndarray
    values: dict[str, np.ndarray]
    valid: dict[str, np.ndarray]
    angular: dict[str, bool]
    max_gap: dict[str, float] = field(default_factory=dict)
    period: dict[str, float] = field(default_factory=dict)


def sample_period(stream: Stream) -> float:
    """Median time (s) between a stream's samples; inf with fewer than two."""
    return float(np.median(np.diff(stream.t))) if len(stream.t) > 1 else float("inf")


def stream_max_gap(
    name: str,
    stream: Stream,
    max_gap_s: float,
    stream_max_gap_s: Mapping[str, float] | None = None,
    gap_periods: float | None = None,
) -> float:
    """The largest gap (s) between two samples of ``stream`` that a step may
    be interpolated across: the stream's own entry of ``stream_max_gap_s``,
    else ``max_gap_s`` or, for a sparse stream, ``gap_periods`` times its
    median sample period, whichever is longer. A log thinned to one scan
    every 1-3 s is then judged by its own rhythm, not by a 10 Hz sensor's."""
    if stream_max_gap_s and name in stream_max_gap_s:
        return float(stream_max_gap_s[name])
    if gap_periods is None or len(stream.t) < 2:
        return max_gap_s
    return max(max_gap_s, gap_periods * sample_period(stream))


def resample_streams(
    streams: Mapping[str, Stream],
    step_t: np.ndarray,
    max_gap_s: float = 0.5,
    stream_max_gap_s: Mapping[str, float] | None = None,
    gap_periods: float | None = None,
) -> StepStreams:
    """Resample every stream; the gap each one may be interpolated across is
    :func:`stream_max_gap`'s (``gap_periods`` None: ``max_gap_s`` unless
    ``stream_max_gap_s`` names the stream)."""
    step_t = np.asarray(step_t, dtype=float)
    if step_t.ndim != 1 or (len(step_t) > 1 and not np.all(np.diff(step_t) > 0.0)):
        raise ValidationError("step times must be a strictly increasing 1-D array")
    values, valid, angular, gaps, periods = {}, {}, {}, {}, {}
    for name, s in streams.items():
        gaps[name] = stream_max_gap(name, s, max_gap_s, stream_max_gap_s, gap_periods)
        periods[name] = sample_period(s)
        values[name], valid[name] = resample(s, step_t, gaps[name])
        angular[name] = s.angular
    return StepStreams(step_t, values, valid, angular, gaps, periods)


def fixed_rate_steps(start_s: float, end_s: float, rate_hz: float) -> np.ndarray:
    """Validation step times from ``start_s`` to ``end_s`` (inclusive) at ``rate_hz``."""
    if not rate_hz > 0.0 or end_s < start_s:
        raise ValidationError(f"validation steps: need rate_hz > 0 and end >= start, got {rate_hz}, {start_s}..{end_s}")
    count = int(np.floor((end_s - start_s) * rate_hz + 1e-9)) + 1
    return start_s + np.arange(count) / rate_hz
