"""What a relation looks like in data: the gain and offset between two
streams' rates and the noise of what is left.

Over windows of ``w`` seconds (centred offline, trailing causal, as the
observers use them) stream a changes by ``da`` and stream b by ``db``. A
line ``db = gain * da + rate_offset * w`` is fitted with Huber weights
(:func:`huber_line`), so a few steps far off the line do not move it. What
is left, ``r = db - gain * da - rate_offset * w``, has a noise floor (the
robust standard deviation of ``r`` over the windows with the smaller half
of the motion, 1.4826 times their median absolute deviation) and may grow
with the motion (``sigma_rel``, from the windows with the largest quarter).

Where stream a hardly moves (its changes spread less than
``MIN_MOTION`` times the residual's noise: the sideways travel of a robot
that does not skid) the gain cannot be told from noise: it stays at the
relation's configured one and only the offset is learnt.

Learnt over a declared clean stretch, every step counts. Learnt over a
whole run, the steps whose residual lies beyond ``OUTLIER_SIGMAS`` times
the band (the noise floor, growing by ``sigma_rel`` of the motion), and
half a window either side of them, are taken for faults and left out of
everything that follows (:attr:`RateFit.inliers`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from slam.commands.calibrate.runs import CalibrationRun
from validation.observers.quantitative import running_level, travel_changes, window_changes
from validation.base.geometry import wrap_angle
from validation.trends import Window, derive_stream

MAD_TO_SD = 1.4826
OUTLIER_SIGMAS = 4.0
MIN_MOTION = 3.0


def robust_sd(x: np.ndarray) -> float:
    """1.4826 x the median absolute deviation from the median; where more
    than half the values are equal (a stream at rest), 1.2533 x the mean
    absolute deviation instead (both are the sd of a normal). 0 for no data."""
    x = np.asarray(x, float)
    if not len(x):
        return 0.0
    dev = np.abs(x - np.median(x))
    mad = float(np.median(dev))
    return MAD_TO_SD * mad if mad > 0.0 else 1.2533 * float(np.mean(dev))


def huber_line(x: np.ndarray, y: np.ndarray, k: float = 1.345, iterations: int = 30) -> tuple[float, float]:
    """``(slope, intercept)`` of ``y ~ slope * x + intercept`` by iteratively
    reweighted least squares with Huber weights (tuning ``k`` robust sds)."""
    x, y = np.asarray(x, float), np.asarray(y, float)
    a = np.column_stack([x, np.ones_like(x)])
    w = np.ones_like(x)
    coef = np.zeros(2)
    for _ in range(iterations):
        sw = np.sqrt(w)
        coef, *_ = np.linalg.lstsq(a * sw[:, None], y * sw, rcond=None)
        r = y - a @ coef
        s = max(robust_sd(r), 1e-12)
        w = np.minimum(1.0, k * s / np.maximum(np.abs(r), 1e-300))
    return float(coef[0]), float(coef[1])


def dilate(mask: np.ndarray, steps: int) -> np.ndarray:
    """``mask`` widened by ``steps`` on each side."""
    if steps <= 0 or not mask.any():
        return mask
    n = len(mask)
    count = np.concatenate(([0], np.cumsum(mask)))
    i = np.arange(n)
    return count[np.minimum(i + steps + 1, n)] - count[np.maximum(i - steps, 0)] > 0


@dataclass
class RateFit:
    """Stream b's windowed change against stream a's, over ``window_s``."""

    a: str
    b: str
    window_s: float
    gain: float
    rate_offset: float
    noise: float
    sigma_rel: float
    corr: float
    steps: int
    motion: float
    inliers: list[np.ndarray] = field(default_factory=list, repr=False)
    gain_fitted: bool = True
    """False where stream a hardly moves and the gain is the configured one."""


def changes(run: CalibrationRun, name: str, window_s: float, window: Window) -> tuple[np.ndarray, np.ndarray]:
    """Windowed change of stream ``name`` at each step of ``run`` and whether the window was whole."""
    s = run.steps
    values = np.where(s.valid[name], s.values[name], 0.0)
    return window_changes(s.t, values, s.valid[name], window_s, window)


def pair_changes(run: CalibrationRun, a: str, b: str, window_s: float, window: Window,
                 travel: float | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(da, db, whole)``: both streams' changes over each step's window,
    of ``window_s`` or, with ``travel``, of that much of stream a's travel
    lasting at most ``window_s`` (a relation's ``window_travel``)."""
    if travel is None:
        da, ok_a = changes(run, a, window_s, window)
        db, ok_b = changes(run, b, window_s, window)
        return da, db, ok_a & ok_b
    s = run.steps
    return travel_changes(s.t, s.values[a], s.values[b], s.valid[a], s.valid[b], travel, window_s, window)


