"""Qualitative trends: the paper's Algorithms 1 (abstractStream) and 2
(deriveStream) against transcriptions of their listings, line by line, and
the batch, reference and online forms against each other."""

from __future__ import annotations

import math

import numpy as np
import pytest

from validation.base.errors import ValidationError
from validation.trends import (
    KEEP,
    Trend,
    TrendEstimator,
    abstract_stream,
    derive_stream,
    stream_derivatives,
    symbol_rule,
    symbols_from_derivatives,
)

# --- the listings, transcribed (1-based indices as printed) ---------------------


def linear_regression(values: list[float], times: list[float]) -> float:
    """Slope of the least-squares line through the points (0 for fewer than two)."""
    if len(values) < 2:
        return 0.0
    tm, vm = sum(times) / len(times), sum(values) / len(values)
    num = sum((a - tm) * (b - vm) for a, b in zip(times, values))
    den = sum((a - tm) ** 2 for a in times)
    return num / den


def listing_derive_stream(S: list[float], w: int, dt: float) -> list[float]:
    """Algorithm 2, deriveStream(S, w), on a stream sampled every ``dt`` s::

        1: for i=1 to |S| do
        2:   start = min(ceil(i + w/2), |S|)
        3:   end = max(1, floor(i - w/2))
        4:   d[i] = linearRegression(S[start, end])
        5: end for
        6: return d
    """
    n = len(S)
    d = [0.0] * (n + 1)  # 1-based
    for i in range(1, n + 1):
        start = min(math.ceil(i + w / 2), n)
        end = max(1, math.floor(i - w / 2))
        idx = range(end, start + 1)
        d[i] = linear_regression([S[j - 1] for j in idx], [j * dt for j in idx])
    return d[1:]


def listing_abstract_stream(S: list[float], b: float, w: int, dt: float) -> list[int]:
    """Algorithm 1, abstractStream(S, b, w)::

         1: r1 = deriveStream(S, w)
         2: r2 = deriveStream(r1, w)
         3: r3 = deriveStream(r2, w)
         4: a[1] = 0
         5: for i=2 to |S| do
         6:   if r1[i] < -b then a[i] = -
         9:   else if r1[i] > b then a[i] = +
        12:   else if not((-b < r2[i] < b) and (-b < r3[i] < b)) then a[i] = 0
        15:   else a[i] = a[i-1]
        20: return a
    """
    r1 = listing_derive_stream(S, w, dt)
    r2 = listing_derive_stream(r1, w, dt)
    r3 = listing_derive_stream(r2, w, dt)
    n = len(S)
    a = [0] * (n + 1)
    a[1] = 0
    for i in range(2, n + 1):
        if r1[i - 1] < -b:
            a[i] = -1
        elif r1[i - 1] > b:
            a[i] = 1
        elif not ((-b < r2[i - 1] < b) and (-b < r3[i - 1] < b)):
            a[i] = 0
        else:
            a[i] = a[i - 1]
    return a[1:]


def ref_trailing(t, v, w):
    """Loop over samples; two-pass least squares on each trailing window [t - w, t]."""
    out = np.zeros(len(t))
    for i in range(len(t)):
        sel = [j for j in range(i + 1) if t[j] >= t[i] - w]
        out[i] = linear_regression([v[j] for j in sel], [t[j] for j in sel])
    return out


def ref_centred(t, v, w):
    """Loop over samples; least squares on each centred window [t - w/2, t + w/2]."""
    out = np.zeros(len(t))
    for i in range(len(t)):
        sel = [j for j in range(len(t)) if t[i] - w / 2 <= t[j] <= t[i] + w / 2]
        out[i] = linear_regression([v[j] for j in sel], [t[j] for j in sel])
    return out


def irregular(n, seed, rate_hz=10.0):
    rng = np.random.default_rng(seed)
    t = np.cumsum(rng.uniform(0.2, 1.8, n) / rate_hz) + 1000.0
    return t, rng


# --- Algorithm 2: deriveStream ---------------------------------------------------


