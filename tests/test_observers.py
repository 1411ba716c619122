"""Observers (Algorithm 3), unary checks, and the validation streams."""

from __future__ import annotations

import numpy as np
import pytest

from slam.recording import Compass, Gps, Gyro, MagneticReference, Recording, Trajectory
from tests.synthetic import field_body, yaw_scenario
from validation.diagnosis.model import Observation, Plausibility
from validation.base.errors import ValidationError
from validation.observers import (
    DEFAULT_RELATIONS,
    GpsQualityCheck,
    MagnetometerCheck,
    MismatchCounter,
    ObserverBank,
    excise_spans,
    ObserversConfig,
    RelationConfig,
    evidence,
    load_observers_config,
    observe,
    observe_steps,
    run_observers,
    unary_checks,
)
from validation.streams import Stream, fixed_rate_steps, resample, resample_streams, validation_streams

YAW_RELATION = DEFAULT_RELATIONS[0]  # compass_yaw ~ gyro_yaw


# --- Algorithm 3 ----------------------------------------------------------------


def test_counter_by_hand():
    a = [0, 0, 1, 1, 1, 0, 0, 0, -1, -1]
    b = [0, 1, 1, 0, 0, 0, 1, 0, -1, 1]
    # mismatch:  .  x  .  x  x  .  x  .  .  x
    counter, no_match = observe(np.array(a), np.array(b), threshold=1)
    assert counter.tolist() == [0, 1, 0, 1, 2, 1, 2, 1, 0, 1]
    assert no_match.tolist() == [False] * 4 + [True, False, True] + [False] * 3
    online = MismatchCounter(1)
    obs = [online.update(x, y) for x, y in zip(a, b)]
    assert [o is Observation.NO_MATCH for o in obs] == no_match.tolist()


def test_invalid_steps_hold_the_counter():
    a = np.array([1, 1, 1, 0, 0, 0])
    b = np.array([0, 0, 0, 0, 0, 0])
    valid = np.array([True, True, False, False, True, True])
    counter, no_match = observe(a, b, 0, valid)
    assert counter.tolist() == [1, 2, 2, 2, 1, 0]
    assert no_match.tolist() == [True, True, False, False, True, False]  # no observation when invalid
    online = MismatchCounter(0)
    assert [online.update(x, y, v) for x, y, v in zip(a, b, valid)][2] is None


def test_threshold_is_strict():
    c = MismatchCounter(3)
    obs = [c.update(1, 0) for _ in range(4)]
    assert [c_ is Observation.NO_MATCH for c_ in obs] == [False, False, False, True]  # 3 is not > 3
    counter, no_match = observe(np.ones(4, int), np.zeros(4, int), 3)
    assert counter.tolist() == [1, 2, 3, 4] and no_match.tolist() == [False, False, False, True]


def test_counter_cap():
    a = np.array([1] * 10 + [0] * 5)
    counter, no_match = observe(a, np.zeros(15, int), 2, max_counter=4)
    assert counter.tolist() == [1, 2, 3, 4, 4, 4, 4, 4, 4, 4, 3, 2, 1, 0, 0]
    assert not no_match[12]


# --- configuration ------------------------------------------------------------------


def test_relations_from_yaml(tmp_path):
    path = tmp_path / "observers.yaml"
    path.write_text(
        "relations:\n"
        "  - {name: yaw_gyro_sm, stream_a: gyro_yaw, stream_b: sm_yaw,\n"
        "     boundary: 0.04, window_s: 1.5, threshold: 3}\n"
        "  - {name: dist, stream_a: odo_distance, stream_b: sm_distance, boundary: 0.1,\n"
        "     boundary_b: 0.2, window_s: 2, threshold: 4}\n"
        "magnetometer: {enabled: false}\n"
    )
    cfg = load_observers_config(path)
    assert [r.name for r in cfg.relations] == ["yaw_gyro_sm", "dist"]
    assert cfg.relations[0].components == ("IMU_GYRO", "SM_YAW")
    assert cfg.relations[1].boundaries == (0.1, 0.2)
    assert [c.name for c in unary_checks(cfg)] == ["gps_plausible"]

    rel = "{name: r, stream_a: gyro_yaw, stream_b: sm_yaw, boundary: 0.1, windw_s: 1, threshold: 1}"
    path.write_text(f"relations:\n  - {rel}\n")
    with pytest.raises(ValidationError, match="unknown key 'relations.0.windw_s'"):
        load_observers_config(path)
    rel = "{name: r, stream_a: gyro, stream_b: sm_yaw, boundary: 0.1, window_s: 1, threshold: 1}"
    path.write_text(f"relations:\n  - {rel}\n")
    with pytest.raises(ValidationError, match="relations.0.stream_a"):
        load_observers_config(path)


