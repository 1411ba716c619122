"""Quantitative relation observers: the residual of two streams' changes,
and the standing offset between two streams.

Trend symbols compare the direction of two streams' changes, not their size:
a scan matcher that reports 20 m/s while the odometry says 0.4 m/s has the
same ``+`` trend. A *residual* relation (``RelationConfig.kind:
residual``) compares the sizes. Over a window of ``w`` seconds, centred on
the step (offline) or ending at it (causal), each stream changes by ``da``
and ``db``; their residual and its expected spread are

    r = db - gain * da - rate_offset * w,   sigma = sqrt(sigma_floor^2 + (sigma_rel * da)^2),

and the step is a mismatch where ``|r| > k_sigma * sigma``. The mismatches
feed Algorithm 3 like differing trend symbols do, so a residual observer's
``NO_MATCH`` means the same to the diagnosis as a trend observer's.
``sigma_floor`` is the noise of the two streams' changes over a window in
stream b's units, ``sigma_rel`` the relative error of a scale (an odometry
a few percent off), so the defaults come from the sensors' noise, or from
``gslam calibrate``.

An *offset* relation (``kind: offset``) compares the streams themselves: an
absolute heading against an integrated one, which agree up to an offset
that changes slowly (the gyro's bias). The difference ``d = b - gain * a``
is compared with its own level, learnt from the steps that agree with it
(a disturbance does not drag the level along): offline, a line fitted to
``d`` over a window of ``level_window_s`` centred on the step (a steady
drift has no lag there), started from the window's median and refitted on
the steps within ``k_sigma * sigma_floor`` of it; near the ends of the data
the window is shifted inside it rather than cut short; causal, over the agreeing steps of the
trailing window, the median of its recent half extrapolated to the step
with the slope between the medians of its two halves (a steady drift would
lag by half a window otherwise), held while no step agrees. Windows do not
reach across a gap in either stream. A step is a mismatch where
``|d - level|`` exceeds ``k_sigma * sigma_floor``. It sees what changes cannot: a compass
that sits a few degrees off for minutes near steel, or comes back from a
disturbance slowly. A *held* level (``level_max_rate``) is learnt from the
steps before each one in both passes (a centred window would straddle the
disturbance it is to measure) and moves no faster than ``level_max_rate``
a second: a difference that runs off faster than the reference can drift
is a mismatch for as long as it stays off. With ``level_window_s`` null the level is 0 and an
angular difference is wrapped: two absolute headings calibrated against
each other (a compass and the GPS course) must agree, and an offset that
stands for minutes is an error however slowly it came.
"""

from __future__ import annotations

from collections import deque

import numpy as np

from validation.observers.config import RelationConfig
from validation.trends import Window


_TOL = 1e-6
"""Relative slack on a window's length: step times are sums of floats."""


def window_changes(t: np.ndarray, v: np.ndarray, valid: np.ndarray, window_s: float, window: Window) -> tuple[np.ndarray, np.ndarray]:
    """Change of ``v`` (m,) over each step's window and whether every step in
    the window has data (a window that reaches past the data is invalid)."""
    eps = _TOL * window_s
    if window == "trailing":
        start, end = np.searchsorted(t, t - window_s - eps, side="left"), np.arange(len(t))
    else:
        start = np.searchsorted(t, t - 0.5 * window_s - eps, side="left")
        end = np.searchsorted(t, t + 0.5 * window_s + eps, side="right") - 1
    bad = np.concatenate(([0], np.cumsum(~valid)))
    whole = (bad[end + 1] - bad[start] == 0) & (end > start)
    # Only a full window counts: at the ends of the data it is truncated.
    whole &= t[end] - t[start] >= window_s - 2 * eps
    change = np.where(whole, v[end] - v[start], 0.0)
    return change, whole


