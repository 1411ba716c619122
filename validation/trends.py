"""Qualitative trends of a sensor stream: the paper's Algorithms 1 and 2.

Algorithm 2, :func:`derive_stream` (deriveStream), estimates the slope of a
stream at every sample by a least-squares line over a window of width ``w``
around it. The paper's window is *centred* on the sample (``i - w/2`` to
``i + w/2``, truncated at the ends of the stream), so it needs the samples
after ``i``: an offline computation. A *trailing* window (``t_i - w`` to
``t_i``) uses the past only, for online validation; a batch run and the
online :class:`TrendEstimator` then give the same values. Windows are in
seconds on the real timestamps, so irregular sampling is fine (on a uniform
stream a window of ``w`` seconds is the paper's ``w * rate`` samples). With
fewer than two samples in the window the slope is 0.

Algorithm 1, :func:`abstract_stream` (abstractStream), applies
deriveStream three times, ``r1`` (slope), ``r2`` (slope of ``r1``) and
``r3`` (slope of ``r2``), and maps each sample to one :class:`Trend` symbol
with a boundary ``b``:

* rule ``paper``, as listed: ``a[1] = 0``; then ``+`` if ``r1 > b``, ``-``
  if ``r1 < -b``; inside the band ``0`` if NOT (``-b < r2 < b`` and
  ``-b < r3 < b``) (a minimum, maximum or saddle point), else the previous
  symbol is kept. ``b`` bounds all three derivatives, as in the listing.
* rule ``project``: inside the band, ``0`` when the slope is flat or
  settling (``r1 * r2 <= 0`` and ``r2 * r3 <= 0``, signs read with dead
  zones ``b / w`` and ``b / w^2``), else the previous symbol is kept. A slope
  still growing in magnitude through the band keeps its symbol, and the
  small, smooth wander of a low-noise slope cannot hold a stale symbol.

Units: ``t`` in s, ``v`` in stream units (rad for yaw), ``r1`` in units/s,
``r2`` in units/s^2, ``r3`` in units/s^3, ``b`` in units/s.
"""

from __future__ import annotations

import logging
from collections import deque
from dataclasses import dataclass
from enum import IntEnum
from typing import Literal, NamedTuple

import numpy as np

from validation.base.errors import ValidationError

logger = logging.getLogger(__name__)

Window = Literal["centred", "trailing"]
Rule = Literal["paper", "project"]


class Trend(IntEnum):
    """Qualitative symbol of a stream's slope."""

    MINUS = -1
    ZERO = 0
    PLUS = 1


KEEP = 2
"""Code returned by :func:`symbol_rule`: keep the previous symbol."""

FLAT_TOL = 1e-9
"""|r1| <= this counts as zero in the project's rule, so that round-off
cannot decide a symbol."""


# --- Algorithm 2: deriveStream ---------------------------------------------------


def _check_stream(t: np.ndarray, v: np.ndarray, window_s: float) -> None:
    if t.ndim != 1 or v.shape != t.shape:
        raise ValidationError(f"trend input: t and v must be 1-D of equal length, got {t.shape} and {v.shape}")
    if not window_s > 0.0:
        raise ValidationError(f"trend input: window_s must be > 0, got {window_s}")
    if not (np.all(np.isfinite(t)) and np.all(np.isfinite(v))):
        raise ValidationError("trend input: t and v must be finite (mask gaps before computing trends)")
    if len(t) > 1 and not np.all(np.diff(t) > 0.0):
        i = int(np.flatnonzero(np.diff(t) <= 0.0)[0]) + 1
        raise ValidationError(f"trend input: timestamps must increase strictly (sample {i}: {t[i]} after {t[i - 1]})")


def window_bounds(t: np.ndarray, window_s: float, window: Window) -> tuple[np.ndarray, np.ndarray]:
    """First and last sample index (inclusive) of each sample's window."""
    n = len(t)
    if window == "trailing":
        return np.searchsorted(t, t - window_s, side="left"), np.arange(n)
    half = 0.5 * window_s
    return np.searchsorted(t, t - half, side="left"), np.searchsorted(t, t + half, side="right") - 1


