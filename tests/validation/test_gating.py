"""Gating: policies, per-degree-of-freedom scales, hold-off timing, the
no-diagnosis fallback, offline and oracle actions."""

from __future__ import annotations

import logging
import math
from pathlib import Path

import numpy as np
import pytest

from validation.diagnosis.model import Observation, Plausibility, SystemModel, load_model
from validation.diagnosis.reiter import Diagnoser, DiagnosisResult
from validation.base.errors import ValidationError
from validation.gating import (
    Gate,
    GatingAction,
    GatingConfig,
    factor_scales,
    offline_actions,
    oracle_actions,
)

INC, INF, EXC = GatingAction.INCLUDE, GatingAction.INFLATE, GatingAction.EXCLUDE
# The pipeline's factor types and their degrees of freedom (slam.graph.measurements.FACTOR_DOFS),
# spelled out here: these tests run without slam.
FACTOR_DOFS = {"odometry": ("x", "y", "yaw"), "gyro": ("yaw",), "compass": ("yaw",),
               "scan_matching": ("x", "y", "yaw"), "gps": ("x", "y")}
TELEMAX = Path(__file__).resolve().parents[2] / "configs" / "validation" / "telemax_model.yaml"


def result(*diagnoses: set[str]) -> DiagnosisResult:
    """A consistent result with the given diagnoses, most probable first."""
    probs = tuple(0.5**i for i in range(1, len(diagnoses) + 1))
    return DiagnosisResult(frozenset(), tuple(frozenset(d) for d in diagnoses), probs, (), True, ())


CLEAN = result(set())
NONE = DiagnosisResult(frozenset(), (), (), (), False, (), frozenset({"yaw_sm"}))


def config(**kw) -> GatingConfig:
    return GatingConfig.from_mapping({"holdoff_s": 0.0, **kw})


def scales(cfg: GatingConfig, actions) -> dict[str, list[float]]:
    return {f: s.tolist() for f, s in factor_scales(cfg, actions, FACTOR_DOFS).items()}


# --- policies and degrees of freedom ----------------------------------------------


def test_empty_diagnosis_includes_everything():
    cfg = config()
    out = Gate(cfg).step(0.0, CLEAN)
    assert out == {}
    assert all(v == [1.0] * len(FACTOR_DOFS[f]) for f, v in scales(cfg, out).items())


@pytest.mark.parametrize("single, action, scale", [("exclude", EXC, math.inf), ("inflate", INF, 7.0)])
def test_single_diagnosis_gates_only_its_degrees_of_freedom(single, action, scale):
    cfg = config(single=single, inflation=7.0)
    out = Gate(cfg).step(0.0, result({"SM_DIST"}))
    assert out == {"SM_DIST": action}
    s = scales(cfg, out)
    assert s["scan_matching"] == [scale, 1.0, 1.0]  # x only: the heading and sideways motion stay
    assert all(v == [1.0] * len(FACTOR_DOFS[f]) for f, v in s.items() if f != "scan_matching")


def test_a_whole_sensor_gates_every_degree_of_freedom_of_its_factor():
    cfg = config()
    s = scales(cfg, Gate(cfg).step(0.0, result({"SM"})))
    assert s["scan_matching"] == [math.inf] * 3 and s["odometry"] == [1.0] * 3


def test_ambiguous_inflate_all():
    cfg = config(ambiguous="inflate_all", inflation=4.0)
    out = Gate(cfg).step(0.0, result({"SM_YAW"}, {"ODO_YAW", "IMU_YAW"}))
    assert out == {"SM_YAW": INF, "ODO_YAW": INF, "IMU_YAW": INF}
    s = scales(cfg, out)
    assert s["odometry"] == [1.0, 1.0, 4.0] and s["compass"] == [4.0] and s["gyro"] == [1.0]


def test_ambiguous_exclude_all():
    out = Gate(config(ambiguous="exclude_all")).step(0.0, result({"SM_DIST"}, {"ODO_DIST"}))
    assert out == {"SM_DIST": EXC, "ODO_DIST": EXC}


@pytest.mark.parametrize("single", [EXC, INF])
def test_ambiguous_most_probable(single):
    cfg = config(ambiguous="most_probable", single=single.value)
    assert Gate(cfg).step(0.0, result({"IMU_YAW"}, {"SM_YAW"})) == {"IMU_YAW": single}