def test_default_relations_cover_the_paper():
    pairs = {frozenset(r.components) for r in ObserversConfig().relations}
    assert {frozenset(p) for p in [("IMU_YAW", "IMU_GYRO"), ("IMU_YAW", "SM_YAW"), ("IMU_GYRO", "SM_YAW")]} <= pairs


# --- streams ---------------------------------------------------------------------------


def small_recording():
    t = np.arange(0.0, 10.001, 0.1)
    odo = Trajectory(t, 0.5 * t, np.zeros_like(t), np.full_like(t, 0.2))
    gyro = Gyro(t, np.full_like(t, 0.1))
    tg = np.arange(0.0, 10.001, 1.0)
    gps = Gps(tg, 2.0 * tg, np.zeros_like(tg), np.full_like(tg, 1.0), np.zeros(len(tg), int))
    return Recording("small", gyro=gyro, odometry=odo, gps=gps)


def test_validation_streams_from_recording():
    rec = small_recording()
    sm = Trajectory(rec.odometry.t[::2], rec.odometry.x[::2] * 2, rec.odometry.y[::2], rec.odometry.yaw[::2])
    s = validation_streams(rec, sm)
    assert set(s) == {
        "gyro_yaw", "odo_yaw", "odo_distance", "odo_forward", "odo_lateral", "odo_speed",
        "sm_yaw", "sm_distance", "sm_forward", "sm_lateral", "sm_speed", "sm_fix_speed", "gps_speed", "gps_sigma",
        "odo_fix_speed", "gps_course",
    }
    np.testing.assert_allclose(s["sm_speed"].values, 1.0, atol=1e-9)
    np.testing.assert_allclose(s["gyro_yaw"].values, 0.1 * rec.gyro.t, atol=1e-12)
    np.testing.assert_allclose(s["odo_distance"].values, 0.5 * rec.odometry.t, atol=1e-12)
    np.testing.assert_allclose(s["odo_speed"].values, 0.5, atol=1e-9)
    np.testing.assert_allclose(s["sm_distance"].values[-1], 10.0, atol=1e-9)
    # Regression slope over the trailing window; the first fix has no slope.
    np.testing.assert_allclose(s["gps_speed"].values[1:], 2.0, atol=1e-9)
    np.testing.assert_allclose(s["gps_speed"].t, np.arange(0.0, 10.001, 1.0))
    # Heading 0.2 rad while moving along +x: each step is partly sideways.
    np.testing.assert_allclose(s["odo_lateral"].values[-1], -np.sin(0.2) * 5.0, atol=1e-9)
    np.testing.assert_allclose(s["odo_forward"].values[-1], np.cos(0.2) * 5.0, atol=1e-9)
    assert s["odo_yaw"].angular and not s["odo_distance"].angular


def test_odometry_speed_derived_as_gps_speed_lags_alike():
    # The robot drives at 1 m/s and stops at 20 s; GPS and odometry see the
    # same path. GPS speed over a trailing 8 s window reports the stop
    # seconds late, the odometry's derivative at once, the odometry's speed
    # through the GPS's regression exactly as late as the GPS.
    t = np.arange(0.0, 40.001, 0.1)
    x = np.minimum(t, 20.0)
    odo = Trajectory(t, x, np.zeros_like(t), np.zeros_like(t))
    tg = t[::4]
    gps = Gps(tg, x[::4], np.zeros_like(tg), np.ones_like(tg), np.zeros(len(tg), int))
    s = validation_streams(Recording("stop", odometry=odo, gps=gps), gps_speed_window_s=8.0, window="trailing")
    at = lambda name, when: float(np.interp(when, s[name].t, s[name].values))  # noqa: E731
    assert at("odo_speed", 22.0) == pytest.approx(0.0, abs=1e-9)
    assert at("gps_speed", 22.0) > 0.5
    for when in (10.0, 21.0, 22.0, 24.0, 26.0, 30.0):
        assert at("odo_fix_speed", when) == pytest.approx(at("gps_speed", when), abs=0.02)
    centred = validation_streams(Recording("stop", odometry=odo, gps=gps), gps_speed_window_s=8.0, window="centred")
    assert float(np.interp(18.0, centred["odo_fix_speed"].t, centred["odo_fix_speed"].values)) < 0.95


