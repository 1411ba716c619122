"""Pipeline config loading: overrides, unknown keys, YAML booleans, the
inlined validation model, the dump round trip and one-line YAML errors."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from slam.config import PipelineConfig, dump_config, load_config, parse_override, validation_sections
from validation.base.yamlio import load_yaml
from slam.errors import GslamError
from validation.diagnosis.model import SystemModel, load_model

REPO = Path(__file__).resolve().parents[1]
TELEMAX = REPO / "configs" / "telemax.yaml"
MODEL = REPO / "configs" / "validation" / "telemax_model.yaml"


def one_line(err: pytest.ExceptionInfo) -> str:
    msg = str(err.value)
    assert "\n" not in msg
    return msg


# --- overrides --------------------------------------------------------------


def test_overrides_set_dotted_keys_with_yaml_values():
    cfg = load_config(
        TELEMAX,
        [
            "backend.optimizer=isam2",
            "backend.factors.gps.enabled=false",
            "keyframes.period_s=0.25",
            "evaluation.rpe_deltas_m=[1.0, 10.0]",
            "input.topics.gps=null",
            "backend.factors.compass.sigma_yaw_deg=2",
        ],
    )
    assert cfg.backend.optimizer == "isam2"
    assert cfg.backend.factors.gps.enabled is False
    assert cfg.keyframes.period_s == 0.25
    assert cfg.evaluation.rpe_deltas_m == [1.0, 10.0]
    assert cfg.input.topics.gps is None
    assert cfg.backend.factors.compass.sigma_yaw_deg == 2.0
    # Untouched keys keep the file's values (not the model defaults).
    assert cfg.backend.factors.gps.robust_kernel == "cauchy"
    assert cfg.input.compass.declination_deg == 3.0


def test_later_override_wins_and_value_may_contain_equals():
    cfg = load_config(TELEMAX, ["backend.optimizer=isam2", "backend.optimizer=batch", "input.topics.scan=/a=b"])
    assert cfg.backend.optimizer == "batch"
    assert cfg.input.topics.scan == "/a=b"


def test_overrides_without_a_file_apply_to_the_defaults():
    cfg = load_config(None, ["backend.optimizer=isam2"])
    assert cfg.backend.optimizer == "isam2"
    assert cfg.keyframes == PipelineConfig().keyframes


def test_parse_override():
    assert parse_override("a.b=3") == ("a.b", 3)
    assert parse_override(" a.b =on") == ("a.b", True)
    assert parse_override("a.b=") == ("a.b", None)
    with pytest.raises(GslamError, match="--set a.b: expected KEY=VALUE"):
        parse_override("a.b")
    with pytest.raises(GslamError, match="--set =3: expected KEY=VALUE with a dotted key"):
        parse_override("=3")
    with pytest.raises(GslamError, match="with a dotted key"):
        parse_override("a..b=3")


def test_override_through_a_scalar_is_an_error():
    with pytest.raises(GslamError) as e:
        load_config(TELEMAX, ["backend.optimizer.x=1"])
    assert one_line(e) == "--set backend.optimizer.x=1: 'backend.optimizer' is a value, not a section"


# --- unknown keys and bad values -------------------------------------------------


@pytest.mark.parametrize(
    "override, named",
    [
        ("backend.optimiser=isam2", "backend.optimiser"),
        ("backend.factors.gps.sigma=1", "backend.factors.gps.sigma"),
        ("frontend.voxel=0.2", "frontend.voxel"),
        ("colour=red", "colour"),
        ("validation.rate=10", "rate"),
        ("validation.observers.magnetometer.tolerance=1", "magnetometer.tolerance"),
        ("validation.observers.typo=1", "typo"),
        ("gating.holdof_s=1", "holdof_s"),
    ],
)
def test_unknown_key_names_the_key(override, named):
    with pytest.raises(GslamError) as e:
        load_config(TELEMAX, [override])
    msg = one_line(e)
    assert msg.startswith(f"--set {override}: ")  # the override is to blame, not the file
    assert "unknown" in msg and named in msg


def test_unknown_key_in_a_file_names_the_key(tmp_path):
    path = tmp_path / "c.yaml"
    path.write_text("backend:\n  factors:\n    odometry: {sigma_xy: 0.1}\n")
    with pytest.raises(GslamError, match=r"unknown config key 'backend\.factors\.odometry\.sigma_xy'"):
        load_config(path)


def test_unknown_key_inside_a_relation_observer(tmp_path):
    tree = yaml.safe_load(TELEMAX.read_text())
    tree["validation"]["model"] = str(MODEL)
    tree["validation"]["observers"]["relations"][0]["treshold"] = 3
    path = tmp_path / "c.yaml"
    path.write_text(yaml.safe_dump(tree))
    with pytest.raises(GslamError) as e:
        load_config(path)
    assert "treshold" in one_line(e)


@pytest.mark.parametrize(
    "override, expected",
    [
        ("backend.optimizer=lbfgs", "backend.optimizer"),
        ("keyframes.period_s=-1", "keyframes.period_s"),
        ("validation.mode=maybe", "mode"),
        ("validation.rate_hz=0", "rate_hz"),
        ("gating.single=drop", "single"),
    ],
)
def test_bad_value_names_the_key(override, expected):
    with pytest.raises(GslamError) as e:
        load_config(TELEMAX, [override])
    assert expected in one_line(e)


def test_validation_model_needed_when_gating(tmp_path):
    path = tmp_path / "c.yaml"
    path.write_text("validation: {mode: on}\n")
    with pytest.raises(GslamError) as e:
        load_config(path)
    assert "validation.model" in one_line(e)


def test_observer_must_be_a_relation_of_the_model():
    rel = "{name: yaw_x, stream_a: compass_yaw, stream_b: gyro_yaw, boundary: 0.05, window_s: 2.0, threshold: 10}"
    with pytest.raises(GslamError) as e:
        load_config(TELEMAX, [f"validation.observers.relations=[{rel}]"])
    assert "yaw_x" in one_line(e)


def test_gated_component_must_be_in_the_model():
    with pytest.raises(GslamError) as e:
        load_config(TELEMAX, ["gating.factors={compass: [MAG]}"])
    assert "gating.factors.compass" in one_line(e) and "MAG" in str(e.value)


# --- YAML booleans for validation.mode ---------------------------------------------


@pytest.mark.parametrize(
    "value, mode",
    [("on", "on"), ("off", "off"), ("yes", "on"), ("false", "off"), ("oracle", "oracle"), ("'on'", "on")],
)
def test_validation_mode_yaml_booleans(value, mode):
    cfg = load_config(TELEMAX, [f"validation.mode={value}"])
    assert validation_sections(cfg)[0].mode == mode


def test_shipped_config_mode_off_is_a_yaml_boolean():
    # configs/telemax.yaml says `mode: off`, which YAML 1.1 reads as false.
    assert load_yaml(TELEMAX)["validation"]["mode"] is False
    assert validation_sections(load_config(TELEMAX))[0].mode == "off"


def test_mode_on_in_a_file(tmp_path):
    path = tmp_path / "c.yaml"
    path.write_text(f"validation:\n  mode: on\n  model: {MODEL}\n")
    vcfg, _ = validation_sections(load_config(path))
    assert vcfg.mode == "on"


# --- validation.model inlined relative to the config file ---------------------


def test_model_path_is_relative_to_the_config_file(tmp_path, monkeypatch):
    (tmp_path / "models").mkdir()
    (tmp_path / "models" / "m.yaml").write_text(MODEL.read_text())
    (tmp_path / "cfgs").mkdir()
    path = tmp_path / "cfgs" / "c.yaml"
    path.write_text("validation:\n  mode: oracle\n  model: ../models/m.yaml\n")
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)
    cfg = load_config(path)
    assert isinstance(cfg.validation["model"], dict)
    assert SystemModel.model_validate(cfg.validation["model"]) == load_model(MODEL)
    vcfg, _ = validation_sections(cfg)
    assert vcfg.model == load_model(MODEL)


def test_model_path_given_as_override_is_relative_to_the_working_directory(tmp_path, monkeypatch):
    (tmp_path / "m.yaml").write_text(MODEL.read_text())
    path = tmp_path / "cfgs" / "c.yaml"
    path.parent.mkdir()
    path.write_text("validation:\n  mode: oracle\n")
    monkeypatch.chdir(tmp_path)
    cfg = load_config(path, ["validation.model=m.yaml"])
    assert SystemModel.model_validate(cfg.validation["model"]) == load_model(MODEL)


def test_shipped_config_inlines_its_model():
    cfg = load_config(TELEMAX)
    assert SystemModel.model_validate(cfg.validation["model"]) == load_model(MODEL)
    assert "model: validation/" not in dump_config(cfg)


def test_missing_model_file_is_named(tmp_path):
    path = tmp_path / "c.yaml"
    path.write_text("validation:\n  model: nope.yaml\n")
    with pytest.raises(GslamError) as e:
        load_config(path)
    assert str(tmp_path / "nope.yaml") in one_line(e)


# --- dump round trip ---------------------------------------------------------


@pytest.mark.parametrize("overrides", [[], ["validation.mode=on", "backend.optimizer=isam2", "input.topics.gps=null"]])
def test_dump_config_round_trip(tmp_path, overrides):
    cfg = load_config(TELEMAX, overrides)
    # Written elsewhere: the dump must not depend on the original location.
    path = tmp_path / "deep" / "config.yaml"
    path.parent.mkdir()
    path.write_text(dump_config(cfg))
    again = load_config(path)
    assert again == cfg
    assert validation_sections(again) == validation_sections(cfg)
    # Every default is spelled out.
    tree = yaml.safe_load(path.read_text())
    assert tree["frontend"]["max_iterations"] == PipelineConfig().frontend.max_iterations
    assert tree["backend"]["fallback_inflation"] == PipelineConfig().backend.fallback_inflation


SHIPPED = sorted([*(REPO / "configs").glob("*.yaml"), *(REPO / "configs" / "datasets").glob("*.yaml")])


@pytest.mark.slow
@pytest.mark.parametrize("mode", ["off", "on", "oracle"])
@pytest.mark.parametrize("config", [p for p in SHIPPED if p.name not in ("variants.yaml", "bench_variants.yaml")], ids=lambda p: p.name)
def test_every_shipped_config_round_trips_with_every_section_spelled_out(tmp_path, config, mode):
    try:
        cfg = load_config(config, [f"validation.mode={mode}"])
    except GslamError as e:  # a config without a validation model cannot gate
        assert mode != "off" and "a system model is needed" in str(e)
        return
    text = dump_config(cfg)
    (tmp_path / "config.yaml").write_text(text)
    assert load_config(tmp_path / "config.yaml") == cfg
    # YAML 1.1 reads a bare off/on as a boolean: the mode is quoted.
    assert f"  mode: '{mode}'" in text.splitlines() if mode != "oracle" else "  mode: oracle" in text.splitlines()
    tree = yaml.safe_load(text)
    assert tree["validation"]["mode"] == mode
    # The typed sections, every default spelled out.
    vcfg, gcfg = validation_sections(cfg)
    assert tree["validation"] == vcfg.model_dump(mode="json", by_alias=True)
    assert tree["gating"] == gcfg.model_dump(mode="json", by_alias=True)
    assert {"pass", "rate_hz", "model", "observers"} <= tree["validation"].keys()
    assert {"max_gap_s", "relations", "magnetometer", "gps"} <= tree["validation"]["observers"].keys()
    assert {"single", "ambiguous", "no_diagnosis", "inflation", "holdoff_s", "lookback_s", "factors"} <= tree["gating"].keys()


def test_an_empty_config_is_written_in_full(tmp_path, caplog):
    path = tmp_path / "empty.yaml"
    path.write_text("")
    cfg = load_config(path)
    assert "empty.yaml is empty: every key takes its built-in default" in caplog.text
    tree = yaml.safe_load(dump_config(cfg))
    assert tree["validation"]["mode"] == "off" and tree["validation"]["observers"]["relations"]
    assert tree["gating"]["holdoff_s"] == 2.0


def test_defaults_round_trip(tmp_path):
    path = tmp_path / "c.yaml"
    path.write_text(dump_config(PipelineConfig()))
    assert load_config(path) == PipelineConfig()


# --- YAML errors ------------------------------------------------------------------


@pytest.mark.parametrize(
    "text, line",
    [
        ("backend:\n  optimizer: batch\n  factors: [1, 2\nkeyframes: {}\n", 4),
        ("backend:\n  optimizer: batch\n optimizer: isam2\n", 3),
        ("a: 1\nb: 'unclosed\n", 3),
    ],
)
def test_invalid_yaml_names_the_line(tmp_path, text, line):
    path = tmp_path / "bad.yaml"
    path.write_text(text)
    with pytest.raises(GslamError) as e:
        load_config(path)
    msg = one_line(e)
    assert msg.startswith(str(path)) and f"line {line}" in msg and "invalid YAML" in msg


@pytest.mark.parametrize(
    "text, line, key, first",
    [
        ("backend:\n  factors:\n    gps: {sigma_xy_m: 0.03, sigma_xy_m: 300}\n", 3, "sigma_xy_m", "earlier on the same line"),
        ("keyframes: {period_s: 0.5, min_distance_m: 0.2, period_s: 5}\n", 1, "period_s", "earlier on the same line"),
        ("backend: {factors: {gps: {sigma_xy_m: 0.03}}, factors: {}}\n", 1, "factors", "earlier on the same line"),
        ("backend: {optimizer: isam2,\n  optimizer: batch}\n", 2, "optimizer", "first on line 1"),
        ("backend:\n  optimizer: isam2\n  optimizer: batch\n", 3, "optimizer", "first on line 2"),
        ("[{a: 1, a: 2}]\n", 1, "a", "earlier on the same line"),
    ],
)
def test_a_key_given_twice_is_refused_in_block_and_flow_mappings(tmp_path, text, line, key, first):
    path = tmp_path / "twice.yaml"
    path.write_text(text)
    with pytest.raises(GslamError) as e:
        load_yaml(path)
    msg = one_line(e)
    assert msg.startswith(f"{path}: line {line}: key '{key}' given twice ({first})"), msg


def test_a_key_given_twice_in_a_set_value_is_refused():
    with pytest.raises(GslamError) as e:
        load_config(TELEMAX, ["backend.factors.gps={sigma_xy_m: 0.03, sigma_xy_m: 300}"])
    assert one_line(e) == ("--set backend.factors.gps={sigma_xy_m: 0.03, sigma_xy_m: 300}: key 'sigma_xy_m' given "
                           "twice; the second would silently replace the first")


def test_keys_that_differ_and_merge_keys_are_no_duplicates(tmp_path):
    path = tmp_path / "ok.yaml"
    path.write_text("base: &b {x: 1, y: 2}\nother: {<<: *b, x: 3, z: [{x: 1}, {x: 2}]}\n")
    assert load_yaml(path)["other"] == {"x": 3, "y": 2, "z": [{"x": 1}, {"x": 2}]}


def test_top_level_must_be_a_mapping(tmp_path):
    path = tmp_path / "list.yaml"
    path.write_text("- 1\n- 2\n")
    with pytest.raises(GslamError, match="expected a YAML mapping of keys at the top level, found a list"):
        load_config(path)


def test_empty_file_is_the_defaults(tmp_path):
    path = tmp_path / "empty.yaml"
    path.write_text("# nothing\n")
    assert load_config(path) == PipelineConfig()


def test_missing_file_is_named(tmp_path):
    with pytest.raises(GslamError) as e:
        load_config(tmp_path / "nope.yaml")
    assert "nope.yaml" in one_line(e) and "cannot read" in str(e.value)


@pytest.mark.parametrize("name", ["variants.yaml", "bench_variants.yaml"])
def test_shipped_variants_are_valid_overrides(name):
    """Every variant of the shipped variant files loads on the shipped config;
    the benchmark's file holds compare's variants unchanged, and three more."""
    from slam.commands.compare import load_variants

    variants = load_variants(REPO / "configs" / name)
    for overrides in variants.values():
        load_config(REPO / "configs" / "telemax.yaml", overrides)
    if name == "bench_variants.yaml":
        shipped = load_variants(REPO / "configs" / "variants.yaml")
        assert {k: variants[k] for k in shipped} == shipped
        assert set(variants) - set(shipped) == {"gated_nocal", "gated_cauchy", "gated_no_loops"}


def test_an_unknown_key_names_the_nearest_known_one():
    hints = {
        "backend.optimiser=isam2": "unknown config key 'backend.optimiser'; did you mean 'optimizer'?",
        "keyframe.period_s=1": "unknown config key 'keyframe'; did you mean 'keyframes'?",
        "submaps.constraints.refine_nar=true": "did you mean 'refine_near'?",
        # the validation and gating sections name their keys the same way
        "gating.holdof_s=1": "--set gating.holdof_s=1: unknown config key 'gating.holdof_s'; did you mean 'holdoff_s'?",
        "validation.rate_hx=10": "unknown config key 'validation.rate_hx'; did you mean 'rate_hz'?",
        "validation.observers.scan.min_return=3":
            "unknown config key 'validation.observers.scan.min_return'; did you mean 'min_returns'?",
    }
    for override, says in hints.items():
        with pytest.raises(GslamError) as e:
            load_config(TELEMAX, [override])
        assert says in str(e.value)
    with pytest.raises(GslamError) as e:  # nothing near: no guess
        load_config(TELEMAX, ["backend.zzz=1"])
    assert str(e.value).endswith("unknown config key 'backend.zzz'")


def test_the_validation_and_gating_sections_name_a_bad_value_by_its_key_path():
    for override, says in {
        "validation.rate_hz=-1": "--set validation.rate_hz=-1: validation.rate_hz: Input should be greater than 0",
        "gating.holdoff_s=-1": "--set gating.holdoff_s=-1: gating.holdoff_s: Input should be greater than or equal to 0",
        "validation.observers.scan.min_returns=0":
            "validation.observers.scan.min_returns: Input should be greater than or equal to 1",
    }.items():
        with pytest.raises(GslamError) as e:
            load_config(TELEMAX, [override])
        assert says in str(e.value)


def test_a_misspelt_gated_factor_type_names_it():
    """A factor type ``gating.factors`` names must be one the graph has (or
    the submap constraints): a misspelt one would gate nothing."""
    with pytest.raises(GslamError) as e:
        load_config(TELEMAX, ["gating.factors.scan_matchin=[SM]"])
    msg = one_line(e)
    assert "gating.factors.scan_matchin: unknown factor type 'scan_matchin'" in msg and "submaps" in msg
    config = load_config(TELEMAX, ["gating.factors.submaps=[SM]"])
    assert validation_sections(config)[1].factors["submaps"] == {"*": ["SM"]}