@pytest.mark.parametrize("w", [2, 4, 6])
def test_derive_stream_follows_the_listing(w):
    """On a uniform stream a centred window of w * dt seconds is the listing's
    w samples; dt = 0.5 s keeps every time exact in binary."""
    rng = np.random.default_rng(w)
    dt = 0.5
    S = list(np.cumsum(rng.normal(0, 1, 40)) + 0.3 * np.arange(40))
    t = np.arange(1, 41) * dt
    np.testing.assert_allclose(derive_stream(t, np.array(S), w * dt, "centred"), listing_derive_stream(S, w, dt), atol=1e-9)


def test_derive_stream_windows_truncated_at_both_ends():
    t = np.arange(6) * 0.5
    v = t**2
    r = derive_stream(t, v, 1.0, "centred")  # windows of 3 samples, 2 at the ends
    assert r[0] == pytest.approx(0.25 / 0.5)  # samples 0, 1: (0.25 - 0) / 0.5
    assert r[2] == pytest.approx(2.0)  # samples 1..3 of t^2: slope 2 t at t = 1
    assert r[5] == pytest.approx((6.25 - 4.0) / 0.5)  # samples 4, 5


@pytest.mark.parametrize("window, ref", [("trailing", ref_trailing), ("centred", ref_centred)])
def test_derive_stream_matches_reference_on_irregular_streams(window, ref):
    for seed in range(3):
        t, rng = irregular(250, seed)
        v = np.cumsum(rng.normal(0, 0.1, len(t))) + 50.0 * np.sin(0.05 * t)
        for w in (0.05, 0.35, 1.0, 3.0):
            np.testing.assert_allclose(derive_stream(t, v, w, window), ref(t, v, w), rtol=1e-9, atol=1e-9)


def test_trailing_window_truncated_at_start():
    t = np.array([0.0, 0.1, 0.2, 0.3, 0.4, 0.5])
    v = np.array([0.0, 1.0, 4.0, 9.0, 16.0, 25.0])
    r = derive_stream(t, v, 0.25, "trailing")
    assert r[0] == 0.0  # one sample -> slope 0
    assert r[1] == pytest.approx(10.0)  # two samples: (1 - 0) / 0.1
    assert r[2] == pytest.approx(20.0)  # [0, 0.2]: fit of 0, 1, 4
    assert r[5] == pytest.approx(80.0)  # [0.3, 0.5]: fit of 9, 16, 25
    # a window holding one sample after a gap has slope 0 again
    assert derive_stream(np.array([0.0, 0.1, 5.0]), np.array([0.0, 1.0, 2.0]), 1.0, "trailing")[2] == 0.0


@pytest.mark.parametrize("window", ["trailing", "centred"])
def test_long_stream_keeps_precision(window):
    """2 h at 10 Hz with a large offset: cumulative sums must not cancel. The
    stream is a line plus a slow sine, whose exact windowed slope is known
    to far better than 1e-9 away from the ends."""
    t = 1000.0 + np.arange(72_000) * 0.1
    v = 2000.0 + 0.8 * t
    r1 = derive_stream(t, v, 2.0, window)
    np.testing.assert_allclose(r1[30:-30], 0.8, rtol=0, atol=1e-9)
    u = np.sin(0.1 * t)
    got = derive_stream(t, u, 2.0, window)
    k = np.arange(30_000, 30_100)
    np.testing.assert_allclose(got[k], (ref_centred if window == "centred" else ref_trailing)(t[k[0] - 40: k[-1] + 41], u[k[0] - 40: k[-1] + 41], 2.0)[40:-40], atol=1e-9)