def test_resample_validity_and_angles():
    t = np.array([0.0, 1.0, 2.0, 5.0, 6.0])
    yaw = np.array([3.0, 3.1, -3.1, -3.0, -2.9])  # crosses +pi between 1 and 2 s
    step = np.array([-0.5, 0.0, 1.5, 3.0, 5.5, 6.0, 6.5])
    v, ok = resample(Stream(t, yaw, angular=True), step, max_gap_s=1.0)
    assert ok.tolist() == [False, True, True, False, True, True, False]
    assert v[2] == pytest.approx(0.5 * (3.1 + (2 * np.pi - 3.1)))  # through pi, not through 0
    assert v[4] == pytest.approx(-2.95 + 2 * np.pi)
    assert np.isnan(v[3])


# --- relation observers on streams ----------------------------------------------------------


def test_absent_stream_makes_no_observation():
    sc = yaw_scenario(duration_s=30.0, compass_drift=None)
    gps_rel = DEFAULT_RELATIONS[-1]
    log = run_observers(sc.streams, [YAW_RELATION, gps_rel], sc.step_t, rule="project")
    assert not log.relations[gps_rel.name].valid.any()
    warm = sc.step_t >= YAW_RELATION.warmup
    assert np.array_equal(log.relations[YAW_RELATION.name].valid, warm)
    assert gps_rel.name not in log.observations(100)
    assert log.observations(100)[YAW_RELATION.name] is Observation.MATCH


def test_patterns_give_every_steps_observations():
    """Diagnosis runs once per distinct pattern: the patterns and the index
    must give back each step's observations, with and without data."""
    sc = yaw_scenario(duration_s=120.0, compass_drift=(40.0, 70.0), seed=3)
    log = run_observers(sc.streams, [YAW_RELATION, DEFAULT_RELATIONS[-1]], sc.step_t, rule="project")
    patterns, index = log.patterns()
    assert len(index) == len(sc.step_t)
    assert len(patterns) == len({frozenset(p.items()) for p in patterns}) >= 3  # no data, match, no_match
    for k in range(len(sc.step_t)):
        assert patterns[index[k]] == log.observations(k)


def test_gap_in_a_stream_invalidates_its_steps():
    sc = yaw_scenario(duration_s=40.0, compass_drift=None)
    c = sc.streams["compass_yaw"]
    keep = (c.t < 10.0) | (c.t > 15.0)
    streams = dict(sc.streams, compass_yaw=Stream(c.t[keep], c.values[keep], True))
    log = run_observers(streams, [YAW_RELATION], sc.step_t, rule="project")
    trace = log.relations[YAW_RELATION.name]
    in_gap = (sc.step_t > 10.1) & (sc.step_t < 14.9)
    assert not trace.valid[in_gap].any()
    assert not trace.valid[(sc.step_t > 15.1) & (sc.step_t < 15.0 + YAW_RELATION.warmup)].any()
    assert trace.valid[(sc.step_t > 15.1 + YAW_RELATION.warmup) & (sc.step_t < 39.0)].all()
    assert trace.counter[in_gap].tolist() == [trace.counter[np.flatnonzero(in_gap)[0] - 1]] * int(in_gap.sum())


def onset_and_clear(t, flag, after):
    on = t[flag & (t >= after)]
    first = on[0]
    off = t[(~flag) & (t > first)]
    return first, off[0]


def test_compass_drift_raises_no_match_and_clears():
    sc = yaw_scenario(duration_s=260.0)
    step = 1.0 / 10.0
    log = run_observers(sc.streams, [YAW_RELATION, DEFAULT_RELATIONS[2]], sc.step_t, rule="project")
    trace = log.relations[YAW_RELATION.name]
    # No false alarm before the fault, through the turns at 20-50 s.
    assert not trace.no_match[sc.step_t < 70.0].any()
    first, cleared = onset_and_clear(sc.step_t, trace.no_match, 70.0)
    # Onset: the compass slope must cross b within the window, then th + 1 mismatches.
    assert 70.0 < first <= 70.0 + YAW_RELATION.window_s + (YAW_RELATION.threshold + 1) * step + 0.5
    # The paper's counter is unbounded: ~800 mismatching steps take ~800 steps to count down.
    assert 150.0 + 70.0 < cleared < 150.0 + 90.0
    # gyro ~ sm never disagrees.
    assert not log.relations["yaw_gyro_sm"].no_match.any()

    capped = YAW_RELATION.model_copy(update={"max_counter": 20})
    trace = run_observers(sc.streams, [capped], sc.step_t, rule="project").relations[capped.name]
    first, cleared = onset_and_clear(sc.step_t, trace.no_match, 70.0)
    assert 150.0 < cleared < 150.0 + YAW_RELATION.window_s + 20 * step + 1.0
    assert not trace.no_match[sc.step_t > cleared].any()