def travel_windows(
    t: np.ndarray, a: np.ndarray, valid: np.ndarray, travel: float, max_s: float, window: Window,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(start, end, whole)``: each step's window spanning ``travel`` of
    stream ``a``'s travel (the sum of its absolute changes), centred on the
    step in travel (offline) or ending at it (causal), and whether it is
    whole: inside the data, every step in it with data, no longer than
    ``max_s``."""
    m = len(t)
    step = np.zeros(m)
    step[1:] = np.abs(np.diff(np.where(valid, a, 0.0)))
    step[1:][~(valid[1:] & valid[:-1])] = 0.0
    run = np.cumsum(step)
    eps = _TOL * travel
    if window == "trailing":
        back, ahead = travel, 0.0
    else:
        back = ahead = 0.5 * travel
    start = np.searchsorted(run, run - back + eps, side="right") - 1
    end = np.searchsorted(run, run + ahead - eps, side="left") if ahead > 0 else np.arange(m)
    inside = (start >= 0) & (end < m)
    start, end = np.clip(start, 0, m - 1), np.clip(end, 0, m - 1)
    bad = np.concatenate(([0], np.cumsum(~valid)))
    whole = inside & (bad[end + 1] - bad[start] == 0) & (end > start)
    whole &= t[end] - t[start] <= max_s + _TOL * max_s
    return start, end, whole


def travel_changes(
    t: np.ndarray, a: np.ndarray, b: np.ndarray, valid_a: np.ndarray, valid_b: np.ndarray, travel: float,
    max_s: float, window: Window,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(da, db, whole)``: the two streams' changes over each step's window
    of ``travel`` of stream a (:func:`travel_windows`)."""
    valid = valid_a & valid_b
    start, end, whole = travel_windows(t, a, valid, travel, max_s, window)
    da = np.where(whole, a[end] - a[start], 0.0)
    db = np.where(whole, b[end] - b[start], 0.0)
    return da, db, whole


def residual_test(rel: RelationConfig, da: np.ndarray, db: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(z, mismatch)``: the normalised residual of each step and whether it
    exceeds ``k_sigma``."""
    r = db - rel.gain * da - rel.rate_offset * rel.window_s
    sigma = np.sqrt(rel.sigma_floor**2 + (rel.sigma_rel * da) ** 2)
    z = r / sigma
    return z, np.abs(z) > rel.k_sigma


class WindowChange:
    """The change of one stream over a trailing window, one step at a time;
    an ``angular`` stream's change is wrapped to (-pi, pi]."""

    def __init__(self, window_s: float, angular: bool = False) -> None:
        self.window_s = window_s
        self.angular = angular
        self._buf: deque[tuple[float, float]] = deque()

    def update(self, t: float, v: float | None) -> float | None:
        """Add the step ``(t, v)``; None where ``v`` is missing or the window
        does not yet hold ``window_s`` of unbroken data."""
        if v is None or not np.isfinite(v):
            self._buf.clear()
            return None
        self._buf.append((t, v))
        eps = _TOL * self.window_s
        while self._buf[0][0] < t - self.window_s - eps:
            self._buf.popleft()
        t0, v0 = self._buf[0]
        if t - t0 < self.window_s - 2 * eps:
            return None
        return float(np.angle(np.exp(1j * (v - v0)))) if self.angular else v - v0


class TravelChange:
    """The changes of two streams over a trailing window of ``travel`` of
    stream a's travel, one step at a time (:func:`travel_windows`)."""

    def __init__(self, travel: float, max_s: float, angular: tuple[bool, bool] = (False, False)) -> None:
        self.travel, self.max_s, self.angular = travel, max_s, angular
        self._buf: deque[tuple[float, float, float, float]] = deque()  # (t, a, b, travel so far)

    def update(self, t: float, a: float | None, b: float | None) -> tuple[float, float] | None:
        """Add the step; ``(da, db)``, or None where either value is missing
        or the window does not hold ``travel`` within ``max_s``."""
        if a is None or b is None or not (np.isfinite(a) and np.isfinite(b)):
            self._buf.clear()
            return None
        run = self._buf[-1][3] + abs(a - self._buf[-1][1]) if self._buf else 0.0
        self._buf.append((t, a, b, run))
        eps = _TOL * self.travel
        # Keep the last step at least ``travel`` back as the window's start.
        while len(self._buf) > 1 and self._buf[1][3] <= run - self.travel + eps:
            self._buf.popleft()
        t0, a0, b0, run0 = self._buf[0]
        if run0 > run - self.travel + eps or len(self._buf) < 2 or t - t0 > self.max_s + _TOL * self.max_s:
            return None
        return tuple(float(np.angle(np.exp(1j * d))) if ang else d
                     for d, ang in ((a - a0, self.angular[0]), (b - b0, self.angular[1])))


def _trailing_level(t: np.ndarray, d: np.ndarray, now: float, window_s: float) -> float:
    """Median of the recent half of a trailing window, extrapolated to ``now``
    with the slope between the medians of the two halves."""
    mid = now - 0.5 * window_s
    recent, older = d[t >= mid], d[t < mid]
    if not len(recent):
        return float(np.median(older))
    level = float(np.median(recent))
    if len(older):
        slope = (level - float(np.median(older))) / (0.5 * window_s)
        level += slope * 0.25 * window_s
    return level


def running_level(
    t: np.ndarray, d: np.ndarray, valid: np.ndarray, window_s: float, window: Window, tolerance: float,
    max_rate: float | None = None,
) -> np.ndarray:
    """Level of ``d`` at each step (module docstring); ``tolerance`` is the
    largest distance from the level at which a step still agrees, and
    ``max_rate`` (per second) holds it. NaN at steps without data."""
    out = np.full(len(t), np.nan)
    run = np.cumsum(np.concatenate(([True], valid[1:] != valid[:-1])))
    if window == "trailing" or max_rate is not None:
        level = None
        for k in range(len(t)):
            if k == 0 or run[k] != run[k - 1]:
                level = RunningLevel(window_s, tolerance, max_rate)
            if valid[k]:
                out[k] = level.update(t[k], d[k])
        return out
    for r in np.unique(run[valid]):
        idx = np.flatnonzero((run == r) & valid)
        out[idx] = _centred_level(t[idx], d[idx], window_s, tolerance)
    return out


def _centred_level(t: np.ndarray, d: np.ndarray, window_s: float, tolerance: float) -> np.ndarray:
    """Level of one unbroken run: at each step, a line fitted to the steps of
    its window that lie within ``tolerance`` of it (a disturbance does not
    drag the level along; a slow drift, such as a gyro's bias, is followed).
    The window is centred on the step, shifted inside the run within half a
    window of its ends (the whole run when it is shorter), so the level at
    the ends is read off the same full window, not a half one. The line is
    fitted every ``window_s / 60`` and interpolated between."""
    eps = _TOL * window_s
    span = t[-1] - t[0]
    lo = np.clip(t - 0.5 * window_s, t[0], max(t[0], t[-1] - window_s))
    hi = np.minimum(lo + window_s, t[-1]) if span >= window_s else np.full(len(t), t[-1])
    a = np.searchsorted(t, lo - eps, side="left")
    b = np.searchsorted(t, hi + eps, side="right")
    # The level is a line over a window of a minute: fitted at one step per
    # 1/60 of the window (1 s for 60 s) and interpolated between.
    knots = np.unique(np.r_[np.searchsorted(t, np.arange(t[0], t[-1], window_s / 60.0)), len(t) - 1])
    level = np.array([_robust_line(t[a[k]:b[k]] - t[k], d[a[k]:b[k]], tolerance) for k in knots])
    return np.interp(t, t[knots], level)


def _robust_line(x: np.ndarray, y: np.ndarray, tolerance: float) -> float:
    """Value at ``x = 0`` of a line through the points within ``tolerance``
    of it: started from the window's median, refitted on the points that
    agree (three times, so a slow drift brings the window's ends back in);
    the median where too few agree."""
    median = float(np.median(y))
    offset, slope, fitted_on = median, 0.0, None
    for _ in range(3):
        near = np.abs(y - (offset + slope * x)) <= tolerance
        n = int(np.count_nonzero(near))
        if n < max(3, len(x) // 10):
            return median
        if fitted_on is not None and np.array_equal(near, fitted_on):
            break  # the same points give the same line
        xs, ys = x[near], y[near]
        xm, ym = xs.sum() / n, ys.sum() / n
        var = float(((xs - xm) ** 2).sum())
        slope = float(((xs - xm) * (ys - ym)).sum()) / var if var > 0 else 0.0
        offset = ym - slope * xm
        fitted_on = near
    return float(offset)


def offset_test(rel: RelationConfig, d: np.ndarray, level: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(z, mismatch)`` of an offset relation at each step."""
    z = (d - level) / rel.sigma_floor
    return z, np.abs(z) > rel.k_sigma


class RunningLevel:
    """The trailing level of a difference, one step at a time (module
    docstring): the steps within ``tolerance`` of the level are learnt, the
    others are not; with ``max_rate`` the level moves no faster than that a
    second. A gap in the data starts it afresh."""

    def __init__(self, window_s: float, tolerance: float, max_rate: float | None = None) -> None:
        self.window_s = window_s
        self.tolerance = tolerance
        self.max_rate = max_rate
        self._t: deque[float] = deque()
        self._d: deque[float] = deque()
        self._level: float | None = None
        self._level_t: float | None = None

    def reset(self) -> None:
        self._t.clear()
        self._d.clear()
        self._level = None
        self._level_t = None

    def update(self, t: float, d: float) -> float:
        """The level at step ``t`` given its difference ``d``."""
        if self._level is None or abs(d - self._level) <= self.tolerance:
            self._t.append(t)
            self._d.append(d)
        while self._t and self._t[0] < t - self.window_s - _TOL * self.window_s:
            self._t.popleft()
            self._d.popleft()
        if self._t:
            level = _trailing_level(np.fromiter(self._t, float), np.fromiter(self._d, float), t, self.window_s)
            if self.max_rate is not None and self._level is not None:
                step = self.max_rate * (t - self._level_t)
                level = min(max(level, self._level - step), self._level + step)
            self._level = level
        self._level_t = t
        return self._level