def test_angles_unwrapped_across_pi():
    t = np.arange(0.0, 20.0, 0.1)
    yaw_true = 2.5 + 0.3 * t  # crosses +pi at t ~ 2.1 and goes on turning left
    wrapped = np.angle(np.exp(1j * yaw_true))
    r1, _, _ = stream_derivatives(t, wrapped, 1.0, "trailing", angular=True)
    np.testing.assert_allclose(r1[10:], 0.3, atol=1e-9)
    raw, _, _ = stream_derivatives(t, wrapped, 1.0, "trailing", angular=False)
    assert np.min(raw) < -1.0  # without unwrapping the jump shows up as a fast turn right
    est = TrendEstimator(1.0, 0.05, angular=True)
    online = np.array([est.update(a, b).r1 for a, b in zip(t, wrapped)])
    np.testing.assert_allclose(online, r1, atol=1e-9)


def test_rejects_bad_input():
    with pytest.raises(ValidationError, match="increase strictly"):
        derive_stream(np.array([0.0, 1.0, 1.0]), np.zeros(3), 1.0)
    with pytest.raises(ValidationError, match="finite"):
        derive_stream(np.array([0.0, 1.0]), np.array([0.0, np.nan]), 1.0)
    with pytest.raises(ValidationError, match="window_s"):
        derive_stream(np.array([0.0, 1.0]), np.zeros(2), 0.0)


# --- Algorithm 1: abstractStream --------------------------------------------------


@pytest.mark.parametrize("seed", range(4))
def test_abstract_stream_follows_the_listing(seed):
    rng = np.random.default_rng(seed)
    dt, w, b = 0.5, 4, 0.2
    n = 80
    ramp = np.concatenate([np.zeros(20), np.linspace(0, 6, 20), np.full(20, 6.0), np.linspace(6, 0, 20)])
    S = list(ramp + rng.normal(0, 0.05, n))
    t = np.arange(1, n + 1) * dt
    got = abstract_stream(t, np.array(S), b, w * dt, "centred", "paper").symbol
    expected = listing_abstract_stream(S, b, w, dt)
    assert got.tolist() == expected
    assert len(set(expected)) == 3  # every branch of the listing is exercised


def test_paper_rule_cases():
    b, w = 0.1, 2.0
    assert symbol_rule(0.2, 0.0, 0.0, b, w, "paper") == Trend.PLUS  # line 9
    assert symbol_rule(-0.2, 5.0, 5.0, b, w, "paper") == Trend.MINUS  # line 6
    assert symbol_rule(0.05, 0.5, 0.0, b, w, "paper") == Trend.ZERO  # r2 outside the band: an extremum
    assert symbol_rule(0.05, 0.0, -0.1, b, w, "paper") == Trend.ZERO  # r3 on the boundary: outside (strict)
    assert symbol_rule(0.05, 0.05, 0.05, b, w, "paper") == KEEP  # smooth inside the band: keep
    assert symbol_rule(0.1, 0.0, 0.0, b, w, "paper") == KEEP  # r1 = b is inside the band


def test_project_rule_cases():
    b, w = 0.1, 2.0  # dead zones: |r2| <= 0.05, |r3| <= 0.025
    assert symbol_rule(0.2, 0.0, 0.0, b, w, "project") == Trend.PLUS
    assert symbol_rule(-0.2, 5.0, 5.0, b, w, "project") == Trend.MINUS
    assert symbol_rule(0.05, 0.0, 0.0, b, w, "project") == Trend.ZERO  # flat
    assert symbol_rule(0.05, -1.0, 1.0, b, w, "project") == Trend.ZERO  # settling, braking less
    assert symbol_rule(0.05, 1.0, 0.0, b, w, "project") == KEEP  # still growing
    assert symbol_rule(0.05, -1.0, -1.0, b, w, "project") == KEEP  # settling but accelerating away
    assert symbol_rule(0.1, 1.0, 0.0, b, w, "project") == KEEP  # boundary belongs to the band
    assert symbol_rule(0.05, 0.04, 1.0, b, w, "project") == Trend.ZERO  # r2 within its dead zone: flat
    assert symbol_rule(0.05, 0.06, 0.02, b, w, "project") == KEEP  # r2 outside, r3 inside
    assert symbol_rule(-0.05, 0.06, -0.03, b, w, "project") == Trend.ZERO  # negative slope settling


