"""Validation of one run: look-back, per-keyframe weights, and
``run_validation`` on a synthetic recording whose compass drifts away."""

from __future__ import annotations

import csv
import io
import math
from pathlib import Path

import numpy as np
import pytest

from slam.config import load_config, validation_sections
from validation.base.geometry import wrap_angle
from slam.graph.measurements import FACTOR_DOFS
from slam.recording import Compass, Gyro, MagneticReference, Recording, Trajectory
from tests.synthetic import DEFAULT_TURNS, bump_error, field_body, sample_times, true_yaw, yaw_rate
from validation.diagnosis.model import Observation
from validation.diagnosis.reiter import Diagnoser
from validation.gating import GatingAction, GatingConfig
from validation.streams import fixed_rate_steps
from validation.validator import integrated_fault_spans, keyframe_weights, run_validation, step_scales

INF = math.inf
INC, INFL, EXC = GatingAction.INCLUDE, GatingAction.INFLATE, GatingAction.EXCLUDE
TELEMAX = Path(__file__).resolve().parents[1] / "configs" / "telemax.yaml"
FACTORS = ("compass", "gps", "gyro", "odometry", "scan_matching")
# One component per factor, one degree of freedom each: the step-scale
# tests read like the decisions they check.
SIMPLE = GatingConfig(factors={"compass": ["C"], "gps": ["G"], "gyro": ["Y"]}, inflation=10.0)
SIMPLE_DOFS = {"compass": ("yaw",), "gps": ("x",), "gyro": ("yaw",)}


def actions_from(columns: dict[str, list[GatingAction]]) -> list[dict[str, GatingAction]]:
    """Per-step actions from per-component columns."""
    n = len(next(iter(columns.values())))
    return [{c: col[k] for c, col in columns.items() if col[k] is not INC} for k in range(n)]


def scale_lists(scales: dict[str, np.ndarray]) -> dict[str, list[float]]:
    return {f: s[:, 0].tolist() for f, s in scales.items()}


# --- step_scales ------------------------------------------------------------


# Steps every 0.25 s (exact in binary floating point), so the look-back window
# [t_k - 0.5, t_k) holds exactly the two steps before step k.
STEPS = 0.25 * np.arange(10)
COLUMNS = {
    "C": [INC] * 6 + [EXC] + [INC] * 3,  # step 6 excluded
    # Excluded at step 4, inflated at step 5: the inflation's look-back
    # (steps 3, 4) must not lower the exclusion's (steps 2, 3) - a maximum.
    "G": [INC] * 4 + [EXC, INFL] + [INC] * 4,
    "Y": [INC] * 10,
}


def test_step_scales_without_lookback_are_the_decisions():
    scales = scale_lists(step_scales(STEPS, actions_from(COLUMNS), SIMPLE, SIMPLE_DOFS, 0.0))
    assert sorted(scales) == ["compass", "gps", "gyro"]
    assert scales["compass"] == [1, 1, 1, 1, 1, 1, INF, 1, 1, 1]
    assert scales["gps"] == [1, 1, 1, 1, INF, 10, 1, 1, 1, 1]
    assert scales["gyro"] == [1] * 10


def test_step_scales_lookback_covers_the_preceding_window():
    scales = scale_lists(step_scales(STEPS, actions_from(COLUMNS), SIMPLE, SIMPLE_DOFS, 0.5))
    # compass: step 6 (1.5 s) also gates 1.0 s and 1.25 s, not 0.75 s.
    assert scales["compass"] == [1, 1, 1, 1, INF, INF, INF, 1, 1, 1]
    # gps: exclusion at 1.0 s reaches back to 0.5 s; the inflation at
    # 1.25 s reaches 0.75 s and 1.0 s, which stay excluded (the max).
    assert scales["gps"] == [1, 1, INF, INF, INF, 10, 1, 1, 1, 1]
    assert scales["gyro"] == [1] * 10


