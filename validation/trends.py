"""Qualitative trends of a sensor stream: the paper's Algorithms 1 and 2.

Algorithm 1 (:func:`derivative`) estimates the slope of a stream at every
sample by a least-squares line over the trailing window ``[t_i - w, t_i]``
on the real timestamps, so irregular sampling is fine; it is causal, hence a
batch run and an online run (:class:`TrendEstimator`) give the same values.
Near the start the window holds fewer samples; with fewer than two the slope
is 0. Applied three times it gives ``r1`` (slope), ``r2`` (slope of ``r1``)
and ``r3`` (slope of ``r2``), all on the same timestamps and window.

Algorithm 2 (:func:`qualitative_rule`, :func:`qualitative_symbols`) turns
``(r1, r2, r3)`` into one :class:`Trend` symbol per sample using a boundary
``b`` in stream units per second.

Units: ``t`` in s, ``v`` in stream units (rad for yaw), ``r1`` in units/s,
``r2`` in units/s^2, ``r3`` in units/s^3.
"""

from __future__ import annotations

import logging
from collections import deque
from dataclasses import dataclass
from enum import IntEnum
from typing import NamedTuple

import numpy as np

from validation.errors import ValidationError

logger = logging.getLogger(__name__)


class Trend(IntEnum):
    """Qualitative symbol of a stream's slope."""

    MINUS = -1
    ZERO = 0
    PLUS = 1


KEEP = 2
"""Code returned by :func:`qualitative_rule`: keep the previous symbol."""

FLAT_TOL = 1e-9
"""|r1| <= this counts as zero in Algorithm 2, so that round-off cannot
decide a symbol."""


def _sign(x, tol: float) -> np.ndarray:
    x = np.asarray(x, dtype=float)
    return np.where(np.abs(x) <= tol, 0.0, np.sign(x))


def qualitative_rule(r1, r2, r3, boundary: float, window_s: float) -> np.ndarray:
    """Algorithm 2 for one or many samples: a :class:`Trend` code or ``KEEP``.

    * ``r1 > b``  -> ``PLUS``; ``r1 < -b`` -> ``MINUS``;
    * inside ``[-b, b]`` the symbol becomes ``ZERO`` when the slope is flat or
      settling, i.e. ``r1*r2 <= 0`` (the magnitude of the slope is not
      increasing) and ``r2*r3 <= 0`` (that change is not accelerating away);
    * otherwise ``KEEP``: the previous symbol is kept (hysteresis: a slope
      still growing in magnitude through the band keeps its symbol).

    This is our reading of the paper's listing, whose exact condition on
    ``r2``/``r3`` is not reproduced in the text we have. ``boundary`` is in
    stream units per second, ``window_s`` is Algorithm 1's window.

    Signs of ``r2`` and ``r3`` are taken with dead zones ``b / w`` and
    ``b / w^2``: a slope changing by less than b over one window is flat.
    Without them, the small, smooth wander of a low-noise slope (r1, r2, r3
    strongly correlated) holds a stale symbol for many seconds.
    """
    r1 = np.asarray(r1, dtype=float)
    s1 = _sign(r1, FLAT_TOL)
    s2 = _sign(r2, boundary / window_s)
    s3 = _sign(r3, boundary / window_s**2)
    settling = (s1 * s2 <= 0) & (s2 * s3 <= 0)
    inside = np.where(settling, int(Trend.ZERO), KEEP)
    out = np.where(r1 > boundary, int(Trend.PLUS), np.where(r1 < -boundary, int(Trend.MINUS), inside))
    return out.astype(np.int8)


def qualitative_symbols(
    r1: np.ndarray, r2: np.ndarray, r3: np.ndarray, boundary: float, window_s: float
) -> np.ndarray:
    """Algorithm 2 over a whole stream: (n,) int8 :class:`Trend` values.

    The keep-previous recursion is resolved without a loop: samples where
    the rule decides carry their code, the others take the code of the last
    deciding sample (forward fill); before the first decision the symbol is
    ``ZERO``.
    """
    codes = qualitative_rule(r1, r2, r3, boundary, window_s)
    n = len(codes)
    decided = np.where(codes != KEEP, np.arange(n), -1)
    last = np.maximum.accumulate(decided) if n else decided
    return np.where(last >= 0, codes[np.maximum(last, 0)], int(Trend.ZERO)).astype(np.int8)


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


