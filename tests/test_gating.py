"""Gating: policies, hold-off timing, the no-diagnosis fallback, oracle mode."""

from __future__ import annotations

import logging
import math
from pathlib import Path

import pytest

from validation.diagnosis import Diagnoser, DiagnosisResult
from validation.errors import ValidationError
from validation.gating import FactorGate, Gate, GatingAction, GatingConfig, oracle_decisions
from validation.model import Observation, Plausibility, load_model

INC, INF, EXC = GatingAction.INCLUDE, GatingAction.INFLATE, GatingAction.EXCLUDE
TELEMAX = Path(__file__).resolve().parents[1] / "configs" / "validation" / "telemax_model.yaml"


def result(*diagnoses: set[str]) -> DiagnosisResult:
    """A consistent result with the given diagnoses, most probable first."""
    probs = tuple(0.5**i for i in range(1, len(diagnoses) + 1))
    return DiagnosisResult(frozenset(), tuple(frozenset(d) for d in diagnoses), probs, (), True, ())


CLEAN = result(set())
NONE = DiagnosisResult(frozenset(), (), (), (), False, (), frozenset({"yaw_sm"}))


def actions(decisions: dict[str, FactorGate]) -> dict[str, GatingAction]:
    return {f: g.action for f, g in decisions.items()}


def config(**kw) -> GatingConfig:
    return GatingConfig.from_mapping({"holdoff_s": 0.0, **kw})


# --- policies -------------------------------------------------------------


def test_empty_diagnosis_includes_everything():
    out = Gate(config()).step(0.0, CLEAN)
    assert set(out) == {"odometry", "gyro", "compass", "scan_matching", "gps"}
    assert all(g == FactorGate(INC, 1.0) for g in out.values())


@pytest.mark.parametrize("single, action, scale", [("exclude", EXC, math.inf), ("inflate", INF, 7.0)])
def test_single_diagnosis(single, action, scale):
    out = Gate(config(single=single, inflation=7.0)).step(0.0, result({"SM"}))
    assert out["scan_matching"] == FactorGate(action, scale)
    assert {f for f, g in out.items() if g.action is INC} == {"odometry", "gyro", "compass", "gps"}


def test_ambiguous_inflate_all():
    out = Gate(config(ambiguous="inflate_all", inflation=4.0)).step(0.0, result({"SM"}, {"ODO", "IMU_YAW"}))
    assert actions(out) == {"odometry": INF, "gyro": INC, "compass": INF, "scan_matching": INF, "gps": INC}
    assert out["compass"].sigma_scale == 4.0


def test_ambiguous_exclude_all():
    out = Gate(config(ambiguous="exclude_all")).step(0.0, result({"SM"}, {"ODO"}))
    assert actions(out) == {"odometry": EXC, "gyro": INC, "compass": INC, "scan_matching": EXC, "gps": INC}


@pytest.mark.parametrize("single", [EXC, INF])
def test_ambiguous_most_probable(single):
    cfg = config(ambiguous="most_probable", single=single.value)
    out = Gate(cfg).step(0.0, result({"IMU_YAW"}, {"SM"}))
    assert actions(out) == {"odometry": INC, "gyro": INC, "compass": single, "scan_matching": INC, "gps": INC}


def test_factor_takes_the_strongest_action_of_its_components():
    cfg = config(factors={"heading": ["IMU_GYRO", "IMU_YAW"], "sm": ["SM"]}, ambiguous="most_probable")
    gate = Gate(cfg)
    assert actions(gate.step(0.0, result({"IMU_YAW"}))) == {"heading": EXC, "sm": INC}


def test_with_real_diagnoser_scan_matching_is_gated():
    model = load_model(TELEMAX)
    obs = {r: Observation.MATCH for r in model.relations} | {
        "yaw_compass_sm": Observation.NO_MATCH,
        "yaw_gyro_sm": Observation.NO_MATCH,
        "distance_odo_sm": Observation.NO_MATCH,
        "mag_plausible": Plausibility.PLAUSIBLE,
    }
    gate = Gate(GatingConfig(), model)
    out = gate.step(80.0, Diagnoser(model).diagnose(obs))
    assert actions(out) == {"odometry": INC, "gyro": INC, "compass": INC, "scan_matching": EXC, "gps": INC}


# --- hold-off -------------------------------------------------------------


def test_holdoff_returns_only_after_holdoff_s_of_clean_steps():
    gate = Gate(config(holdoff_s=2.0))
    dt = 0.5
    sm = {}
    for i in range(16):  # faulty at 0.0 .. 1.0, clean from 1.5 on
        t = i * dt
        sm[t] = gate.step(t, result({"SM"}) if t <= 1.0 else CLEAN)["scan_matching"].action
    assert all(sm[t] is EXC for t in (0.0, 0.5, 1.0, 1.5, 2.0, 2.5, 3.0))
    assert all(sm[t] is INC for t in (3.5, 4.0, 7.5))  # clean since 1.5: 3.5 - 1.5 = 2.0