def test_a_component_named_to_inflate_is_inflated_while_its_partners_are_excluded():
    cfg = config(inflate=["ODO_DIST"], inflation=5.0)
    out = Gate(cfg).step(0.0, result({"ODO_DIST", "SM_YAW"}))
    assert out == {"ODO_DIST": INF, "SM_YAW": EXC}
    s = scales(cfg, out)
    assert s["odometry"] == [5.0, 5.0, 1.0] and s["scan_matching"] == [1.0, 1.0, math.inf]
    assert offline_actions(cfg, [result({"ODO_DIST"}), CLEAN]) == [{"ODO_DIST": INF}, {}]
    with pytest.raises(ValidationError, match="gating.inflate: unknown component 'WHEEL'"):
        Gate(config(inflate=["WHEEL"]), load_model(TELEMAX))


def test_degree_of_freedom_takes_the_strongest_action_of_its_components():
    cfg = config(factors={"heading": {"yaw": ["IMU_GYRO", "IMU_YAW"]}, "sm": ["SM"]})
    s = factor_scales(cfg, {"IMU_YAW": EXC, "IMU_GYRO": INF}, {"heading": ("yaw",), "sm": ("x", "yaw")})
    assert s["heading"].tolist() == [math.inf] and s["sm"].tolist() == [1.0, 1.0]


def test_a_plain_list_applies_to_every_degree_of_freedom():
    cfg = config(factors={"gps": ["GPS"]})
    assert cfg.components_of("gps", "x") == ["GPS"] == cfg.components_of("gps", "y")
    assert factor_scales(cfg, {"GPS": EXC}, {"gps": ("x", "y")})["gps"].tolist() == [math.inf, math.inf]


def test_with_real_diagnoser_scan_matching_is_gated():
    model = load_model(TELEMAX)
    obs = {r: Observation.MATCH for r in model.relations} | {
        "yaw_compass_sm": Observation.NO_MATCH,
        "yaw_gyro_sm": Observation.NO_MATCH,
        "distance_odo_sm": Observation.NO_MATCH,
        "lateral_odo_sm": Observation.NO_MATCH,
        "mag_plausible": Plausibility.PLAUSIBLE,
    }
    gate = Gate(GatingConfig(), model)
    out = gate.step(80.0, Diagnoser(model).diagnose(obs))
    assert out == {"SM": EXC}  # one fault of the whole scan matcher explains all four
    s = scales(GatingConfig(), out)
    assert s["scan_matching"] == [math.inf] * 3 and s["odometry"] == [1.0] * 3


# --- hold-off (causal) ----------------------------------------------------------


def test_holdoff_returns_only_after_holdoff_s_of_clean_steps():
    gate = Gate(config(holdoff_s=2.0))
    dt = 0.5
    sm = {}
    for i in range(16):  # faulty at 0.0 .. 1.0, clean from 1.5 on
        t = i * dt
        sm[t] = gate.step(t, result({"SM"}) if t <= 1.0 else CLEAN).get("SM", INC)
    assert all(sm[t] is EXC for t in (0.0, 0.5, 1.0, 1.5, 2.0, 2.5, 3.0))
    assert all(sm[t] is INC for t in (3.5, 4.0, 7.5))  # clean since 1.5: 3.5 - 1.5 = 2.0


def test_holdoff_restarts_when_suspected_again():
    gate = Gate(config(holdoff_s=1.0))
    seq = [(0.0, {"GPS"}), (0.5, set()), (1.0, {"GPS"}), (1.5, set()), (2.0, set()), (2.5, set())]
    got = [gate.step(t, result(d)).get("GPS", INC) for t, d in seq]
    assert got == [EXC, EXC, EXC, EXC, EXC, INC]


def test_zero_holdoff_returns_at_the_first_clean_step():
    gate = Gate(config(holdoff_s=0.0))
    assert gate.step(0.0, result({"ODO_DIST"})) == {"ODO_DIST": EXC}
    assert gate.step(0.1, CLEAN) == {}


def test_held_component_keeps_its_action_while_another_is_suspected():
    gate = Gate(config(holdoff_s=1.0))
    gate.step(0.0, result({"SM"}))
    assert gate.step(0.5, result({"GPS"})) == {"SM": EXC, "GPS": EXC}
    assert "SM" not in gate.step(1.5, result({"GPS"}))  # clean since 0.5


def test_time_must_not_go_back():
    gate = Gate(config())
    gate.step(1.0, CLEAN)
    with pytest.raises(ValidationError, match="before the previous step"):
        gate.step(0.5, CLEAN)


# --- no diagnosis -----------------------------------------------------------------