# --- unary checks --------------------------------------------------------------------------


def mag_recording(disturb: tuple[float, float], extra_T: float, extra_dip: float = 0.0):
    ref = MagneticReference(strength_T=48e-6, dip_rad=np.radians(65.0))
    t = np.arange(0.0, 100.0, 0.05)
    yaw = 0.02 * t
    bad = (t >= disturb[0]) & (t < disturb[1])
    strength = np.where(bad, ref.strength_T + extra_T, ref.strength_T)
    dip = np.where(bad, ref.dip_rad + extra_dip, ref.dip_rad)
    return Recording("mag", compass=Compass(t, yaw, field_body(yaw, strength, dip)), magnetic_reference=ref)


def test_magnetometer_check_flags_a_disturbed_field_only():
    cfg = ObserversConfig(relations=())
    step_t = np.arange(0.0, 99.0, 0.1)
    rec = mag_recording((40.0, 60.0), extra_T=20e-6)
    checks = unary_checks(cfg, rec.magnetic_reference)
    log = run_observers(validation_streams(rec), [], step_t, checks)
    u = log.unary["mag_plausible"]
    assert u.component == "IMU_YAW" and u.valid.all()
    hold = cfg.magnetometer.hold_s
    expect = (step_t >= 40.0 + hold - 1e-6) & (step_t < 60.0 - 0.05)
    away = np.abs(step_t - 40.0 - hold) > 0.06  # the onset step may round either way
    assert np.array_equal(u.implausible[away], expect[away])
    assert log.observations(10)["mag_plausible"] is Plausibility.PLAUSIBLE

    # The reference field itself is plausible; so is the heading's own change.
    clean = mag_recording((0.0, 0.0), extra_T=0.0)
    assert not run_observers(validation_streams(clean), [], step_t, checks).unary["mag_plausible"].implausible.any()
    # A dip change alone is caught.
    dip = mag_recording((40.0, 60.0), extra_T=0.0, extra_dip=np.radians(10.0))
    assert run_observers(validation_streams(dip), [], step_t, checks).unary["mag_plausible"].implausible.sum() > 150


def test_gps_quality_check():
    check = GpsQualityCheck("gps_plausible", "GPS", max_sigma_m=3.0, hold_s=0.0)
    tg = np.arange(0.0, 20.0, 1.0)
    sigma = np.where((tg >= 8) & (tg <= 12), 10.0, 1.0)
    status = np.where(tg == 15, -1, 0)
    rec = Recording("g", gps=Gps(tg, tg, tg, sigma, status))
    cfg = ObserversConfig()
    step_t = np.arange(0.0, 19.0, 0.5)
    log = run_observers(validation_streams(rec), [], step_t, [check], cfg.max_gap_s, cfg.stream_max_gap_s)
    u = log.unary["gps_plausible"]
    assert u.implausible[(step_t >= 8) & (step_t <= 12)].all()
    assert not u.implausible[(step_t <= 7) | (step_t >= 13)].any()
    assert u.valid.all()  # the dropped fix leaves a 2 s gap, within the 2.5 s allowed


# --- batch == online ------------------------------------------------------------------------