def test_step_scales_lookback_is_clipped_at_the_first_step():
    scales = step_scales(0.25 * np.arange(4), actions_from({"C": [INC, EXC, INC, INC]}), SIMPLE, SIMPLE_DOFS, 100.0)
    assert scales["compass"][:, 0].tolist() == [INF, INF, 1, 1]


def test_step_scales_per_degree_of_freedom():
    gating = GatingConfig()
    scales = step_scales(STEPS[:3], [{}, {"SM_DIST": EXC}, {"SM": INFL}], gating, FACTOR_DOFS)
    assert scales["scan_matching"].tolist() == [[1, 1, 1], [INF, 1, 1], [10, 10, 10]]
    assert scales["odometry"].tolist() == [[1, 1, 1]] * 3


def test_step_scales_lookback_boundary_on_a_10hz_grid():
    # On the validator's own 10 Hz steps a 0.2 s look-back is exactly two
    # steps, [t_k - 0.2, t_k), for every k; the left end is inclusive.
    step_t = fixed_rate_steps(0.0, 10.0, 10.0)
    n = len(step_t)
    wrong = []
    for k in range(2, n):
        col = [INC] * n
        col[k] = EXC
        scale = step_scales(step_t, actions_from({"C": col}), SIMPLE, SIMPLE_DOFS, 0.2)["compass"][:, 0]
        if np.flatnonzero(~np.isfinite(scale)).tolist() != [k - 2, k - 1, k]:
            wrong.append(k)
    assert wrong == [], f"look-back did not cover exactly 2 steps for steps {wrong[:10]}"


# --- keyframe_weights ------------------------------------------------------


STEP_T = 0.5 * np.arange(7)  # 0, 0.5, ..., 3.0 s


def col(*values: float) -> np.ndarray:
    """One degree of freedom's scales over the steps, (m, 1)."""
    return np.array(values, dtype=float)[:, None]


def test_keyframe_weights_max_over_steps_since_previous_keyframe():
    scales = {"f": col(1, 10, 1, INF, 1, 1, 10)}
    kf = np.array([0.25, 1.0, 1.5, 2.2, 3.0])
    # kf 0 (0.25 s): last step at or before it, step 0 -> 1
    # kf 1 (1.0 s): steps in (0.25, 1.0] = 0.5, 1.0 -> max(10, 1) = 10
    # kf 2 (1.5 s): (1.0, 1.5] = 1.5 -> inf
    # kf 3 (2.2 s): (1.5, 2.2] = 2.0 -> 1
    # kf 4 (3.0 s): (2.2, 3.0] = 2.5, 3.0 -> 10
    w = keyframe_weights(STEP_T, scales, kf)
    assert w["f"][:, 0].tolist() == [1, 10, INF, 1, 10]


def test_keyframe_weights_step_on_a_keyframe_belongs_to_that_keyframe():
    scales = {"f": col(1, 1, INF, 1, 1, 1, 1)}  # 1.0 s excluded
    w = keyframe_weights(STEP_T, scales, np.array([0.0, 1.0, 1.5]))
    assert w["f"][:, 0].tolist() == [1, INF, 1]


def test_keyframe_zero_takes_the_last_step_at_or_before_it():
    scales = {"f": col(1, 10, 1, 1, 1, 1, 1)}  # 0.5 s inflated
    assert keyframe_weights(STEP_T, scales, np.array([0.5, 1.0]))["f"][:, 0].tolist() == [10, 1]
    assert keyframe_weights(STEP_T, scales, np.array([0.7, 1.0]))["f"][:, 0].tolist() == [10, 1]
    # Before the first step there is no decision: included.
    assert keyframe_weights(STEP_T, scales, np.array([-1.0, 0.5]))["f"][:, 0].tolist() == [1, 10]


def test_keyframe_without_a_step_since_the_previous_keeps_the_last_step():
    scales = {"f": col(1, INF, 1, 1, 1, 1, 1)}  # 0.5 s excluded
    # 0.6 -> 0.7 s holds no step: the decision in force is step 0.5 s.
    w = keyframe_weights(STEP_T, scales, np.array([0.0, 0.6, 0.7, 1.0]))
    assert w["f"][:, 0].tolist() == [1, INF, INF, 1]