def _ratio(x: np.ndarray, y: np.ndarray, prior_gain: float) -> tuple[float, float, bool]:
    """The median of ``y / x`` as the gain, through 0; ``prior_gain`` where
    ``x`` never moves."""
    moved = np.abs(x) > 0
    if not moved.any():
        return prior_gain, 0.0, False
    return float(np.median(y[moved] / x[moved])), 0.0, True


def _line(x: np.ndarray, y: np.ndarray, prior_gain: float) -> tuple[float, float, bool]:
    """Huber line, or ``prior_gain`` and a robust intercept where ``x``
    hardly moves (module docstring); and whether the gain was fitted."""
    gain, intercept = huber_line(x, y)
    if robust_sd(x) < MIN_MOTION * max(robust_sd(y - gain * x - intercept), 1e-12):
        gain = prior_gain
        intercept = float(np.median(y - gain * x))
        return gain, intercept, False
    return gain, intercept, True


def _noise_model(r: np.ndarray, da: np.ndarray, keep: np.ndarray) -> tuple[float, float, float]:
    """``(noise, sigma_rel, spread)`` of the residuals ``r`` on the ``keep``
    windows: the robust sd over the windows with the smaller half of the
    motion, the share of the motion by which it grows (from the windows
    with the largest quarter), and the robust sd over all of them."""
    spread = max(robust_sd(r[keep]), 1e-12)
    small = keep & (np.abs(da) <= np.median(np.abs(da[keep])))
    large = keep & (np.abs(da) >= np.percentile(np.abs(da[keep]), 75))
    noise = max(robust_sd(r[small]) if small.sum() > 10 else spread, 1e-9)
    sigma_rel = 0.0
    big = float(np.median(np.abs(da[large]))) if large.any() else 0.0
    if big > 0.0 and large.sum() > 10:
        sigma_rel = float(np.sqrt(max(robust_sd(r[large]) ** 2 - noise**2, 0.0)) / big)
    return noise, sigma_rel, spread


def fit_rates(runs: Sequence[CalibrationRun], a: str, b: str, window_s: float, window: Window,
              rate_hz: float, prior_gain: float = 1.0, travel: float | None = None) -> RateFit | None:
    """The fit of the module docstring over every run holding both streams;
    None when no step has both. With ``travel``, over windows of that much
    of stream a's travel lasting at most ``window_s`` (:func:`pair_changes`):
    the line then goes through 0, a rate offset having no time to act on."""
    per_run = []
    for run in runs:
        if a not in run.streams or b not in run.streams:
            per_run.append(None)
            continue
        da, db, ok = pair_changes(run, a, b, window_s, window, travel)
        per_run.append((da, db, ok & run.clean))
    used = [p for p in per_run if p is not None]
    if not used or not any(m.any() for _, _, m in used):
        return None
    da = np.concatenate([d[m] for d, _, m in used])
    db = np.concatenate([d[m] for _, d, m in used])
    keep = np.ones(len(da), dtype=bool)
    declared = all(r.declared for r in runs)
    # Windows of travel all hold about the same change of stream a: a line
    # through them is ill-posed, their ratio is not.
    line = _ratio if travel is not None else _line
    for _ in range(1 if declared else 3):
        gain, intercept, _ = line(da[keep], db[keep], prior_gain)
        r = db - gain * da - intercept
        if not declared:
            # The band grows with the motion: a sensor whose error is a
            # share of the turn (tracks slipping) is not faulty in every turn.
            noise, sigma_rel, spread = _noise_model(r, da, keep)
            band = np.maximum(spread, np.sqrt(noise**2 + (sigma_rel * da) ** 2))
            keep = np.abs(r - np.median(r[keep])) <= OUTLIER_SIGMAS * band
    gain, intercept, fitted = line(da[keep], db[keep], prior_gain)
    r = db - gain * da - intercept
    noise, sigma_rel, spread = _noise_model(r, da, keep)
    corr = float(np.corrcoef(da[keep], db[keep])[0, 1]) if keep.sum() > 2 and np.std(da[keep]) > 0 and np.std(db[keep]) > 0 else 0.0
    inliers = []
    for run, p in zip(runs, per_run):
        if p is None:
            inliers.append(np.zeros(len(run.steps.t), dtype=bool))
            continue
        ra, rb, m = p
        res = rb - gain * ra - intercept
        band = np.maximum(spread, np.sqrt(noise**2 + (sigma_rel * ra) ** 2))
        out = m & (np.abs(res) > OUTLIER_SIGMAS * band)
        # A centred window reaches half its length either side of an outlier.
        good = run.clean if run.declared else run.clean & ~dilate(out, int(round(0.5 * window_s * rate_hz)))
        inliers.append(good)
    return RateFit(a, b, window_s, gain, intercept / window_s, noise, sigma_rel, corr, int(keep.sum()),
                   robust_sd(da[keep]), inliers, fitted)


