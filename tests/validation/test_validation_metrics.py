"""Validation metrics against true fault intervals, on hand-built steps
with answers counted by hand (definitions in validation/metrics.py)."""

from __future__ import annotations

import numpy as np
import pytest

from validation.diagnosis.reiter import DiagnosisResult
from validation.gating import GatingAction, GatingConfig, oracle_actions
from validation.metrics import validation_metrics

GATING = GatingConfig()
STEP_T = np.arange(10.0)  # steps at 0, 1, ..., 9 s


def consistent(*diagnoses: set[str]) -> DiagnosisResult:
    """A consistent result, most probable diagnosis first."""
    probs = tuple(0.5**i for i in range(1, len(diagnoses) + 1))
    return DiagnosisResult(frozenset(), tuple(frozenset(d) for d in diagnoses), probs, (), True, ())


CLEAN = consistent(set())
NO_DIAGNOSIS = DiagnosisResult(frozenset(), (), (), (), False, (), frozenset({"yaw_gyro_sm"}))

RESULTS = [
    CLEAN,                          # 0
    CLEAN,                          # 1
    CLEAN,                          # 2  SM fault began at 2 s, not seen yet
    consistent({"SM"}),             # 3  SM blamed
    consistent({"SM"}, {"ODO", "IMU_GYRO"}),  # 4  SM most probable
    consistent({"ODO"}),            # 5  wrong component blamed
    NO_DIAGNOSIS,                   # 6  alarm, nothing blamed
    CLEAN,                          # 7  IMU_YAW fault missed
    CLEAN,                          # 8
    consistent({"GPS"}, {"SM"}),    # 9  GPS most probable, SM also minimal
]
FAULTS = {  # the truth of every component is known, as in a simulated run
    "SM": [(2.0, 5.0), (5.2, 5.8), (8.5, 9.5)],  # the middle one holds no step
    "IMU_YAW": [(7.0, 8.0)],
    "GPS": [],
    "ODO": [],
    "IMU_GYRO": [],
}
ALL_FINE = {c: [] for c in FAULTS}  # known to be fault-free
DECISIONS = [{} for _ in STEP_T]  # not used with results


def test_metrics_from_diagnoses():
    m = validation_metrics(STEP_T, RESULTS, DECISIONS, FAULTS)
    assert m["validation_steps"] == 10
    # Alarms: steps 3, 4, 5, 9 (a non-empty top diagnosis) and 6 (none) -> 5 / 10.
    assert m["alarm_fraction"] == 0.5
    # Of those, only step 6 lies outside every true fault interval.
    assert m["false_alarm_fraction"] == 0.1
    # True sets: SM at 2, 3, 4, 5, 9; IMU_YAW at 7, 8 -> 7 component-steps.
    # Blamed (top diagnosis): 3 {SM}, 4 {SM}, 5 {ODO}, 9 {GPS} -> 4;
    # correct: 3 and 4 -> 2. Precision 2 / 4, recall 2 / 7.
    assert m["isolation_precision"] == 0.5
    assert m["isolation_recall"] == round(2 / 7, 4) == 0.2857
    # SM: interval 1 first in a minimal diagnosis at 3 s (delay 1.0), interval
    # 3 at 9 s (second diagnosis, delay 0.5), interval 2 has no step and
    # does not count -> mean 0.75. IMU_YAW never -> None and one miss. GPS,
    # ODO and IMU_GYRO have no fault intervals -> no entry.
    assert m["detection_delay_s"] == {"SM": 0.75, "IMU_YAW": None}
    assert m["faults_missed"] == 1 and m["faults_detected"] == 2
    assert m["blamed_steps"] == {"GPS": 1, "ODO": 1, "SM": 2}
    assert m["no_diagnosis_steps"] == 1


def test_detection_counts_only_steps_inside_the_interval():
    # SM blamed at 1 s, before its fault (2-5 s), and never during it.
    results = [CLEAN, consistent({"SM"})] + [CLEAN] * 8
    m = validation_metrics(STEP_T, results, DECISIONS, {"SM": [(2.0, 5.0)]})
    assert m["detection_delay_s"] == {"SM": None}
    assert m["faults_missed"] == 1
    # Blamed once, wrongly: precision 0 / 1; recall 0 / 4.
    assert m["isolation_precision"] == 0.0 and m["isolation_recall"] == 0.0
    assert m["alarm_fraction"] == 0.1


