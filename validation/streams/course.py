"""The GPS course: the robot's direction of travel from its fixes, an
absolute heading independent of the compass.

Over each fix's window (``window_s``, centred or trailing, the one
``gps_speed`` uses) the regression slopes (Algorithm 2) of the fixes' x
and y give a velocity; its direction is the course (rad, ENU yaw, wrapped).
Three things make that direction differ from the heading, and the stream
leaves those fixes out rather than report a course that is not the heading:

* **Too little travel.** The slope of a regression over a window of ``w``
  seconds with ``n`` fixes of noise ``sigma`` has an sd of about
  ``sigma * sqrt(12 / n) / w`` per axis, so the course's sd is that over
  the speed: the travel ``v * w`` must be several times ``sigma``. A fix is
  kept where the regression's speed is at least ``min_speed_mps``; the
  default 0.5 m/s travels 2.5-4 m over windows of 5-8 s, three to four
  times the 0.9 m of a consumer receiver: with fixes at 2.5 Hz, a course
  sd from white noise of 10 degrees (8 s) to 20 degrees (5 s) at that
  speed, half that at 1 m/s (GPS errors that wander slowly add to it).
* **Turns.** Over a window that holds a turn, the direction of travel is a
  chord, not the heading at the step (a trailing window lags by half its
  length times the turn rate). A fix is kept where the odometry's yaw turns
  by at most ``max_turn_rad`` over the same window.
* **Reversing.** A skid-steer or tracked robot backing up travels opposite
  its heading: where the odometry's forward speed (the regression slope of
  its forward travel over the same window) is negative, the course is
  turned by pi, so the stream stays a heading.

Both the turn and the driving direction come from the odometry, so without
odometry there is no course stream: a course that might be the heading
plus pi would be silently wrong.
"""

from __future__ import annotations

import numpy as np

from validation.trends import Window, derive_stream


def _window_span(at: np.ndarray, window_s: float, window: Window) -> tuple[np.ndarray, np.ndarray]:
    """Start and end (s) of each step's window."""
    if window == "trailing":
        return at - window_s, at
    return at - 0.5 * window_s, at + 0.5 * window_s


def _window_turn(t: np.ndarray, yaw: np.ndarray, at: np.ndarray, window_s: float, window: Window) -> np.ndarray:
    """Largest absolute change (rad) of the unwrapped ``yaw`` (sampled at
    ``t``) between any two instants of each window around ``at``: the
    spread of the heading over the window."""
    lo, hi = _window_span(at, window_s, window)
    yaw = np.unwrap(yaw)
    a = np.searchsorted(t, lo, side="left")
    b = np.searchsorted(t, hi, side="right")
    y_lo, y_hi = np.interp(lo, t, yaw), np.interp(hi, t, yaw)
    out = np.abs(y_hi - y_lo)
    for k in np.flatnonzero(b > a):
        inside = np.concatenate(([y_lo[k], y_hi[k]], yaw[a[k]:b[k]]))
        out[k] = inside.max() - inside.min()
    return out


def gps_course(
    t: np.ndarray,
    vx: np.ndarray,
    vy: np.ndarray,
    odo_yaw: tuple[np.ndarray, np.ndarray],
    odo_forward: tuple[np.ndarray, np.ndarray],
    window_s: float,
    window: Window,
    min_speed_mps: float,
    max_turn_rad: float,
) -> tuple[np.ndarray, np.ndarray]:
    """``(t, course)`` at the fixes (s, strictly increasing ``t``) where the
    course is the heading (module docstring); ``vx``, ``vy`` (m/s) are the
    regression slopes of the fixes' x and y over the window, as
    ``gps_speed`` takes them; ``course`` is wrapped to (-pi, pi].
    ``odo_yaw`` is the odometry's ``(t, yaw)`` (s, rad), ``odo_forward`` its
    ``(t, cumulative forward travel)`` (s, m)."""
    course = np.arctan2(vy, vx)
    keep = np.hypot(vx, vy) >= min_speed_mps
    # The odometry must cover the whole window for its turn and direction to count.
    yaw_t, yaw = odo_yaw
    fwd_t, fwd = odo_forward
    lo, hi = _window_span(t, window_s, window)
    keep &= (lo >= max(yaw_t[0], fwd_t[0])) & (hi <= min(yaw_t[-1], fwd_t[-1]))
    keep &= _window_turn(yaw_t, yaw, t, window_s, window) <= max_turn_rad
    forward = np.interp(t, fwd_t, derive_stream(fwd_t, fwd, window_s, window))
    course = np.where(forward < 0.0, course + np.pi, course)
    return t[keep], np.angle(np.exp(1j * course[keep]))