def fit_offset(runs: Sequence[CalibrationRun], a: str, b: str, gain: float, level_window_s: float | None,
               window: Window, inliers: Sequence[np.ndarray],
               max_rate: float | None = None) -> tuple[float, float, int]:
    """``(sd, median, steps)``: robust sd and median of ``b - gain * a``
    about its running median over ``level_window_s`` (the offset observer's
    level, held to ``max_rate`` where given) on the inlier steps, and how
    many there were;
    with ``level_window_s`` None (a level of 0), of the difference itself,
    wrapped where a stream is an angle. A robust sd, because the difference
    of two absolute headings has heavy tails: the GPS course at walking
    speed swings by tens of degrees where the fixes jump."""
    res = []
    for run, good in zip(runs, inliers):
        if a not in run.streams or b not in run.streams:
            continue
        s = run.steps
        valid = s.valid[a] & s.valid[b]
        d = np.where(valid, s.values[b] - gain * s.values[a], 0.0)
        if level_window_s is None:
            if s.angular[a] or s.angular[b]:
                d = wrap_angle(d)
            level = np.zeros(len(d))
        else:
            level = running_level(s.t, d, valid, level_window_s, window, np.inf, max_rate)
        keep = valid & good
        res.append((d - level)[keep])
    if not res or not sum(len(r) for r in res):
        return 0.0, 0.0, 0
    res = np.concatenate(res)
    return max(robust_sd(res), 1e-9), float(np.median(res)), len(res)


def _slopes(run: CalibrationRun, name: str, window_s: float, window: Window) -> np.ndarray:
    s = run.steps
    v = s.valid[name]
    out = np.zeros(len(s.t))
    out[v] = derive_stream(s.t[v], s.values[name][v], window_s, window)
    return out


def fit_slopes(runs: Sequence[CalibrationRun], a: str, b: str, window_s: float, window: Window,
               inliers: Sequence[np.ndarray]) -> tuple[float, float]:
    """``(sd, median)``: robust sd and median of stream b's regression slope
    (Algorithm 2, over ``window_s``) minus stream a's, on the inlier steps:
    how much the two slopes disagree, and by how much one stands off the
    other (a gyro's bias), which a trend boundary must stand above (the
    symbols compare directions, whatever the gain); ``(0, 0)`` without a step."""
    res = []
    for run, good in zip(runs, inliers):
        if a not in run.streams or b not in run.streams:
            continue
        s = run.steps
        keep = s.valid[a] & s.valid[b] & good
        res.append((_slopes(run, b, window_s, window) - _slopes(run, a, window_s, window))[keep])
    d = np.concatenate(res) if res else np.zeros(0)
    return (max(robust_sd(d), 1e-9), float(np.median(d))) if len(d) else (0.0, 0.0)


MOTION_QUANTILE = 90.0


def motion_scale(runs: Sequence[CalibrationRun], name: str, window_s: float, window: Window,
                 inliers: Sequence[np.ndarray], slope: bool = False) -> float:
    """How much stream ``name`` moves when it moves: the ``MOTION_QUANTILE``
    percentile of its absolute change over ``window_s`` (its regression
    slope with ``slope``) on the inlier steps; 0 without a step."""
    out = []
    for run, good in zip(runs, inliers):
        if name not in run.streams:
            continue
        if slope:
            ok = run.steps.valid[name]
            out.append(np.abs(_slopes(run, name, window_s, window))[ok & good])
        else:
            d, ok = changes(run, name, window_s, window)
            out.append(np.abs(d)[ok & good])
    moved = np.concatenate(out) if out else np.zeros(0)
    return float(np.percentile(moved, MOTION_QUANTILE)) if len(moved) else 0.0