def derive_stream(t: np.ndarray, v: np.ndarray, window_s: float, window: Window = "centred") -> np.ndarray:
    """Algorithm 2 (deriveStream): the least-squares slope of ``v`` over each
    sample's window (module docstring), in O(n).

    ``slope_i = cov(t, v) / var(t)`` over the window's samples; 0 with fewer
    than two. Windowed sums come from cumulative sums, which would lose the
    slope to cancellation on long streams if taken on raw times (sum t^2 ~
    1e12 for a 2 h run against a window variance ~ 1). So the stream is cut
    into time bins a little wider than the window, times and values are
    taken relative to the first sample of their bin, and a window (which
    spans at most two bins) shifts the part lying in the earlier bin to the
    reference of the later one.
    """
    t = np.asarray(t, dtype=float)
    v = np.asarray(v, dtype=float)
    _check_stream(t, v, window_s)
    n = len(t)
    if n < 2:
        return np.zeros(n)
    start, end = window_bounds(t, window_s, window)
    idx = np.arange(n)

    # 1. Bins: wider than the window by a margin far above the round-off of
    #    the division, so no window can touch three bins.
    bins = np.floor((t - t[0]) / (window_s * (1.0 + 1e-6))).astype(np.int64)
    new_bin = np.concatenate(([True], bins[1:] != bins[:-1]))
    first = np.maximum.accumulate(np.where(new_bin, idx, 0))

    # 2. Local coordinates and their prefix sums (leading 0).
    a = t - t[first]
    b = v - v[first]

    def prefix(x: np.ndarray) -> np.ndarray:
        return np.concatenate(([0.0], np.cumsum(x)))

    pa, pb, paa, pab = prefix(a), prefix(b), prefix(a * a), prefix(a * b)

    # 3. Part of the window in the bin of its last sample: [max(start, f), end].
    f = first[end]
    s_a = np.maximum(start, f)
    n_a = (end + 1 - s_a).astype(float)
    su = pa[end + 1] - pa[s_a]
    sv = pb[end + 1] - pb[s_a]
    suu = paa[end + 1] - paa[s_a]
    suv = pab[end + 1] - pab[s_a]

    # 4. Part in the bin before: [start, f - 1], shifted by the offset
    #    between the two bins' references (zero-length when start >= f).
    s_b = np.minimum(start, f)
    n_b = (f - s_b).astype(float)
    prev_first = first[s_b]
    dt = t[prev_first] - t[f]
    dv = v[prev_first] - v[f]
    ba = pa[f] - pa[s_b]
    bb = pb[f] - pb[s_b]
    baa = paa[f] - paa[s_b]
    bab = pab[f] - pab[s_b]
    su = su + ba + n_b * dt
    sv = sv + bb + n_b * dv
    suu = suu + baa + 2.0 * dt * ba + n_b * dt * dt
    suv = suv + bab + dt * bb + dv * ba + n_b * dt * dv

    # 5. Slope of the least-squares line.
    count = n_a + n_b
    den = count * suu - su * su
    num = count * suv - su * sv
    ok = (count >= 2) & (den > 0.0)
    return np.where(ok, num / np.where(ok, den, 1.0), 0.0)


