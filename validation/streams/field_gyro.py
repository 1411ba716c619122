"""The magnetic field against the gyro: in an undisturbed field, the
magnetometer's vector turns exactly as the gyro says.

A compass heading is the direction of the field's horizontal part. A
magnet passing by adds a field of its own, which moves that direction; it
also moves the field's vector in a way no turn of the sensor explains. The
gyro measures the turn, so

    w(t) = Rz(psi(t)) f(t),

the field ``f`` (level frame, z up) turned by the gyro's integrated
heading ``psi``, stays constant in an undisturbed field, whatever the
sensor does. Its change over a short trailing window,

    c(t) = |mean of w over (t - s, t] - mean of w over (t - w - s, t - w]|,

(window ``w``, smoothing ``s`` against the magnetometer's noise) is the
stream ``mag_field_change`` (T); the unary check
(:class:`validation.observers.checks.FieldGyroCheck`) flags the compass where it
exceeds a tolerance. Unlike the field's strength and dip against the run's
start, it needs no reference that the sensor's residual calibration error
moves over a run (a hand-held board turned over shows 2-5 uT), only the
last ``w`` seconds; unlike the compass-gyro trend, it sees a disturbance
that leaves the heading's slope alone for most of a pass and the field's
vertical part, which a heading never shows.

The gyro's bias turns ``w`` slowly (0.5 deg/s turns a 15 uT horizontal
field by 0.13 uT a second) and the magnetometer's calibration error moves
it as the sensor turns; both set the tolerance, which ``gslam calibrate``
learns. The two sensors' samples must be on one clock: a 12 ms lag turns a
40 uT field by 5 uT at 10 rad/s (:mod:`slam.readers.broad`).
"""

from __future__ import annotations

import numpy as np

GAP_PERIODS = 5.0
"""The window's start must lie within this many of the compass's median
sample periods after a compass sample."""


def _trailing_mean(t: np.ndarray, v: np.ndarray, span_s: float) -> np.ndarray:
    """Mean of the rows of ``v`` (n, k) over ``(t - span_s, t]`` at each sample."""
    c = np.vstack([np.zeros((1, v.shape[1])), np.cumsum(v, axis=0)])
    start = np.searchsorted(t, t - span_s, side="right")
    end = np.arange(1, len(t) + 1)
    return (c[end] - c[start]) / (end - start)[:, None]


def field_change(
    compass_t: np.ndarray,
    field: np.ndarray,
    gyro_t: np.ndarray,
    gyro_yaw: np.ndarray,
    window_s: float,
    smooth_s: float,
) -> np.ndarray:
    """``mag_field_change`` (module docstring) at each compass sample, in the
    field's units; NaN where the window's start has no compass sample
    within ``GAP_PERIODS`` sample periods or lies before the data or
    outside the gyro's."""
    t = np.asarray(compass_t, dtype=float)
    out = np.full(len(t), np.nan)
    if len(t) < 2 or len(gyro_t) < 2:
        return out
    psi = np.interp(t, gyro_t, gyro_yaw)
    f = np.asarray(field, dtype=float)
    c, s = np.cos(psi), np.sin(psi)
    w = np.column_stack([c * f[:, 0] - s * f[:, 1], s * f[:, 0] + c * f[:, 1], f[:, 2]])
    mean = _trailing_mean(t, w, smooth_s)
    # Each end needs a sample of its own: the gyro's heading runs on through
    # a gap in the compass (dropped samples, a level frame undefined), so
    # the ends may lie on either side of one.
    near = GAP_PERIODS * float(np.median(np.diff(t)))
    back = t - window_s
    j = np.searchsorted(t, back, side="right") - 1
    ok = (j >= 0) & (back - t[np.maximum(j, 0)] <= near) & (t - window_s >= gyro_t[0]) & (t <= gyro_t[-1])
    ok &= t - t[0] >= window_s + smooth_s  # the first mean is a whole one
    if not ok.any():
        return out
    earlier = np.column_stack([np.interp(back[ok], t, mean[:, k]) for k in range(3)])
    out[ok] = np.linalg.norm(mean[ok] - earlier, axis=1)
    return out