# --- run_validation on a drifting compass ----------------------------------


DRIFT = (55.0, 80.0)  # s; the compass heading runs away at 0.1 rad/s and comes back
DURATION = 100.0
KEYFRAMES = np.arange(0.0, 99.0 + 1e-9, 0.5)


def drift_recording(seed: int = 0, sm_yaw_step: tuple[float, float, float] | None = None) -> tuple[Recording, Trajectory]:
    """A robot driving at 0.5 m/s through the default turns (20-30 s,
    40-50 s) with compass, gyro, odometry and scan matching; the compass
    heading drifts away during ``DRIFT`` (its field stays plausible).
    ``sm_yaw_step`` (start s, end s, rad) instead turns the scan matcher's
    heading by that much over that span, for good, and leaves the compass
    right. Returns the recording and the scan-matching trajectory."""
    rng = np.random.default_rng(seed)
    tf = np.arange(0.0, DURATION + 1e-9, 0.01)
    yaw = true_yaw(tf, DEFAULT_TURNS, 0.5)

    def path(heading: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        x = np.concatenate(([0.0], np.cumsum(0.25 * (np.cos(heading[1:]) + np.cos(heading[:-1])) * 0.01)))
        y = np.concatenate(([0.0], np.cumsum(0.25 * (np.sin(heading[1:]) + np.sin(heading[:-1])) * 0.01)))
        return x, y

    x, y = path(yaw)

    def trajectory(rate_hz: float, step: tuple[float, float, float] | None = None) -> Trajectory:
        t = sample_times(DURATION, rate_hz, rng)
        seen, px, py = yaw, x, y
        if step is not None:  # a chained heading error turns the path after it too
            seen = yaw + step[2] * np.clip((tf - step[0]) / (step[1] - step[0]), 0.0, 1.0)
            px, py = path(seen)
        noisy = np.interp(t, tf, seen) + rng.normal(0.0, 0.002, len(t))
        return Trajectory(t, np.interp(t, tf, px), np.interp(t, tf, py), wrap_angle(noisy))

    ref = MagneticReference(48.5e-6, np.radians(64.5))
    tc = sample_times(DURATION, 20.0, rng)
    true_c = np.interp(tc, tf, yaw)
    heading = true_c + rng.normal(0.0, 0.01, len(tc))
    if sm_yaw_step is None:
        heading += bump_error(tc, DRIFT, 0.1)
    compass = Compass(tc, wrap_angle(heading), field_body(true_c, ref.strength_T, ref.dip_rad))
    tg = sample_times(DURATION, 100.0, rng)
    gyro = Gyro(tg, yaw_rate(tg, DEFAULT_TURNS) + rng.normal(0.0, 0.002, len(tg)))
    rec = Recording(
        "drift", compass=compass, gyro=gyro, odometry=trajectory(20.0),
        faults={"IMU_YAW": [DRIFT]} if sm_yaw_step is None else {"SM_YAW": [sm_yaw_step[:2]]},
        magnetic_reference=ref,
    )
    return rec, trajectory(10.0, sm_yaw_step)


@pytest.fixture(scope="module")
def drift():
    return drift_recording()


def sections(mode: str, *overrides: str):
    return validation_sections(load_config(TELEMAX, [f"validation.mode={mode}", *overrides]))


def rows(outcome) -> list[dict[str, str]]:
    return list(csv.DictReader(io.StringIO(outcome.csv_text())))


def validate(rec, sm, vcfg, gcfg):
    return run_validation(rec, sm, KEYFRAMES, vcfg, gcfg, FACTOR_DOFS, rec.faults, rec.magnetic_reference)


def compass_excluded(out) -> np.ndarray:
    return ~np.isfinite(out.weights["compass"][:, 0])


def test_causal_validation_excludes_the_drifting_compass_and_nothing_else(drift):
    rec, sm = drift
    vcfg, gcfg = sections("on", "validation.pass=causal", "gating.lookback_s=0", "gating.holdoff_s=2")
    out = validate(rec, sm, vcfg, gcfg)
    assert out.results is not None and out.observer_log is not None
    assert sorted(out.weights) == list(FACTORS)
    for f in FACTORS:
        assert out.weights[f].shape == (len(KEYFRAMES), len(FACTOR_DOFS[f]))
        if f != "compass":
            assert np.all(out.weights[f] == 1.0), f
    excluded = compass_excluded(out)
    assert np.all((out.weights["compass"] == 1.0) | ~np.isfinite(out.weights["compass"]))  # single: exclude
    # Causal: the trailing windows and the counter take a few seconds; from
    # then to the end of the drift every keyframe is excluded.
    assert excluded[(KEYFRAMES >= DRIFT[0] + 3.5) & (KEYFRAMES <= DRIFT[1])].all()
    # No false alarm before (through the turns at 20-50 s); after the drift
    # the counters drain and the hold-off is 2 s (+ margin).
    assert not excluded[KEYFRAMES < DRIFT[0]].any()
    assert not excluded[KEYFRAMES > DRIFT[1] + 6.0].any()

    m = out.metrics
    assert m["validation_steps"] == len(out.step_t) == len(fixed_rate_steps(0.0, 99.0, 10.0))
    assert m["blamed_steps"].keys() == {"IMU_YAW"}
    assert 0.0 < m["detection_delay_s"]["IMU_YAW"] <= 3.5
    assert m["faults_missed"] == 0 and m["no_diagnosis_steps"] == 0
    assert m["isolation_precision"] > 0.75 and m["isolation_recall"] > 0.85
    assert m["keyframes_excluded"] == {f: int(excluded.sum()) if f == "compass" else 0 for f in FACTORS}


def test_offline_validation_dates_the_fault_by_its_evidence(drift):
    rec, sm = drift
    vcfg, gcfg = sections("on")  # the shipped config: offline
    assert vcfg.offline and vcfg.window == "centred"
    out = validate(rec, sm, vcfg, gcfg)
    excluded = compass_excluded(out)
    inside = (KEYFRAMES >= DRIFT[0] + 1.0) & (KEYFRAMES <= DRIFT[1] - 1.0)
    assert excluded[inside].all()
    assert not excluded[(KEYFRAMES < DRIFT[0] - 1.0) | (KEYFRAMES > DRIFT[1] + 1.0)].any()
    m = out.metrics
    assert abs(m["detection_delay_s"]["IMU_YAW"]) <= 1.0
    assert abs(m["blame_end_lag_s"]["IMU_YAW"]) <= 1.0
    assert m["isolation_precision"] > 0.9 and m["isolation_recall"] > 0.9


def test_lookback_extends_the_causal_exclusion_back(drift):
    rec, sm = drift
    vcfg, gcfg = sections("on", "validation.pass=causal")  # the shipped look-back: 6 s
    assert gcfg.lookback_s == 6.0
    out = validate(rec, sm, vcfg, gcfg)
    excluded = compass_excluded(out)
    # Detected within 3.5 s, so the 6 s look-back covers the onset.
    assert excluded[(KEYFRAMES >= DRIFT[0]) & (KEYFRAMES <= DRIFT[1])].all()
    assert not excluded[KEYFRAMES < DRIFT[0] - 6.0].any()
    # The weights are the per-step decisions with look-back, per keyframe.
    expected = keyframe_weights(out.step_t, step_scales(out.step_t, out.actions, gcfg, FACTOR_DOFS, 6.0), KEYFRAMES)
    for f in FACTORS:
        np.testing.assert_array_equal(out.weights[f], expected[f])


GLITCH = (60.0, 61.0, 0.3)  # s, s, rad: the scan matcher's heading turns 17 deg in a second, for good


def test_offset_forgets_what_the_integrated_stream_summed_while_blamed(monkeypatch):
    """The scan matcher's heading jumps once and stays off: its chained yaw
    carries the step for good. The gyro witnesses it, so scan matching is
    blamed for the jump; afterwards the causal offset observer of the
    compass against the scan matcher's yaw (its trailing level learns only
    from agreeing steps) would see a standing offset and blame the compass
    for the rest of the run. It takes out the change the scan matcher
    summed while blamed, so the compass stays in."""
    rec, sm = drift_recording(sm_yaw_step=GLITCH)
    vcfg, gcfg = sections("on", "validation.pass=causal")
    out = validate(rec, sm, vcfg, gcfg)
    after = out.step_t > GLITCH[1] + 10.0  # the counters drain
    blamed = np.array([r.consistent and "IMU_YAW" in r.diagnoses[0] for r in out.results])
    sm_blamed = np.array([r.consistent and bool({"SM_YAW", "SM"} & r.diagnoses[0]) for r in out.results])
    assert sm_blamed[(out.step_t >= GLITCH[0]) & (out.step_t <= GLITCH[1] + 2.0)].any()
    assert not blamed[after].any()
    assert not compass_excluded(out)[KEYFRAMES > GLITCH[1] + 10.0 + gcfg.holdoff_s].any()
    # Without it, the compass is blamed long after the jump: the test can fail.
    monkeypatch.setattr("validation.validator.MAX_EXCISE_PASSES", 0)
    stale = validate(rec, sm, vcfg, gcfg)
    blamed = np.array([r.consistent and "IMU_YAW" in r.diagnoses[0] for r in stale.results])
    assert blamed[after].mean() > 0.5


def test_validation_csv_columns_and_rows(drift):
    rec, sm = drift
    vcfg, gcfg = sections("on")
    out = validate(rec, sm, vcfg, gcfg)
    text = out.csv_text()
    header = text.splitlines()[0].split(",")
    expected = ["t"]
    for rel in vcfg.observers.relations:
        first = ("trend_a", "trend_b") if rel.kind == "trend" else ("z",)
        expected += [f"{rel.name}.{c}" for c in (*first, "valid", "counter", "no_match")]
    for check in ("mag_plausible", "gps_plausible"):
        expected += [f"{check}.valid", f"{check}.implausible"]
    expected += ["consistent", "diagnoses"]
    expected += [f"gate.{f}.{d}" for f in FACTORS for d in FACTOR_DOFS[f]]
    assert header == expected

    table = rows(out)
    assert len(table) == len(out.step_t) == len(text.splitlines()) - 1
    np.testing.assert_allclose([float(r["t"]) for r in table], out.step_t, atol=1e-4)
    for r in table:
        for rel in vcfg.observers.relations:
            if rel.kind == "trend":
                assert r[f"{rel.name}.trend_a"] in {"-1", "0", "1"}
            assert r[f"{rel.name}.valid"] in {"0", "1"} and r[f"{rel.name}.no_match"] in {"0", "1"}
            assert 0 <= int(r[f"{rel.name}.counter"]) <= rel.max_counter
        assert r["gps_plausible.valid"] == "0"  # no GPS in this recording
        assert r["consistent"] == "1"
        assert r["gate.compass.yaw"] in {"include", "exclude"}
        assert all(r[f"gate.{f}.{d}"] == "include" for f in FACTORS if f != "compass" for d in FACTOR_DOFS[f])
    by_t = {round(float(r["t"]), 1): r for r in table}
    # Healthy before the drift, both compass relations in conflict during it.
    assert by_t[30.0]["diagnoses"] == "{}" and by_t[30.0]["gate.compass.yaw"] == "include"
    during = by_t[70.0]
    assert during["yaw_compass_gyro.no_match"] == "1" and during["yaw_compass_sm.no_match"] == "1"
    assert during["yaw_gyro_sm.no_match"] == "0"
    assert during["diagnoses"].split(" | ")[0] == "{IMU_YAW}"
    assert during["gate.compass.yaw"] == "exclude"


def test_oracle_uses_the_true_faults_without_lookback(drift):
    rec, sm = drift
    vcfg, gcfg = sections("interval_oracle")
    assert gcfg.lookback_s == 6.0  # ignored by the oracle
    out = validate(rec, sm, vcfg, gcfg)
    assert out.results is None and out.observer_log is None
    # Keyframe k takes the steps in (t_{k-1}, t_k]: exactly the keyframes
    # at 55.0 .. 80.0 s hold a step inside the closed fault interval.
    in_fault = (KEYFRAMES >= DRIFT[0]) & (KEYFRAMES <= DRIFT[1])
    np.testing.assert_array_equal(compass_excluded(out), in_fault)
    for f in FACTORS:
        if f != "compass":
            assert np.all(out.weights[f] == 1.0)
    m = out.metrics
    assert m["isolation_precision"] == 1.0 and m["isolation_recall"] == 1.0
    assert m["detection_delay_s"] == {"IMU_YAW": 0.0}
    steps_in = int(np.sum((out.step_t >= DRIFT[0]) & (out.step_t <= DRIFT[1])))
    assert steps_in == 251
    assert m["alarm_fraction"] == round(steps_in / len(out.step_t), 5)
    header = out.csv_text().splitlines()[0]
    assert header == "t," + ",".join(f"gate.{f}.{d}" for f in FACTORS for d in FACTOR_DOFS[f])
    assert len(rows(out)) == len(out.step_t)


def test_oracle_without_faults_gates_nothing(drift):
    rec, sm = drift
    clean = Recording("clean", compass=rec.compass, gyro=rec.gyro, odometry=rec.odometry)
    vcfg, gcfg = sections("interval_oracle")
    out = validate(clean, sm, vcfg, gcfg)
    assert all(np.all(w == 1.0) for w in out.weights.values())
    assert out.metrics["alarm_fraction"] == 0.0
    assert out.metrics["isolation_precision"] is None and out.metrics["isolation_recall"] is None


def test_integrated_fault_spans_cover_the_blame_of_the_integrated_side_only():
    """Scan matching blamed at steps 5-8, the compass at 12-14: the offset of
    compass against scan-matching yaw gets one span, from the look-back
    before the first blamed step to the first step after; the compass is
    the absolute side and gets none, nor does the compass-gyro offset."""
    vcfg, _ = sections("on")
    d = Diagnoser(vcfg.model)
    clear = d.diagnose({})
    sm = d.diagnose({"yaw_gyro_sm": Observation.NO_MATCH, "yaw_compass_sm": Observation.NO_MATCH,
                     "yaw_compass_gyro": Observation.MATCH})
    compass = d.diagnose({"yaw_compass_gyro": Observation.NO_MATCH, "yaw_compass_sm": Observation.NO_MATCH,
                          "yaw_gyro_sm": Observation.MATCH})
    assert sm.diagnoses[0] <= {"SM", "SM_YAW"} and compass.diagnoses[0] == {"IMU_YAW"}
    results = [clear] * 5 + [sm] * 4 + [clear] * 3 + [compass] * 3 + [clear] * 5
    t = np.arange(len(results)) * 0.1
    spans = integrated_fault_spans(vcfg.observers.relations, vcfg.model, t, results, lookback_s=0.3)
    assert spans == {"yaw_compass_sm_off": [(2, 9)]}
    assert integrated_fault_spans(vcfg.observers.relations, vcfg.model, t, results, 0.0) == {
        "yaw_compass_sm_off": [(5, 9)]}


def test_integrated_fault_spans_merge_where_the_look_back_overlaps():
    """Two bursts of scan-matching blame 0.3 s apart, with a look-back of
    0.5 s: one span, so no change is taken out twice."""
    vcfg, _ = sections("on")
    d = Diagnoser(vcfg.model)
    clear = d.diagnose({})
    sm = d.diagnose({"yaw_gyro_sm": Observation.NO_MATCH, "yaw_compass_sm": Observation.NO_MATCH,
                     "yaw_compass_gyro": Observation.MATCH})
    results = [clear] * 8 + [sm] * 2 + [clear] * 3 + [sm] * 2 + [clear] * 5
    t = np.arange(len(results)) * 0.1
    spans = integrated_fault_spans(vcfg.observers.relations, vcfg.model, t, results, lookback_s=0.5)
    assert spans == {"yaw_compass_sm_off": [(3, 15)]}