@pytest.mark.slow
@pytest.mark.parametrize("rule", ["paper", "project"])
def test_batch_and_online_agree(rule):
    sc = yaw_scenario(duration_s=120.0, compass_drift=(40.0, 70.0), seed=3)
    c = sc.streams["compass_yaw"]
    keep = (c.t < 80.0) | (c.t > 83.0)  # a gap in the middle
    streams = dict(sc.streams, compass_yaw=Stream(c.t[keep], c.values[keep], True))
    ref = MagneticReference(50e-6, np.radians(60.0))
    field = np.repeat(field_body(np.zeros(1), ref.strength_T, ref.dip_rad), len(c.t), axis=0)
    field[(c.t > 50) & (c.t < 55), 0] += 30e-6
    mag = validation_streams(Recording("m", compass=Compass(c.t, c.values, field)))
    streams.update(mag_strength=mag["mag_strength"], mag_dip=mag["mag_dip"])
    relations = [
        *DEFAULT_RELATIONS[:3],
        DEFAULT_RELATIONS[0].model_copy(update={"name": "capped", "max_counter": 12, "boundary_b": 0.03}),
        RelationConfig(name="res", kind="residual", stream_a="gyro_yaw", stream_b="compass_yaw",
                       window_s=2.0, sigma_floor=0.03, threshold=3, max_counter=10),
        RelationConfig(name="off", kind="offset", stream_a="gyro_yaw", stream_b="compass_yaw",
                       window_s=2.0, sigma_floor=0.02, level_window_s=20.0, threshold=3, max_counter=10),
        RelationConfig(name="cus", kind="cusum", stream_a="gyro_yaw", stream_b="compass_yaw",
                       window_s=2.0, sigma_floor=0.03, k_sigma=20.0, threshold=2, max_counter=10),
        RelationConfig(name="held", kind="offset", stream_a="gyro_yaw", stream_b="compass_yaw", window_s=2.0,
                       sigma_floor=0.02, level_window_s=20.0, level_max_rate=0.002, threshold=3, max_counter=10),
        DEFAULT_RELATIONS[0].model_copy(update={"name": "margin", "mismatch_margin": 1.0, "threshold": 3}),
        RelationConfig(name="travel", kind="residual", stream_a="gyro_yaw", stream_b="compass_yaw", window_s=30.0,
                       window_travel=0.3, sigma_floor=0.03, threshold=3, max_counter=10),
    ]
    checks = [MagnetometerCheck("mag", "IMU_YAW", ref.strength_T, ref.dip_rad, 5e-6, 0.1, 1.0)]

    steps = resample_streams(streams, sc.step_t)
    log = observe_steps(steps, relations, checks, "trailing", rule)
    bank = ObserverBank(relations, checks, steps.angular, rule)
    for k, t in enumerate(steps.t):
        out = bank.update(t, {n: v[k] for n, v in steps.values.items()})
        for r in relations:
            tr = log.relations[r.name]
            assert out.counters[r.name] == tr.counter[k], (r.name, t)
            assert out.symbols[r.name] == (tr.symbol_a[k], tr.symbol_b[k])
            assert out.observations[r.name] == tr.observation(k)
        assert out.observations["mag"] == log.unary["mag"].plausibility(k)
    assert log.relations["capped"].no_match.any() and log.unary["mag"].implausible.any()
    assert log.relations["res"].no_match.any() and log.relations["off"].no_match.any()
    assert log.relations["cus"].no_match.any() and log.relations["held"].no_match.any()
    assert log.relations["margin"].no_match.any() and log.relations["travel"].no_match.any()
    cols = log.columns()
    assert cols["capped.counter"] is log.relations["capped"].counter and len(cols["t"]) == len(steps.t)


def test_fixed_rate_steps():
    np.testing.assert_allclose(fixed_rate_steps(1.0, 2.0, 10.0), np.linspace(1.0, 2.0, 11))
    with pytest.raises(ValidationError):
        fixed_rate_steps(0.0, 1.0, 0.0)


# --- offline: alarms dated by their evidence ----------------------------------------------


def test_evidence_dates_an_alarm_from_its_first_to_its_last_mismatch():
    a = np.array([0, 0, 1, 1, 1, 1, 0, 1, 1, 0, 0, 0, 0, 0, 1, 0, 0])
    b = np.zeros(17, int)
    valid = np.ones(17, bool)
    counter, no_match = observe(a, b, 2, valid)
    # counter:  0 0 1 2 3 4 3 4 5 4 3 2 1 0 1 0 0 ; alarm where > 2: steps 4-10
    assert counter.tolist() == [0, 0, 1, 2, 3, 4, 3, 4, 5, 4, 3, 2, 1, 0, 1, 0, 0]
    dated = evidence(a, b, 2, valid)
    # from the first mismatch of the climb (step 2) to its last (step 8); the
    # lone mismatch at 14 never raised an alarm
    assert np.flatnonzero(dated).tolist() == list(range(2, 9))
    # Mismatches while the counter drains do not extend the alarm: run
    # backward, the counter climbs only from the alarm's last dense mismatch.
    a = np.array([1] * 8 + [0, 0, 1, 0, 0, 1, 0, 0, 0, 0, 0, 0])
    b = np.zeros(len(a), int)
    counter, _ = observe(a, b, 3, np.ones(len(a), bool))
    assert counter[13] > 0  # still draining at the noise mismatch at 13
    assert np.flatnonzero(evidence(a, b, 3, np.ones(len(a), bool))).tolist() == list(range(0, 8))