def test_holdoff_restarts_when_suspected_again():
    gate = Gate(config(holdoff_s=1.0))
    seq = [(0.0, {"GPS"}), (0.5, set()), (1.0, {"GPS"}), (1.5, set()), (2.0, set()), (2.5, set())]
    got = [gate.step(t, result(d))["gps"].action for t, d in seq]
    assert got == [EXC, EXC, EXC, EXC, EXC, INC]


def test_zero_holdoff_returns_at_the_first_clean_step():
    gate = Gate(config(holdoff_s=0.0))
    assert gate.step(0.0, result({"ODO"}))["odometry"].action is EXC
    assert gate.step(0.1, CLEAN)["odometry"].action is INC


def test_held_component_keeps_its_action_while_another_is_suspected():
    gate = Gate(config(holdoff_s=1.0))
    gate.step(0.0, result({"SM"}))
    out = gate.step(0.5, result({"GPS"}))
    assert out["scan_matching"].action is EXC and out["gps"].action is EXC
    out = gate.step(1.5, result({"GPS"}))
    assert out["scan_matching"].action is INC  # clean since 0.5


def test_time_must_not_go_back():
    gate = Gate(config())
    gate.step(1.0, CLEAN)
    with pytest.raises(ValidationError, match="before the previous step"):
        gate.step(0.5, CLEAN)


# --- no diagnosis ---------------------------------------------------------


def test_no_diagnosis_keep_previous_and_message_once_per_episode(caplog):
    gate = Gate(config(holdoff_s=0.0, no_diagnosis="keep_previous"))
    caplog.set_level(logging.WARNING, logger="validation.gating")
    before = gate.step(0.0, result({"SM"}))
    for t in (0.5, 1.0, 1.5):
        assert gate.step(t, NONE) == before
    assert len(caplog.records) == 1
    assert "no diagnosis" in caplog.records[0].getMessage()
    assert "yaw_sm" in caplog.records[0].getMessage()
    assert actions(gate.step(2.0, CLEAN))["scan_matching"] is INC
    gate.step(2.5, NONE)
    gate.step(3.0, NONE)
    assert len(caplog.records) == 2  # a new episode, a new message


def test_no_diagnosis_include_all_and_inflate_all():
    gate = Gate(config(no_diagnosis="include_all"))
    gate.step(0.0, result({"SM"}))
    assert all(g == FactorGate(INC, 1.0) for g in gate.step(0.5, NONE).values())
    gate = Gate(config(no_diagnosis="inflate_all", inflation=3.0))
    gate.step(0.0, result({"SM"}))
    assert all(g == FactorGate(INF, 3.0) for g in gate.step(0.5, NONE).values())


def test_no_diagnosis_step_interrupts_the_holdoff():
    gate = Gate(config(holdoff_s=1.0, no_diagnosis="include_all"))
    gate.step(0.0, result({"SM"}))
    gate.step(0.5, CLEAN)
    gate.step(1.0, NONE)
    assert gate.step(1.5, CLEAN)["scan_matching"].action is EXC  # clean again only since 1.5
    assert gate.step(2.5, CLEAN)["scan_matching"].action is INC


# --- oracle and config ----------------------------------------------------


def test_oracle_decisions_from_fault_intervals():
    cfg = config(single="inflate", inflation=5.0)
    times = [60.0, 70.0, 100.0, 150.0, 150.5, 200.0]
    out = oracle_decisions(cfg, times, {"SM": [(70.0, 150.0)], "GPS": [(0.0, 65.0), (199.0, 220.0)]})
    assert [d["scan_matching"].action for d in out] == [INC, INF, INF, INF, INC, INC]
    assert [d["gps"].action for d in out] == [INF, INC, INC, INC, INC, INF]
    assert out[2]["scan_matching"].sigma_scale == 5.0
    assert all(d["odometry"] == FactorGate(INC, 1.0) for d in out)


def test_config_errors():
    with pytest.raises(ValidationError, match="unknown key 'holdof_s'"):
        GatingConfig.from_mapping({"holdof_s": 1.0})
    with pytest.raises(ValidationError, match="gating: ambiguous"):
        GatingConfig.from_mapping({"ambiguous": "guess"})
    with pytest.raises(ValidationError, match="inflation"):
        GatingConfig.from_mapping({"inflation": 0.5})
    model = load_model(TELEMAX)
    cfg = GatingConfig.from_mapping({"factors": {"wheel": ["WHEEL"]}})
    with pytest.raises(ValidationError, match="gating.factors.wheel: unknown component 'WHEEL'"):
        Gate(cfg, model)
