"""Qualitative trends (Algorithms 1 and 2): batch == reference == online."""

from __future__ import annotations

import numpy as np
import pytest

from validation.errors import ValidationError
from validation.trends import (
    KEEP,
    Trend,
    TrendEstimator,
    derivative,
    qualitative_rule,
    qualitative_symbols,
    trend_derivatives,
    trends,
)

# --- obviously-correct references -----------------------------------------


def ref_derivative(t, v, w):
    """Loop over samples; two-pass least squares on each trailing window."""
    out = np.zeros(len(t))
    for i in range(len(t)):
        sel = [j for j in range(i + 1) if t[j] >= t[i] - w]
        if len(sel) < 2:
            continue
        tt = np.array([t[j] for j in sel])
        vv = np.array([v[j] for j in sel])
        tm, vm = tt.mean(), vv.mean()
        out[i] = np.sum((tt - tm) * (vv - vm)) / np.sum((tt - tm) ** 2)
    return out


def ref_derivative_offsets(t, v, w):
    """The same two-pass regression vectorised over the window offset,
    O(n * samples per window); used where the loop would be too slow."""
    n = len(t)
    start = np.searchsorted(t, t - w, side="left")
    m = int(np.max(np.arange(n) - start)) + 1
    count = np.arange(n) - start + 1
    st = np.zeros(n)
    sv = np.zeros(n)
    for k in range(m):
        j = np.arange(n) - k
        use = j >= start
        st[use] += t[j[use]]
        sv[use] += v[j[use]]
    tm, vm = st / count, sv / count
    cov = np.zeros(n)
    var = np.zeros(n)
    for k in range(m):
        j = np.arange(n) - k
        use = j >= start
        dt = t[j[use]] - tm[use]
        cov[use] += dt * (v[j[use]] - vm[use])
        var[use] += dt * dt
    return np.where(count >= 2, cov / np.where(count >= 2, var, 1.0), 0.0)


def ref_symbols(r1, r2, r3, b, w):
    """Algorithm 2 as a loop over samples."""
    out, prev = [], Trend.ZERO
    for x1, x2, x3 in zip(r1, r2, r3):
        code = int(qualitative_rule(x1, x2, x3, b, w))
        if code != KEEP:
            prev = Trend(code)
        out.append(int(prev))
    return np.array(out)


def irregular(n, seed, rate_hz=10.0):
    rng = np.random.default_rng(seed)
    t = np.cumsum(rng.uniform(0.2, 1.8, n) / rate_hz) + 1000.0
    return t, rng


# --- Algorithm 1 -------------------------------------------------------------


def test_derivative_matches_reference_on_irregular_streams():
    for seed in range(4):
        t, rng = irregular(300, seed)
        v = np.cumsum(rng.normal(0, 0.1, len(t))) + 50.0 * np.sin(0.05 * t)
        for w in (0.05, 0.35, 1.0, 3.0):
            np.testing.assert_allclose(derivative(t, v, w), ref_derivative(t, v, w), rtol=1e-9, atol=1e-9)


def test_window_truncated_at_start():
    t = np.array([0.0, 0.1, 0.2, 0.3, 0.4, 0.5])
    v = np.array([0.0, 1.0, 4.0, 9.0, 16.0, 25.0])
    r = derivative(t, v, 0.25)
    assert r[0] == 0.0  # one sample -> slope 0
    assert r[1] == pytest.approx(10.0)  # two samples: (1 - 0) / 0.1
    assert r[2] == pytest.approx(20.0)  # [0, 0.2]: fit of 0, 1, 4
    assert r[5] == pytest.approx(80.0)  # [0.3, 0.5]: fit of 9, 16, 25
    # a window holding one sample after a gap has slope 0 again
    assert derivative(np.array([0.0, 0.1, 5.0]), np.array([0.0, 1.0, 2.0]), 1.0)[2] == 0.0


def test_long_stream_matches_reference_to_1e9():
    """2 h at 10 Hz with a large offset: cumulative sums must not cancel."""
    t, rng = irregular(72_000, 7)
    v = 2000.0 + 0.8 * t + 3.0 * np.sin(0.1 * t) + rng.normal(0, 0.05, len(t))
    for w in (0.5, 2.0):
        r1 = derivative(t, v, w)
        np.testing.assert_allclose(r1, ref_derivative_offsets(t, v, w), rtol=0, atol=1e-9)
        r2 = derivative(t, r1, w)
        np.testing.assert_allclose(r2, ref_derivative_offsets(t, r1, w), rtol=0, atol=1e-9 * np.max(np.abs(r2)))


def test_offset_reference_agrees_with_loop_reference():
    t, rng = irregular(200, 3)
    v = rng.normal(size=len(t))
    np.testing.assert_allclose(ref_derivative_offsets(t, v, 0.7), ref_derivative(t, v, 0.7), atol=1e-12)


