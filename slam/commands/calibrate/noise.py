"""The compass factor's noise, measured against the gyro.

Over a stretch the gyro can be trusted for (its bias turns the integrated
heading into a line), the compass heading minus the integrated gyro
heading, less a line fitted to each clean stretch, is the compass's own
error (in runs learnt whole, the steps far off it are left out as
faults). Two figures describe it for the factor
(:class:`slam.config.CompassFactorConfig`):

* its robust sd, the error of one heading;
* its correlation time: the lag at which its autocorrelation, pooled over
  the stretches, first falls below 1/e (linear between steps). An AHRS
  heading or a disturbed magnetic field wanders for seconds to tens of
  seconds; priors at every keyframe treated as independent would average
  that wander away and pull the map onto it.

Both are lower bounds: the line fitted to a stretch takes in part of a
slow error, the more so the shorter the stretch. On simulated
first-order Gauss-Markov errors of correlation time tau (five each), a
stretch of 60 tau gave tau within 25 %, one of 14 tau 17-39 % short and
one of 4 tau about a quarter of it. Stretches shorter than
``MIN_STRETCH_S`` are left out.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from slam.commands.calibrate.fit import OUTLIER_SIGMAS, dilate, huber_line, robust_sd
from slam.commands.calibrate.runs import CalibrationRun

MIN_STRETCH_S = 30.0
MAX_LAG_FRACTION = 0.5
"""Lags up to this share of the longest stretch are searched."""


@dataclass(frozen=True)
class CompassNoise:
    """The compass's error against the gyro: ``sd_rad``, ``correlation_s``,
    over ``steps`` steps of ``stretches`` stretches."""

    sd_rad: float
    correlation_s: float
    steps: int
    stretches: int


def _usable(run: CalibrationRun, rate_hz: float) -> np.ndarray:
    """The clean steps with both headings; in a run learnt whole (nothing
    declared clean), less those more than ``OUTLIER_SIGMAS`` robust sds
    off a Huber line through the difference, and a second either side:
    a disturbance is a fault, not the compass's noise."""
    s = run.steps
    ok = run.clean & s.valid["compass_yaw"] & s.valid["gyro_yaw"]
    if run.declared or ok.sum() < 3:
        return ok
    d = s.values["compass_yaw"][ok] - s.values["gyro_yaw"][ok]
    slope, intercept = huber_line(s.t[ok], d)
    r = d - slope * s.t[ok] - intercept
    out = np.zeros(len(ok), dtype=bool)
    out[ok] = np.abs(r - np.median(r)) > OUTLIER_SIGMAS * max(robust_sd(r), 1e-12)
    return ok & ~dilate(out, int(round(rate_hz)))


def _stretches(run: CalibrationRun, rate_hz: float, min_steps: int) -> list[np.ndarray]:
    """Compass minus gyro heading (rad), less a line, on each run of
    consecutive usable steps."""
    s = run.steps
    if "compass_yaw" not in s.values or "gyro_yaw" not in s.values:
        return []
    ok = _usable(run, rate_hz)
    edges = np.flatnonzero(np.diff(np.concatenate(([0], ok.astype(np.int8), [0]))))
    out = []
    for a, b in zip(edges[::2], edges[1::2]):
        if b - a >= min_steps:
            d = s.values["compass_yaw"][a:b] - s.values["gyro_yaw"][a:b]
            i = np.arange(len(d), dtype=float)
            out.append(d - np.polyval(np.polyfit(i, d, 1), i))
    return out


def _autocorrelation(pieces: Sequence[np.ndarray], max_lag: int) -> np.ndarray:
    """Autocorrelation at lags 0..max_lag steps, pooled over ``pieces``
    (their lag products summed, over the pooled variance)."""
    var = sum(float(np.dot(p, p)) for p in pieces) / sum(len(p) for p in pieces)
    rho = np.ones(max_lag + 1)
    for k in range(1, max_lag + 1):
        num = sum(float(np.dot(p[:-k], p[k:])) for p in pieces if len(p) > k)
        den = sum(len(p) - k for p in pieces if len(p) > k)
        rho[k] = num / den / var
    return rho


def learn_compass_noise(runs: Sequence[CalibrationRun], rate_hz: float) -> CompassNoise | None:
    """The compass's error (module docstring); None without a compass and a
    gyro over a clean stretch of ``MIN_STRETCH_S``, or where the
    autocorrelation stays above 1/e over the lags searched."""
    dt = 1.0 / rate_hz
    pieces = [p for run in runs for p in _stretches(run, rate_hz, int(np.ceil(MIN_STRETCH_S / dt)))]
    if not pieces:
        return None
    rho = _autocorrelation(pieces, int(MAX_LAG_FRACTION * max(len(p) for p in pieces)))
    below = np.flatnonzero(rho < np.exp(-1.0))
    if not len(below):
        return None
    k = int(below[0])
    # Linear between the last lag above 1/e and the first below.
    tau = dt * (k - 1 + (rho[k - 1] - np.exp(-1.0)) / (rho[k - 1] - rho[k]))
    return CompassNoise(robust_sd(np.concatenate(pieces)), float(tau), sum(len(p) for p in pieces), len(pieces))