def test_offline_observer_has_no_delay_and_no_drain():
    sc = yaw_scenario(duration_s=260.0)  # the compass drifts from 70 s to 150 s
    causal = run_observers(sc.streams, [YAW_RELATION], sc.step_t, window="trailing", rule="project")
    offline = run_observers(sc.streams, [YAW_RELATION], sc.step_t, window="centred", rule="project", offline=True)
    c, o = causal.relations[YAW_RELATION.name].no_match, offline.relations[YAW_RELATION.name].no_match
    first_c, cleared_c = onset_and_clear(sc.step_t, c, 60.0)
    first_o, cleared_o = onset_and_clear(sc.step_t, o, 60.0)
    assert first_o < first_c - 1.0 and abs(first_o - 70.0) < 1.5
    assert cleared_o < cleared_c - 60.0 and abs(cleared_o - 150.0) < 2.0


def test_offline_unary_check_flags_the_whole_deviation():
    cfg = ObserversConfig(relations=())
    step_t = np.arange(0.0, 99.0, 0.1)
    rec = mag_recording((40.0, 60.0), extra_T=20e-6)
    checks = unary_checks(cfg, rec.magnetic_reference)
    u = run_observers(validation_streams(rec), [], step_t, checks, offline=True).unary["mag_plausible"]
    assert np.array_equal(u.implausible[np.abs(step_t - 40.0) > 0.06], ((step_t >= 40.0) & (step_t < 59.95))[np.abs(step_t - 40.0) > 0.06])


# --- quantitative (residual) observers -------------------------------------------------------


def test_residual_observer_sees_a_wrong_size_that_trends_miss():
    t = np.arange(0.0, 60.0, 0.1)
    odo = 0.4 * t  # odometry distance, 0.4 m/s
    sm = np.where(t < 20, 0.4 * t, np.where(t < 40, 8.0 + 4.0 * (t - 20), 88.0 + 0.4 * (t - 40)))  # 10x too fast
    streams = {"odo_distance": Stream(t, odo), "sm_distance": Stream(t, sm)}
    trend = RelationConfig(name="trend", stream_a="odo_distance", stream_b="sm_distance", boundary=0.1,
                           window_s=2.0, threshold=5)
    res = RelationConfig(name="res", kind="residual", stream_a="odo_distance", stream_b="sm_distance",
                         window_s=2.0, sigma_floor=0.05, sigma_rel=0.05, threshold=5)
    log = run_observers(streams, [trend, res], t, window="centred", offline=True)
    assert not log.relations["trend"].no_match.any()  # both '+' all along
    flagged = t[log.relations["res"].no_match]
    assert 18.5 < flagged[0] < 20.0 and 40.0 < flagged[-1] < 41.5
    assert log.relations["res"].no_match[(t > 20.5) & (t < 39.5)].all()
    z = log.relations["res"].z
    assert np.all(np.abs(z[(t > 3) & (t < 18)]) < 1e-9)  # exact agreement outside


def test_travel_window_sees_a_slip_at_every_speed():
    """Wheels that slip (the odometry 1.5 times the motion) from 60 to 120 s,
    the robot crawling at 0.05 m/s, then driving at 1 m/s, with stops between.
    A window of 2 s sees the crawl's error of 5 cm no better than its noise
    floor; a window of 2 m of travel sees the same 33 % at both speeds, and
    nothing where the robot stands or the odometry is right."""
    t = np.arange(0.0, 180.0, 0.1)
    speed = np.select([t < 20, t < 40, t < 60, t < 90, t < 100, t < 120, t < 140], [0.5, 0.0, 0.05, 0.05, 0.0, 1.0, 0.05], 0.5)
    true = np.concatenate(([0.0], np.cumsum(speed[:-1] * 0.1)))
    slip = (t >= 60) & (t < 120)
    odo = np.concatenate(([0.0], np.cumsum(np.where(slip, 1.5, 1.0)[:-1] * speed[:-1] * 0.1)))
    streams = {"odo_distance": Stream(t, odo), "sm_distance": Stream(t, true)}
    common = dict(kind="residual", stream_a="odo_distance", stream_b="sm_distance", sigma_floor=0.05,
                  sigma_rel=0.1, k_sigma=2.5, threshold=3, max_counter=10)
    timed = RelationConfig(name="timed", window_s=2.0, **common)
    travel = RelationConfig(name="travel", window_s=60.0, window_travel=2.0, **common)
    for window, offline in (("centred", True), ("trailing", False)):
        log = run_observers(streams, [timed, travel], t, window=window, offline=offline)
        crawl, fast = (t > 85) & (t < 90), (t > 105) & (t < 119)
        assert not log.relations["timed"].no_match[crawl].any()
        assert log.relations["travel"].no_match[crawl].all() and log.relations["travel"].no_match[fast].all()
        right = (t < 50) | (t > 170)  # a trailing window holds the slip for 2 m after it
        assert not log.relations["travel"].no_match[right].any()