def test_keep_previous_symbol():
    r1 = np.array([0.05, 0.2, 0.05, 0.05, -0.05, -0.2, -0.05, 0.0])
    r2 = np.array([1.0, 0.0, 1.0, -1.0, -1.0, 0.0, -1.0, 0.0])
    r3 = np.zeros(8)
    s = symbols_from_derivatives(r1, r2, r3, 0.1, 1.0, "project")
    # start: KEEP with no previous -> 0; growing inside band after + -> keep +;
    # settling -> 0; growing negative -> keep 0; - ; growing -> keep -; flat -> 0
    assert s.tolist() == [0, 1, 1, 0, 0, -1, -1, 0]
    # the paper's rule: r2 outside the band gives 0, a smooth band keeps
    p = symbols_from_derivatives(r1, np.array([0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.5, 0.0]), r3, 0.1, 1.0, "paper")
    assert p.tolist() == [0, 1, 1, 1, 1, -1, 0, 0]


def test_known_trends_both_rules_and_windows():
    t = np.arange(0.0, 30.0, 0.1)
    v = np.where(t < 10, 0.5 * t, np.where(t < 20, 5.0, 5.0 - 0.5 * (t - 20)))
    for window in ("centred", "trailing"):
        for rule in ("paper", "project"):
            s = abstract_stream(t, v, 0.1, 1.0, window, rule).symbol
            assert np.all(s[(t > 1.5) & (t < 9)] == Trend.PLUS), (window, rule)
            assert np.all(s[(t > 12.5) & (t < 19)] == Trend.ZERO), (window, rule)
            assert np.all(s[(t > 22.5)] == Trend.MINUS), (window, rule)


def test_centred_window_has_no_delay():
    """A step in the slope at 10 s: the centred trend turns + before the
    trailing one, which lags by about half its window."""
    t = np.arange(0.0, 20.0, 0.1)
    v = np.where(t < 10, 0.0, t - 10)
    w = 2.0
    first = {}
    for window in ("centred", "trailing"):
        s = abstract_stream(t, v, 0.3, w, window, "paper").symbol
        first[window] = t[np.argmax(s == Trend.PLUS)]
    assert first["centred"] < 10.0 < first["trailing"]
    assert first["trailing"] - first["centred"] == pytest.approx(w / 2, abs=0.25)


@pytest.mark.parametrize("rule", ["paper", "project"])
def test_batch_reference_online_agree_on_random_streams(rule):
    for seed in range(3):
        t, rng = irregular(400, 10 + seed)
        v = np.cumsum(rng.normal(0, 0.05, len(t))) + np.where(t > t[200], 0.3 * (t - t[200]), 0.0)
        w, b = 0.8, 0.15
        batch = abstract_stream(t, v, b, w, "trailing", rule)
        r1 = ref_trailing(t, v, w)
        r2 = ref_trailing(t, r1, w)
        r3 = ref_trailing(t, r2, w)
        np.testing.assert_allclose(batch.r1, r1, atol=1e-9)
        np.testing.assert_allclose(batch.r3, r3, atol=1e-9 * max(1.0, np.max(np.abs(r3))))
        est = TrendEstimator(w, b, rule=rule)
        online = [est.update(a, x) for a, x in zip(t, v)]
        np.testing.assert_allclose([o.r1 for o in online], batch.r1, atol=1e-9)
        np.testing.assert_allclose([o.r2 for o in online], batch.r2, atol=1e-9 * max(1.0, np.max(np.abs(r2))))
        np.testing.assert_allclose([o.r3 for o in online], batch.r3, atol=1e-9 * max(1.0, np.max(np.abs(r3))))
        assert [int(o.symbol) for o in online] == batch.symbol.tolist()
        assert len(set(batch.symbol.tolist())) == 3  # the test exercises every symbol


def test_online_rejects_time_going_back():
    est = TrendEstimator(1.0, 0.1)
    est.update(1.0, 0.0)
    with pytest.raises(ValidationError, match="does not follow"):
        est.update(1.0, 0.0)