def stream_derivatives(
    t: np.ndarray, v: np.ndarray, window_s: float, window: Window = "centred", angular: bool = False
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(r1, r2, r3)``: Algorithm 2 applied three times on the same window
    (lines 1-3 of Algorithm 1). ``angular`` streams (yaw, rad) are unwrapped
    first so a crossing of +-pi is not a jump."""
    v = np.unwrap(np.asarray(v, dtype=float)) if angular else np.asarray(v, dtype=float)
    r1 = derive_stream(t, v, window_s, window)
    r2 = derive_stream(t, r1, window_s, window)
    r3 = derive_stream(t, r2, window_s, window)
    return r1, r2, r3


# --- Algorithm 1: abstractStream ------------------------------------------------


def _sign(x, tol: float) -> np.ndarray:
    x = np.asarray(x, dtype=float)
    return np.where(np.abs(x) <= tol, 0.0, np.sign(x))


def symbol_rule(r1, r2, r3, boundary: float, window_s: float, rule: Rule = "paper") -> np.ndarray:
    """Lines 6-16 of Algorithm 1 for one or many samples: a :class:`Trend`
    code, or ``KEEP`` where the previous symbol is kept (module docstring)."""
    r1 = np.asarray(r1, dtype=float)
    r2 = np.asarray(r2, dtype=float)
    r3 = np.asarray(r3, dtype=float)
    b = boundary
    if rule == "paper":
        in_band = (-b < r2) & (r2 < b) & (-b < r3) & (r3 < b)
        inside = np.where(~in_band, int(Trend.ZERO), KEEP)
    else:
        s1 = _sign(r1, FLAT_TOL)
        s2 = _sign(r2, b / window_s)
        s3 = _sign(r3, b / window_s**2)
        settling = (s1 * s2 <= 0) & (s2 * s3 <= 0)
        inside = np.where(settling, int(Trend.ZERO), KEEP)
    out = np.where(r1 > b, int(Trend.PLUS), np.where(r1 < -b, int(Trend.MINUS), inside))
    return out.astype(np.int8)


def symbols_from_derivatives(
    r1: np.ndarray, r2: np.ndarray, r3: np.ndarray, boundary: float, window_s: float, rule: Rule = "paper"
) -> np.ndarray:
    """Lines 4-19 of Algorithm 1 over a whole stream: (n,) int8 symbols.

    The keep-previous recursion is resolved without a loop: samples where
    the rule decides carry their code, the others take the code of the last
    deciding sample (forward fill); before the first decision the symbol is
    ``ZERO``. With the paper's rule the first sample is ``ZERO`` (line 4).
    """
    codes = symbol_rule(r1, r2, r3, boundary, window_s, rule)
    if rule == "paper" and len(codes):
        codes[0] = int(Trend.ZERO)
    n = len(codes)
    decided = np.where(codes != KEEP, np.arange(n), -1)
    last = np.maximum.accumulate(decided) if n else decided
    return np.where(last >= 0, codes[np.maximum(last, 0)], int(Trend.ZERO)).astype(np.int8)


@dataclass(frozen=True)
class TrendSeries:
    """Trends of one stream: derivatives and the (n,) int8 symbol per sample."""

    t: np.ndarray
    r1: np.ndarray
    r2: np.ndarray
    r3: np.ndarray
    symbol: np.ndarray


def abstract_stream(
    t: np.ndarray,
    v: np.ndarray,
    boundary: float,
    window_s: float,
    window: Window = "centred",
    rule: Rule = "paper",
    angular: bool = False,
) -> TrendSeries:
    """Algorithm 1 (abstractStream) over a whole stream (batch, vectorised)."""
    r1, r2, r3 = stream_derivatives(t, v, window_s, window, angular)
    symbol = symbols_from_derivatives(r1, r2, r3, boundary, window_s, rule)
    return TrendSeries(np.asarray(t, dtype=float), r1, r2, r3, symbol)


# --- online (trailing windows) ------------------------------------------------------


class _SlidingSlope:
    """Causal least-squares slope over ``[t - w, t]`` with running sums.

    Sums are kept relative to a reference sample; every
    ``max(len(window), 16)`` updates they are recomputed about the newest
    sample, which bounds both the round-off drift of adding and removing
    and the distance to the reference, at O(1) amortised cost.
    """

    def __init__(self, window_s: float) -> None:
        self._w = window_s
        self._buf: deque[tuple[float, float]] = deque()
        self._ref_t = self._ref_v = 0.0
        self._su = self._sv = self._suu = self._suv = 0.0
        self._since_rebase = 0

    def _add(self, t: float, v: float, sign: float) -> None:
        a, b = t - self._ref_t, v - self._ref_v
        self._su += sign * a
        self._sv += sign * b
        self._suu += sign * a * a
        self._suv += sign * a * b

    def _rebase(self, t: float, v: float) -> None:
        self._ref_t, self._ref_v = t, v
        self._su = self._sv = self._suu = self._suv = 0.0
        for tj, vj in self._buf:
            self._add(tj, vj, 1.0)
        self._since_rebase = 0

    def update(self, t: float, v: float) -> float:
        if not self._buf:
            self._ref_t, self._ref_v = t, v
        self._buf.append((t, v))
        self._add(t, v, 1.0)
        lower = t - self._w
        while self._buf[0][0] < lower:
            tj, vj = self._buf.popleft()
            self._add(tj, vj, -1.0)
        self._since_rebase += 1
        if self._since_rebase >= max(len(self._buf), 16):
            self._rebase(t, v)
        n = float(len(self._buf))
        den = n * self._suu - self._su * self._su
        if n < 2 or den <= 0.0:
            return 0.0
        return (n * self._suv - self._su * self._sv) / den


class TrendSample(NamedTuple):
    """One online trend estimate."""

    r1: float
    r2: float
    r3: float
    symbol: Trend


class TrendEstimator:
    """Algorithm 1 with trailing windows, one sample at a time (causal,
    O(1) amortised); gives the same values as :func:`abstract_stream` with
    ``window="trailing"`` on the same samples."""

    def __init__(self, window_s: float, boundary: float, angular: bool = False, rule: Rule = "paper") -> None:
        if not window_s > 0.0:
            raise ValidationError(f"trend estimator: window_s must be > 0, got {window_s}")
        self.window_s = window_s
        self.boundary = boundary
        self.angular = angular
        self.rule = rule
        self._levels = (_SlidingSlope(window_s), _SlidingSlope(window_s), _SlidingSlope(window_s))
        self._symbol = Trend.ZERO
        self._last_t: float | None = None
        self._last_raw = 0.0
        self._unwrap_offset = 0.0

    def _unwrap(self, v: float) -> float:
        # Same arithmetic as np.unwrap, applied incrementally.
        if self._last_t is not None:
            dd = v - self._last_raw
            ddmod = np.mod(dd + np.pi, 2.0 * np.pi) - np.pi
            if ddmod == -np.pi and dd > 0:
                ddmod = np.pi
            if abs(dd) >= np.pi:
                self._unwrap_offset += ddmod - dd
        self._last_raw = v
        return v + self._unwrap_offset

    def update(self, t: float, v: float) -> TrendSample:
        """Add the sample ``(t s, v units)``; times must increase strictly."""
        t, v = float(t), float(v)
        if not (np.isfinite(t) and np.isfinite(v)):
            raise ValidationError(f"trend estimator: non-finite sample ({t}, {v})")
        if self._last_t is not None and t <= self._last_t:
            raise ValidationError(f"trend estimator: time {t} does not follow {self._last_t}")
        first = self._last_t is None
        if self.angular:
            v = self._unwrap(v)
        self._last_t = t
        r1 = self._levels[0].update(t, v)
        r2 = self._levels[1].update(t, r1)
        r3 = self._levels[2].update(t, r2)
        code = int(symbol_rule(r1, r2, r3, self.boundary, self.window_s, self.rule))
        if first and self.rule == "paper":
            code = int(Trend.ZERO)
        if code != KEEP:
            self._symbol = Trend(code)
        return TrendSample(r1, r2, r3, self._symbol)