def test_interval_bounds_are_closed():
    # Fault exactly 3-4 s: steps 3 and 4 are both inside.
    results = [CLEAN] * 4 + [consistent({"IMU_YAW"})] + [CLEAN] * 5
    m = validation_metrics(STEP_T, results, DECISIONS, {"IMU_YAW": [(3.0, 4.0)]})
    assert m["detection_delay_s"] == {"IMU_YAW": 1.0}
    assert m["isolation_precision"] == 1.0 and m["isolation_recall"] == 0.5  # 1 of steps 3, 4
    assert m["faults_missed"] == 0


def test_no_faults_and_no_alarms():
    m = validation_metrics(STEP_T, [CLEAN] * 10, DECISIONS, ALL_FINE)
    assert m["alarm_fraction"] == 0.0 and m["false_alarm_fraction"] == 0.0
    assert m["isolation_precision"] is None and m["isolation_recall"] is None
    assert m["detection_delay_s"] == {} and m["faults_missed"] == 0 and m["blamed_steps"] == {}


def test_no_faults_false_alarms_give_zero_precision_and_no_recall():
    results = [CLEAN] * 8 + [consistent({"ODO"}), consistent({"ODO", "GPS"})]
    m = validation_metrics(STEP_T, results, DECISIONS, ALL_FINE)
    assert m["alarm_fraction"] == m["false_alarm_fraction"] == 0.2
    assert m["isolation_precision"] == 0.0  # 0 of 3 blamed component-steps
    assert m["isolation_recall"] is None  # nothing was faulty


def test_without_truth_every_truth_metric_is_null():
    # A recording nobody labelled (a plain bag): alarms are counted, but
    # whether they were right is unknown, not 0.
    results = [CLEAN] * 8 + [consistent({"ODO"}), consistent({"ODO", "GPS"})]
    m = validation_metrics(STEP_T, results, DECISIONS, {})
    assert m["alarm_fraction"] == 0.2
    for key in ("false_alarm_fraction", "isolation_precision", "isolation_recall", "detection_delay_s",
                "faults_missed", "faults_detected"):
        assert m[key] is None, key
    assert m["truth_components"] == [] and m["blamed_steps"] == {"GPS": 1, "ODO": 2}


def test_partial_truth_judges_only_the_labelled_components():
    # Only the compass is labelled (as on a BROAD trial): blaming ODO is
    # neither right nor wrong; blaming IMU_YAW is judged.
    results = [CLEAN] * 6 + [consistent({"ODO"}), consistent({"IMU_YAW"}), consistent({"IMU_YAW"}), CLEAN]
    m = validation_metrics(STEP_T, results, DECISIONS, {"IMU_YAW": [(8.0, 9.0)]})
    assert m["isolation_precision"] == 0.5  # IMU_YAW blamed at 7 (wrong) and 8 (right); ODO not counted
    assert m["isolation_recall"] == 0.5  # IMU_YAW faulty at 8 and 9, blamed at 8
    assert m["false_alarm_fraction"] is None  # step 6 blames ODO, whose truth is unknown
    assert m["truth_components"] == ["IMU_YAW"]
    only_labelled = [CLEAN] * 7 + [consistent({"IMU_YAW"})] * 2 + [CLEAN]
    m = validation_metrics(STEP_T, only_labelled, DECISIONS, {"IMU_YAW": [(8.0, 9.0)]})
    assert m["false_alarm_fraction"] == 0.1  # step 7


# --- oracle mode (results None): the gated components are the blamed set ---


def gates(**actions: GatingAction) -> dict[str, GatingAction]:
    """The actions of one step."""
    return dict(actions)


EXC, INF = GatingAction.EXCLUDE, GatingAction.INFLATE


