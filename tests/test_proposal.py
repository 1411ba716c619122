"""The system model proposed from physics (validation/proposal/) and the
starter config gslam inspect writes with it (slam/commands/inspect/starter.py,
slam/commands/inspect/topic_choice.py), on sensor sets of their own and on the shipped ones."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from bagfactory import sensor_bag
from slam.cli import main
from slam.config import load_config, validation_sections
from slam.commands.inspect.inspection import inspect_recording
from validation.diagnosis.model import load_model
from validation.proposal import Source, propose_model

CONFIGS = Path(__file__).resolve().parents[1] / "configs"

TELEMAX = [Source("gyro", "gyro", period_s=0.01), Source("compass", "compass", period_s=0.05, magnetometer=True),
           Source("odometry", "odo", period_s=0.05), Source("scan", "sm", period_s=0.1),
           Source("gps", "gps", period_s=0.2)]


def _pairs(relations) -> set[frozenset]:
    return {frozenset(pair) for pair in relations}


@pytest.mark.parametrize("model, sources, impossible", [
    ("telemax_model.yaml", TELEMAX, set()),
    ("carmen_model.yaml", [Source("odometry", "odo"), Source("scan", "sm")], set()),
    # The Husky's heading is an orientation estimate: it has no field to check. Its
    # and BROAD's models hold LOOP for a recording with a laser; these sources have none.
    ("husky_model.yaml", [Source("gyro", "gyro"), Source("compass", "compass"), Source("odometry", "odo"),
                          Source("gps", "gps")], {"mag_plausible", "loop_consistency"}),
    ("broad_model.yaml", [Source("gyro", "gyro"), Source("compass", "compass", magnetometer=True)],
     {"loop_consistency"}),
])
def test_the_proposal_holds_every_relation_of_the_hand_written_models(model, sources, impossible):
    shipped = load_model(CONFIGS / "validation" / model)
    proposed = propose_model(sources).model()
    assert _pairs(shipped.relations.values()) <= _pairs(proposed.relations.values())
    # The field's turn against the gyro's (an observer off unless enabled) is proposed wherever both exist.
    assert set(proposed.unary_checks) - {"mag_field_gyro"} == set(shipped.unary_checks) - impossible - {"mag_field_gyro"}
    assert set(proposed.components) <= set(shipped.components) | {"ODO", "SM"}


def test_a_further_odometry_source_is_a_sensor_of_its_own_and_a_witness():
    p = propose_model([Source("gyro", "gyro"), Source("odometry", "odo"), Source("odometry", "vo")])
    assert p.sensors == {"ODO": ["ODO_DIST", "ODO_YAW"], "VO": ["VO_DIST", "VO_YAW"]}
    names = {r.config.name for r in p.relations}
    assert {"yaw_odo_vo", "yaw_vo_gyro", "yaw_odo_gyro", "distance_odo_vo", "lateral_odo_vo_res"} <= names
    assert "vo" not in str(p.gating_factors) and set(p.gating_factors) == {"odometry", "gyro"}
    # Three witnesses of the heading: a fault of any one of them is isolated.
    yaw = [r.config.components for r in p.relations if r.config.kind == "trend" and r.config.name.startswith("yaw")]
    assert {frozenset(c) for c in yaw} == {frozenset(("ODO_YAW", "VO_YAW")), frozenset(("ODO_YAW", "IMU_GYRO")),
                                          frozenset(("VO_YAW", "IMU_GYRO"))}


def test_windows_hold_four_samples_of_the_sparser_stream():
    p = propose_model([Source("odometry", "odo", period_s=2.9), Source("scan", "sm", period_s=2.9)])
    assert {r.config.window_s for r in p.relations} == {11.6}


@pytest.mark.parametrize("sources, why", [
    ([Source("odometry", "odo", "/odom")], "the recording holds one stream (odometry /odom); a stream is validated "
                                           "against another that measures the same motion"),
    ([Source("gyro", "gyro"), Source("gps", "gps")], "no two of its streams (gyro, GPS) measure the same motion"),
    ([Source("compass", "compass", magnetometer=True), Source("gps", "gps")], "no two of its streams"),
])
def test_nothing_to_validate_says_why(sources, why):
    p = propose_model(sources)
    assert not p.relations and why in p.nothing_to_validate()
    assert "\n" not in p.nothing_to_validate()


# --- the starter gslam inspect writes --------------------------------------------------------------


def _starter(tmp_path, sensors, **kwargs):
    bag = sensor_bag(sensors, duration_s=30.0, **kwargs).write(tmp_path / "run.bag")
    found = inspect_recording(bag, starter=True)
    path = tmp_path / "starter.yaml"
    path.write_text(found.starter)
    return bag, found, load_config(path)


def test_a_bag_with_wheels_a_visual_odometry_and_an_imu(tmp_path):
    _, found, config = _starter(tmp_path, ["imu", "odom", "vo", "filtered", "gps"])
    assert config.input.topics.odometry == "/odom"
    assert config.input.extra_odometry["vo"].topic == "/vo/odom"
    assert config.input.compass.source == "imu_orientation" and config.input.gyro.axis == "z"
    assert any("not used: /odometry/filtered" in n for n in found.starter.splitlines())
    vcfg, gating = validation_sections(config)
    assert {"VO_DIST", "VO_YAW", "ODO_DIST", "IMU_GYRO", "IMU_YAW", "GPS"} <= set(vcfg.model.components)
    assert [r.name for r in vcfg.observers.relations] == [r.config.name for r in found.proposal.relations]
    assert vcfg.mode == "off" and not vcfg.observers.magnetometer.enabled and vcfg.observers.gps.enabled
    assert set(gating.factors) == {"odometry", "gyro", "compass", "gps"}


def test_a_magnetometer_instead_of_an_orientation(tmp_path):
    _, found, config = _starter(tmp_path, ["imu_no_orientation", "mag", "odom"])
    assert config.input.compass.source == "magnetic_field" and config.input.topics.compass == "/imu/mag"
    vcfg, _ = validation_sections(config)
    assert vcfg.observers.magnetometer.enabled and vcfg.model.unary_checks["mag_plausible"] == "IMU_YAW"


def test_an_imu_mounted_upside_down_is_read_from_its_gravity(tmp_path):
    _, found, config = _starter(tmp_path, ["imu_down", "odom"])
    assert config.input.gyro.axis == "z" and config.input.frames.gyro.body == "frd"
    assert "reads gravity on its -z axis" in found.starter


def test_the_shipped_configs_as_bases_keep_their_other_sections(tmp_path, short_run):
    found = inspect_recording(short_run.run_dir, starter=True, base=CONFIGS / "telemax.yaml")
    path = tmp_path / "s.yaml"
    path.write_text(found.starter)
    config, shipped = load_config(path), load_config(CONFIGS / "telemax.yaml")
    assert config.backend == shipped.backend and config.frontend == shipped.frontend
    vcfg, gating = validation_sections(config)
    assert vcfg.observers.rule == "paper" and gating.holdoff_s == 5.0 and vcfg.observers.scan.enabled


SHIPPED = [CONFIGS / "telemax.yaml", *sorted((CONFIGS / "datasets").glob("*.yaml"))]


@pytest.mark.parametrize("base", SHIPPED, ids=lambda p: p.stem)
@pytest.mark.parametrize("sources", [TELEMAX, [Source("odometry", "odo"), Source("scan", "sm")]], ids=["telemax", "laser"])
def test_the_proposal_over_each_shipped_config_is_a_config_that_loads(base, sources, tmp_path):
    """Each check the proposal writes replaces the base's (a key given twice
    is an error of the loader), and the result loads as a config."""
    from slam.commands.inspect.starter import replace_sections, validation_sections as proposed_sections

    text = base.read_text()
    tree = yaml.safe_load(text)
    sections = proposed_sections(propose_model(sources), tree.get("validation"), tree.get("gating"))
    path = tmp_path / base.name
    path.write_text(replace_sections(text, sections))
    config = load_config(path)
    vcfg, _ = validation_sections(config)
    assert [r.name for r in vcfg.observers.relations] == [r.config.name for r in propose_model(sources).relations]


def test_inspect_says_in_one_line_when_nothing_can_be_validated(tmp_path, capsys):
    bag = sensor_bag(["odom"], duration_s=20.0).write(tmp_path / "odom.bag")
    out = tmp_path / "starter.yaml"
    assert main(["-q", "inspect", str(bag), "--config-out", str(out)]) == 0
    printed = capsys.readouterr().out.splitlines()
    lines = [line for line in printed if "nothing can be validated" in line]
    assert len(lines) == 1 and "one stream (odometry /odom)" in lines[0]
    assert "ungated" in printed[-1]
    assert "# Nothing can be validated" in out.read_text()
    assert main(["-q", "calibrate", str(bag), "--config", str(out), "--out", str(tmp_path / "c.yaml")]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "nothing can be validated" in err[0]


def test_the_starter_is_commented_like_the_shipped_models(tmp_path):
    _, found, _ = _starter(tmp_path, ["imu", "odom", "gps"])
    text = found.starter
    assert "# One component per modality, as in the paper's Table 1." in text
    assert "yaw_odo_gyro: [ODO_YAW, IMU_GYRO]" in text and "# heading change: odometry against gyro" in text
    assert text.startswith("# gslam inspect result")
    yaml.safe_load(text)