def test_no_diagnosis_keep_previous_and_message_once_per_episode(caplog):
    gate = Gate(config(holdoff_s=0.0, no_diagnosis="keep_previous"))
    caplog.set_level(logging.WARNING, logger="validation.gating")
    before = gate.step(0.0, result({"SM"}))
    for t in (0.5, 1.0, 1.5):
        assert gate.step(t, NONE) == before
    assert len(caplog.records) == 1
    assert "no diagnosis" in caplog.records[0].getMessage()
    assert "yaw_sm" in caplog.records[0].getMessage()
    assert gate.step(2.0, CLEAN) == {}
    gate.step(2.5, NONE)
    gate.step(3.0, NONE)
    assert len(caplog.records) == 2  # a new episode, a new message


def test_no_diagnosis_include_all_and_inflate_all():
    gate = Gate(config(no_diagnosis="include_all"))
    gate.step(0.0, result({"SM"}))
    assert gate.step(0.5, NONE) == {}
    cfg = config(no_diagnosis="inflate_all", inflation=3.0)
    gate = Gate(cfg)
    gate.step(0.0, result({"SM"}))
    s = scales(cfg, gate.step(0.5, NONE))
    assert all(v == [3.0] * len(FACTOR_DOFS[f]) for f, v in s.items())


def test_no_diagnosis_step_interrupts_the_holdoff():
    gate = Gate(config(holdoff_s=1.0, no_diagnosis="include_all"))
    gate.step(0.0, result({"SM"}))
    gate.step(0.5, CLEAN)
    gate.step(1.0, NONE)
    assert gate.step(1.5, CLEAN) == {"SM": EXC}  # clean again only since 1.5
    assert gate.step(2.5, CLEAN) == {}


# --- offline, oracle and config ---------------------------------------------------


def test_offline_actions_follow_each_step_without_holdoff():
    cfg = config(holdoff_s=5.0, no_diagnosis="keep_previous")
    out = offline_actions(cfg, [CLEAN, result({"SM"}), CLEAN, result({"GPS"}), NONE, CLEAN])
    assert out == [{}, {"SM": EXC}, {}, {"GPS": EXC}, {"GPS": EXC}, {}]


def test_oracle_actions_from_fault_intervals():
    cfg = config(single="inflate", inflation=5.0)
    times = [60.0, 70.0, 100.0, 150.0, 150.5, 200.0]
    out = oracle_actions(cfg, times, {"SM_DIST": [(70.0, 150.0)], "GPS": [(0.0, 65.0), (199.0, 220.0)]})
    assert [d.get("SM_DIST", INC) for d in out] == [INC, INF, INF, INF, INC, INC]
    assert [d.get("GPS", INC) for d in out] == [INF, INC, INC, INC, INC, INF]
    assert scales(cfg, out[2])["scan_matching"] == [5.0, 1.0, 1.0]


def test_config_errors():
    with pytest.raises(ValidationError, match="unknown key 'holdof_s'"):
        GatingConfig.from_mapping({"holdof_s": 1.0})
    with pytest.raises(ValidationError, match="gating: ambiguous"):
        GatingConfig.from_mapping({"ambiguous": "guess"})
    with pytest.raises(ValidationError, match="inflation"):
        GatingConfig.from_mapping({"inflation": 0.5})
    with pytest.raises(ValidationError, match="needs at least one component"):
        GatingConfig.from_mapping({"factors": {"gps": {"x": []}}})
    model = load_model(TELEMAX)
    cfg = GatingConfig.from_mapping({"factors": {"wheel": {"x": ["WHEEL"]}}})
    with pytest.raises(ValidationError, match="gating.factors.wheel.x: unknown component 'WHEEL'"):
        Gate(cfg, model)
    assert np.isinf(factor_scales(GatingConfig(), {"SM": EXC}, FACTOR_DOFS)["scan_matching"]).all()


def test_a_sensor_must_gate_what_its_modalities_gate():
    """A blame of the whole scan matcher (SM) must reach the factors its
    modalities gate; named only under SM_DIST it would change nothing."""
    from validation.gating import check_components

    model = SystemModel(components=("ODO_DIST", "SM_DIST", "SM"), sensors={"SM": ("SM_DIST",)},
                        relations={"distance_odo_sm": ("ODO_DIST", "SM_DIST")})
    idle = GatingConfig(factors={"scan_matching": {"x": ["SM_DIST"]}})
    with pytest.raises(ValidationError, match="sensor 'SM' gates no factor.*name it beside SM_DIST"):
        check_components(idle, model)
    check_components(GatingConfig(factors={"scan_matching": {"x": ["SM_DIST", "SM"]}}), model)
    check_components(GatingConfig(factors={"odometry": {"x": ["ODO_DIST"]}}), model)  # scan matching not gated at all