def test_travel_window_only_where_it_means_travel():
    for bad, match in ((dict(kind="trend", boundary=0.1), "window_travel"),
                       (dict(kind="residual", sigma_floor=0.05, rate_offset=0.1), "rate_offset")):
        with pytest.raises(ValueError, match=match):
            RelationConfig(name="r", stream_a="odo_distance", stream_b="sm_distance", window_s=30.0,
                           window_travel=2.0, threshold=3, **bad)


def test_residual_config_needs_its_noise():
    with pytest.raises(ValueError, match="sigma_floor"):
        RelationConfig(name="r", kind="residual", stream_a="odo_distance", stream_b="sm_distance",
                       window_s=2.0, threshold=1)
    with pytest.raises(ValueError, match="boundary"):
        RelationConfig(name="r", stream_a="odo_distance", stream_b="sm_distance", window_s=2.0, threshold=1)


def test_offset_observer_sees_a_standing_offset_that_changes_miss():
    """A compass that steps 0.1 rad off for 30 s and back: its changes agree
    with the gyro's but at the two steps; its offset does not, throughout."""
    t = np.arange(0.0, 120.0, 0.1)
    gyro = 0.002 * t  # a slow bias drift
    compass = gyro + np.where((t >= 50) & (t < 80), 0.1, 0.0)
    streams = {"gyro_yaw": Stream(t, gyro), "compass_yaw": Stream(t, compass, angular=True)}
    res = RelationConfig(name="res", kind="residual", stream_a="gyro_yaw", stream_b="compass_yaw",
                         window_s=2.0, sigma_floor=0.03, threshold=5)
    off = RelationConfig(name="off", kind="offset", stream_a="gyro_yaw", stream_b="compass_yaw",
                         window_s=2.0, sigma_floor=0.01, level_window_s=90.0, threshold=5)
    log = run_observers(streams, [res, off], t, window="centred", offline=True)
    inside = (t > 51) & (t < 79)
    assert log.relations["res"].no_match[inside].mean() < 0.2  # only around the steps
    assert log.relations["off"].no_match[inside].all()
    assert not log.relations["off"].no_match[(t < 49) | (t > 81)].any()


@pytest.mark.parametrize("offline", [True, False])
def test_held_level_keeps_seeing_an_offset_that_stands(offline):
    """A compass that walks 0.5 rad off over 10 s and stays there: a level
    held to the gyro's drift keeps seeing it, in either pass, and follows
    the gyro's own slow drift; the offline pass's free level moves onto the
    offset within its window."""
    t = np.arange(0.0, 300.0, 0.1)
    gyro = 0.0002 * t  # a bias drift below the hold
    compass = gyro + np.clip((t - 100.0) / 10.0, 0.0, 1.0) * 0.5
    streams = {"gyro_yaw": Stream(t, gyro), "compass_yaw": Stream(t, compass, angular=True)}
    common = dict(kind="offset", stream_a="gyro_yaw", stream_b="compass_yaw", window_s=2.0, sigma_floor=0.02,
                  level_window_s=60.0, threshold=3)
    free = RelationConfig(name="free", **common)
    held = RelationConfig(name="held", level_max_rate=0.001, **common)
    log = run_observers(streams, [free, held], t, window="centred" if offline else "trailing", offline=offline)
    before, standing = t < 100.0, t > 115.0
    assert not log.relations["held"].no_match[before].any()
    assert log.relations["held"].no_match[standing].all()
    if offline:
        assert not log.relations["free"].no_match[t > 200.0].any()


def test_held_level_only_on_offset_relations_with_a_level():
    for bad in (dict(kind="residual"), dict(kind="offset", level_window_s=None)):
        with pytest.raises(ValueError, match="level_max_rate"):
            RelationConfig(name="r", stream_a="gyro_yaw", stream_b="compass_yaw", window_s=2.0, sigma_floor=0.02,
                           level_max_rate=0.001, threshold=3, **bad)