def derivative(t: np.ndarray, v: np.ndarray, window_s: float) -> np.ndarray:
    """Algorithm 1: least-squares slope over the trailing window, O(n).

    ``slope_i = cov(t, v) / var(t)`` over the samples with
    ``t_i - window_s <= t_j <= t_i``; 0 with fewer than two samples.

    Windowed sums come from cumulative sums, which would lose the slope to
    cancellation on long streams if taken on raw times (sum t^2 ~ 1e12 for a
    2 h run against a window variance ~ 1). So the stream is cut into time
    bins a little wider than the window, times and values are taken
    relative to the first sample of their bin, and a window (which spans at
    most two bins) shifts the part lying in the previous bin to the
    reference of the current one.
    """
    t = np.asarray(t, dtype=float)
    v = np.asarray(v, dtype=float)
    _check_stream(t, v, window_s)
    n = len(t)
    if n < 2:
        return np.zeros(n)
    idx = np.arange(n)
    start = np.searchsorted(t, t - window_s, side="left")

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

    # 3. Part of the window in the current bin: [max(start, first), i].
    s_a = np.maximum(start, first)
    n_a = (idx + 1 - s_a).astype(float)
    su = pa[idx + 1] - pa[s_a]
    sv = pb[idx + 1] - pb[s_a]
    suu = paa[idx + 1] - paa[s_a]
    suv = pab[idx + 1] - pab[s_a]

    # 4. Part in the previous bin: [start, first - 1], shifted by the offset
    #    between the two bins' references (zero-length when start >= first).
    s_b = np.minimum(start, first)
    n_b = (first - s_b).astype(float)
    prev_first = first[s_b]
    dt = t[prev_first] - t[first]
    dv = v[prev_first] - v[first]
    ba = pa[first] - pa[s_b]
    bb = pb[first] - pb[s_b]
    baa = paa[first] - paa[s_b]
    bab = pab[first] - pab[s_b]
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


def trend_derivatives(
    t: np.ndarray, v: np.ndarray, window_s: float, angular: bool = False
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(r1, r2, r3)``: Algorithm 1 applied three times on the same window.

    ``angular`` streams (yaw, rad) are unwrapped first so a crossing of
    +-pi is not a jump.
    """
    v = np.unwrap(np.asarray(v, dtype=float)) if angular else np.asarray(v, dtype=float)
    r1 = derivative(t, v, window_s)
    r2 = derivative(t, r1, window_s)
    r3 = derivative(t, r2, window_s)
    return r1, r2, r3


@dataclass(frozen=True)
class TrendSeries:
    """Trends of one stream: derivatives and the (n,) int8 symbol per sample."""

    t: np.ndarray
    r1: np.ndarray
    r2: np.ndarray
    r3: np.ndarray
    symbol: np.ndarray


def trends(t: np.ndarray, v: np.ndarray, window_s: float, boundary: float, angular: bool = False) -> TrendSeries:
    """Algorithms 1 and 2 over a whole stream (batch, vectorised)."""
    r1, r2, r3 = trend_derivatives(t, v, window_s, angular)
    return TrendSeries(np.asarray(t, dtype=float), r1, r2, r3, qualitative_symbols(r1, r2, r3, boundary, window_s))


# --- online --------------------------------------------------------------


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
    """Causal Algorithms 1 and 2, one sample at a time (O(1) amortised).

    Gives the same values as :func:`trends` on the same samples.
    """

    def __init__(self, window_s: float, boundary: float, angular: bool = False) -> None:
        if not window_s > 0.0:
            raise ValidationError(f"trend estimator: window_s must be > 0, got {window_s}")
        self.window_s = window_s
        self.boundary = boundary
        self.angular = angular
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
        if self.angular:
            v = self._unwrap(v)
        self._last_t = t
        r1 = self._levels[0].update(t, v)
        r2 = self._levels[1].update(t, r1)
        r3 = self._levels[2].update(t, r2)
        code = int(qualitative_rule(r1, r2, r3, self.boundary, self.window_s))
        if code != KEEP:
            self._symbol = Trend(code)
        return TrendSample(r1, r2, r3, self._symbol)