def test_oracle_metrics_from_decisions():
    decisions = (
        [gates()] * 2
        + [gates(SM=EXC)] * 4          # 2, 3, 4, 5
        + [gates()]                    # 6
        + [gates(IMU_YAW=INF)]         # 7: inflated counts as gated
        + [gates()] * 2                # 8, 9
    )
    faults = {"SM": [(2.0, 5.0)], "IMU_YAW": [(7.0, 8.0)]}
    m = validation_metrics(STEP_T, None, decisions, faults)
    # Alarms: 2, 3, 4, 5, 7 -> 0.5. Blamed 5 component-steps, all true;
    # true: SM 2-5 (4) + IMU_YAW 7, 8 (2) = 6 -> recall 5 / 6.
    assert m["alarm_fraction"] == 0.5
    assert m["isolation_precision"] == 1.0
    assert m["isolation_recall"] == round(5 / 6, 4) == 0.8333
    assert m["detection_delay_s"] == {"SM": 0.0, "IMU_YAW": 0.0}
    assert m["faults_missed"] == 0
    assert m["blamed_steps"] == {"IMU_YAW": 1, "SM": 4}
    assert m["no_diagnosis_steps"] == 0


def test_a_blamed_sensor_counts_as_all_its_modalities():
    results = [CLEAN] * 5 + [consistent({"SM"})] * 5
    expand = {"SM": ("SM_DIST", "SM_LAT", "SM_YAW")}
    faults = {"SM_DIST": [(5.0, 9.0)], "SM_LAT": [], "SM_YAW": []}
    m = validation_metrics(STEP_T, results, DECISIONS, faults, expand)
    # Steps 5-9 blame SM_DIST, SM_LAT and SM_YAW: 15 blamed, 5 true -> precision 1/3.
    assert m["isolation_precision"] == round(1 / 3, 4) and m["isolation_recall"] == 1.0
    assert m["blamed_steps"] == {"SM_DIST": 5, "SM_LAT": 5, "SM_YAW": 5}
    assert m["detection_delay_s"] == {"SM_DIST": 0.0}


def test_blame_end_lag():
    # IMU_YAW at fault 2-5 s, blamed 3-7 s: the blame ends 2 s after the fault.
    results = [CLEAN] * 3 + [consistent({"IMU_YAW"})] * 5 + [CLEAN] * 2
    m = validation_metrics(STEP_T, results, DECISIONS, {"IMU_YAW": [(2.0, 5.0)]})
    assert m["blame_end_lag_s"] == {"IMU_YAW": 2.0}
    assert m["detection_delay_s"] == {"IMU_YAW": 1.0}


def test_blame_end_lag_stops_at_the_next_fault():
    # Faults at 1-2 s and 4-5 s, blamed 1-7 s: the first fault's blame runs
    # into the second, counted to the last step before it (3 s: lag 1 s); the
    # second's ends 2 s late; the mean is 1.5 s.
    results = [CLEAN] + [consistent({"IMU_YAW"})] * 7 + [CLEAN] * 2
    m = validation_metrics(STEP_T, results, DECISIONS, {"IMU_YAW": [(1.0, 2.0), (4.0, 5.0)]})
    assert m["blame_end_lag_s"] == {"IMU_YAW": 1.5}


def test_oracle_decisions_are_perfect():
    faults = {"SM": [(2.0, 5.0)], "GPS": [(8.0, 20.0)]}
    decisions = oracle_actions(GATING, STEP_T, faults)
    m = validation_metrics(STEP_T, None, decisions, faults)
    # Gated: SM at 2-5, GPS at 8, 9 -> 6 of 10 steps.
    assert m["alarm_fraction"] == 0.6
    assert m["isolation_precision"] == 1.0 and m["isolation_recall"] == 1.0
    assert m["detection_delay_s"] == {"SM": 0.0, "GPS": 0.0}


def test_interval_after_the_last_step_is_not_missed():
    m = validation_metrics(STEP_T, [CLEAN] * 10, DECISIONS, {"SM": [(20.0, 30.0)]})
    assert m["faults_missed"] == 0 and m["detection_delay_s"] == {"SM": None}


@pytest.mark.parametrize("results", [None, [CLEAN] * 10])
def test_metrics_are_json_ready(results):
    import json

    m = validation_metrics(STEP_T, results, DECISIONS, FAULTS)
    assert json.loads(json.dumps(m)) == m