def test_cusum_observer_sees_a_standing_error_below_the_residual_band():
    """A scan matcher 6 % short for 30 s: each window's residual is 0.5 sd,
    under any residual band; the CUSUM adds it up and sees it within a few
    seconds, and lets go once it ends."""
    rng = np.random.default_rng(4)
    t = np.arange(0.0, 120.0, 0.1)
    odo = 0.4 * t
    scale = np.where((t >= 50) & (t < 80), 0.94, 1.0)
    sm = np.concatenate(([0.0], np.cumsum(np.diff(odo) * scale[1:]))) + rng.normal(0.0, 0.01, len(t))
    streams = {"odo_distance": Stream(t, odo), "sm_distance": Stream(t, sm)}
    common = dict(stream_a="odo_distance", stream_b="sm_distance", window_s=2.0, sigma_floor=0.1, threshold=1,
                  max_counter=5)
    res = RelationConfig(name="res", kind="residual", k_sigma=3.0, **common)
    cus = RelationConfig(name="cus", kind="cusum", k_sigma=10.0, cusum_drift=0.25, **common)
    log = run_observers(streams, [res, cus], t, window="trailing")
    inside, outside = (t > 56) & (t < 80), (t < 50) | (t > 88)
    assert not log.relations["res"].no_match.any()
    assert log.relations["cus"].no_match[inside].all()
    assert not log.relations["cus"].no_match[outside].any()
    first = t[log.relations["cus"].no_match][0]
    assert 50.0 < first < 56.0


def test_cusum_starts_again_after_a_gap():
    from validation.observers.sequential import cusum

    z = np.full(10, 2.0)
    valid = np.ones(10, dtype=bool)
    valid[4] = False
    stat, mismatch = cusum(z, valid, drift=0.5, limit=4.0)
    np.testing.assert_allclose(stat, [1.5, 3.0, 4.5, 6.0, 0.0, 1.5, 3.0, 4.5, 6.0, 7.5])
    assert mismatch.tolist() == [False, False, True, True, False, False, False, True, True, True]
    stat, _ = cusum(np.concatenate([z, -np.ones(3)]), np.ones(13, dtype=bool), drift=0.5, limit=4.0)
    np.testing.assert_allclose(stat[8:], [8.0, 8.0, 6.5, 5.0, 3.5])  # capped at twice the limit


@pytest.mark.parametrize("offline", [True, False])
def test_mismatch_margin_ignores_slopes_that_straddle_the_boundary(offline):
    """Gyro turning at 0.9 b and compass at 1.1 b: their symbols are 0 and
    +, a mismatch at every step for the paper's comparison, though the two
    agree to a fifth of b. With a margin of 1 b they match; a compass that
    turns 3 b faster for 10 s is flagged either way."""
    b = 0.05
    t = np.arange(0.0, 100.0, 0.1)
    gyro = 0.9 * b * t
    compass = 1.1 * b * t + 3.0 * b * np.clip(t - 50.0, 0.0, 10.0)
    streams = {"gyro_yaw": Stream(t, gyro), "compass_yaw": Stream(t, compass, angular=True)}
    common = dict(stream_a="compass_yaw", stream_b="gyro_yaw", boundary=b, window_s=2.0, threshold=5, max_counter=25)
    paper = RelationConfig(name="paper", **common)
    margin = RelationConfig(name="margin", mismatch_margin=1.0, **common)
    log = run_observers(streams, [paper, margin], t, window="centred" if offline else "trailing", offline=offline)
    agree = ((t > 10.0) & (t < 48.0)) | (t > 66.0)
    assert log.relations["paper"].no_match[agree].mean() > 0.95
    assert not log.relations["margin"].no_match[agree].any()
    apart = (t > 53.0) & (t < 59.0)
    assert log.relations["margin"].no_match[apart].all() and log.relations["paper"].no_match[apart].all()
    trace = log.relations["margin"]
    assert set(np.unique(trace.symbol_b[agree])) == {0}  # the log keeps the symbols as abstracted


def test_mismatch_margin_only_on_trend_relations():
    with pytest.raises(ValueError, match="mismatch_margin"):
        RelationConfig(name="r", kind="residual", stream_a="gyro_yaw", stream_b="compass_yaw", window_s=2.0,
                       sigma_floor=0.02, mismatch_margin=1.0, threshold=3)


def test_excise_spans_takes_out_the_change_over_each_span_from_its_end_on():
    d = np.array([0.0, 0.0, 1.0, 2.0, 3.0, 3.0, 3.0, 5.0, 5.0])
    valid = np.ones(len(d), dtype=bool)
    # Over steps 1-4 the difference rose by 3: gone from step 4 on; the later
    # change (step 7) stays.
    np.testing.assert_array_equal(excise_spans(d, valid, [(1, 4)]), [0, 0, 1, 2, 0, 0, 0, 2, 2])
    # Spans add up in time order; an end without data leaves the span alone.
    np.testing.assert_array_equal(excise_spans(d, valid, [(1, 4), (6, 7)]), [0, 0, 1, 2, 0, 0, 0, 0, 0])
    gap = valid.copy()
    gap[4] = False
    np.testing.assert_array_equal(excise_spans(d, gap, [(1, 4)]), d)