def test_angles_unwrapped_across_pi():
    t = np.arange(0.0, 20.0, 0.1)
    yaw_true = 2.5 + 0.3 * t  # crosses +pi at t ~ 2.1 and goes on turning left
    wrapped = np.angle(np.exp(1j * yaw_true))
    r1, r2, _ = trend_derivatives(t, wrapped, 1.0, angular=True)
    np.testing.assert_allclose(r1[10:], 0.3, atol=1e-9)
    raw, _, _ = trend_derivatives(t, wrapped, 1.0, angular=False)
    assert np.min(raw) < -1.0  # without unwrapping the jump shows up as a fast turn right
    est = TrendEstimator(1.0, 0.05, angular=True)
    online = np.array([est.update(a, b).r1 for a, b in zip(t, wrapped)])
    np.testing.assert_allclose(online, r1, atol=1e-9)


def test_rejects_bad_input():
    with pytest.raises(ValidationError, match="increase strictly"):
        derivative(np.array([0.0, 1.0, 1.0]), np.zeros(3), 1.0)
    with pytest.raises(ValidationError, match="finite"):
        derivative(np.array([0.0, 1.0]), np.array([0.0, np.nan]), 1.0)
    with pytest.raises(ValidationError, match="window_s"):
        derivative(np.array([0.0, 1.0]), np.zeros(2), 0.0)


# --- Algorithm 2 -------------------------------------------------------------


def test_known_trends():
    t = np.arange(0.0, 30.0, 0.1)
    v = np.where(t < 10, 0.5 * t, np.where(t < 20, 5.0, 5.0 - 0.5 * (t - 20)))
    s = trends(t, v, 1.0, 0.1).symbol
    assert np.all(s[(t > 1.0) & (t < 10)] == Trend.PLUS)
    assert np.all(s[(t > 12.0) & (t < 20)] == Trend.ZERO)
    assert np.all(s[(t > 22.0)] == Trend.MINUS)


def test_rule_cases():
    b, w = 0.1, 2.0  # dead zones: |r2| <= 0.05, |r3| <= 0.025
    assert qualitative_rule(0.2, 0.0, 0.0, b, w) == Trend.PLUS
    assert qualitative_rule(-0.2, 5.0, 5.0, b, w) == Trend.MINUS
    assert qualitative_rule(0.05, 0.0, 0.0, b, w) == Trend.ZERO  # flat
    assert qualitative_rule(0.05, -1.0, 1.0, b, w) == Trend.ZERO  # settling, braking less
    assert qualitative_rule(0.05, 1.0, 0.0, b, w) == KEEP  # still growing
    assert qualitative_rule(0.05, -1.0, -1.0, b, w) == KEEP  # settling but accelerating away
    assert qualitative_rule(0.1, 1.0, 0.0, b, w) == KEEP  # boundary belongs to the band
    assert qualitative_rule(0.05, 0.04, 1.0, b, w) == Trend.ZERO  # r2 within its dead zone: flat
    assert qualitative_rule(0.05, 0.06, 0.02, b, w) == KEEP  # r2 outside, r3 inside
    assert qualitative_rule(-0.05, 0.06, -0.03, b, w) == Trend.ZERO  # negative slope settling


def test_keep_previous_symbol():
    r1 = np.array([0.05, 0.2, 0.05, 0.05, -0.05, -0.2, -0.05, 0.0])
    r2 = np.array([1.0, 0.0, 1.0, -1.0, -1.0, 0.0, -1.0, 0.0])
    r3 = np.zeros(8)
    s = qualitative_symbols(r1, r2, r3, 0.1, 1.0)
    # start: KEEP with no previous -> 0; growing inside band after + -> keep +;
    # settling -> 0; growing negative -> keep 0; - ; growing -> keep -; flat -> 0
    assert s.tolist() == [0, 1, 1, 0, 0, -1, -1, 0]
    assert s.tolist() == ref_symbols(r1, r2, r3, 0.1, 1.0).tolist()


def test_batch_reference_online_agree_on_random_streams():
    for seed in range(3):
        t, rng = irregular(400, 10 + seed)
        v = np.cumsum(rng.normal(0, 0.05, len(t))) + np.where(t > t[200], 0.3 * (t - t[200]), 0.0)
        w, b = 0.8, 0.15
        batch = trends(t, v, w, b)
        r1 = ref_derivative(t, v, w)
        r2 = ref_derivative(t, r1, w)
        r3 = ref_derivative(t, r2, w)
        np.testing.assert_allclose(batch.r1, r1, atol=1e-9)
        np.testing.assert_allclose(batch.r3, r3, atol=1e-9 * max(1.0, np.max(np.abs(r3))))
        assert np.array_equal(batch.symbol, ref_symbols(r1, r2, r3, b, w))
        assert len(set(batch.symbol.tolist())) == 3  # the test exercises every symbol
        est = TrendEstimator(w, b)
        online = [est.update(a, x) for a, x in zip(t, v)]
        np.testing.assert_allclose([o.r1 for o in online], batch.r1, atol=1e-9)
        np.testing.assert_allclose([o.r2 for o in online], batch.r2, atol=1e-9 * max(1.0, np.max(np.abs(r2))))
        np.testing.assert_allclose([o.r3 for o in online], batch.r3, atol=1e-9 * max(1.0, np.max(np.abs(r3))))
        assert [int(o.symbol) for o in online] == batch.symbol.tolist()


def test_online_rejects_time_going_back():
    est = TrendEstimator(1.0, 0.1)
    est.update(1.0, 0.0)
    with pytest.raises(ValidationError, match="does not follow"):
        est.update(1.0, 0.0)
