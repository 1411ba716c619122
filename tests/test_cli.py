"""``gslam`` smoke tests: help texts, every shipped pipeline config on the
short simulated run (conftest.py), one-line errors, the entry point."""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

import pytest

from slam.cli import build_parser, main
from slam.config import load_config, validation_sections
from tests.conftest import CONFIGS, REPO, TELEMAX_CONFIG

# Top-level configs/*.yaml are pipeline configs, except these.
NOT_PIPELINE_CONFIGS = {"variants.yaml"}
PIPELINE_CONFIGS = sorted(p for p in CONFIGS.glob("*.yaml") if p.name not in NOT_PIPELINE_CONFIGS)
DATASET_CONFIGS = sorted((CONFIGS / "datasets").glob("*.yaml"))


def run_cli(capsys, *argv: str) -> tuple[int, str, str]:
    code = main(["-q", *map(str, argv)])
    out, err = capsys.readouterr()
    return code, out, err


def printed_metrics(stdout: str) -> dict:
    """The JSON block ``gslam map`` prints after 'wrote OUT'."""
    return json.loads(stdout[stdout.index("{") :])


# --- help ------------------------------------------------------------------------


def subcommands() -> dict[str, argparse.ArgumentParser]:
    parser = build_parser()
    action = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return dict(action.choices)


def test_help_shows_examples(capsys):
    with pytest.raises(SystemExit) as e:
        main(["--help"])
    assert e.value.code == 0
    out = capsys.readouterr().out
    assert "examples:" in out
    for command in ("simulate", "map", "demo"):
        assert f"gslam {command}" in out
    assert "--gating on" in out and "--set backend.optimizer=isam2" in out


def test_the_documented_subcommands_exist():
    assert {"simulate", "map", "demo"} <= set(subcommands())


@pytest.mark.parametrize("command", sorted(subcommands()))
def test_subcommand_help_shows_examples(capsys, command):
    with pytest.raises(SystemExit) as e:
        main([command, "--help"])
    assert e.value.code == 0
    out = capsys.readouterr().out
    assert "example" in out and f"gslam {command} " in out.split("example", 1)[1], out


def test_usage_error_exits_2(capsys):
    with pytest.raises(SystemExit) as e:
        main(["map", "somewhere"])  # no --config / --out
    assert e.value.code == 2
    assert "--config" in capsys.readouterr().err


# --- shipped configs ------------------------------------------------------------------


def test_shipped_pipeline_configs_found():
    assert TELEMAX_CONFIG in PIPELINE_CONFIGS


@pytest.mark.parametrize("gating", [None, "on", "oracle"])
@pytest.mark.parametrize("config", PIPELINE_CONFIGS, ids=lambda p: p.name)
def test_map_with_every_shipped_pipeline_config(capsys, short_run, tmp_path, config, gating):
    out = tmp_path / "map"
    argv = ["map", short_run.run_dir, "--config", config, "--out", out]
    if gating is not None:
        argv += ["--gating", gating]
    code, stdout, stderr = run_cli(capsys, *argv)
    assert code == 0, stderr
    assert stdout.startswith(f"wrote {out}\n")
    shown = printed_metrics(stdout)
    assert shown == {k: v for k, v in json.loads((out / "metrics.json").read_text()).items() if k in shown}
    assert shown["ate_rmse_m"] < 0.06  # measured 0.012-0.024 m on this run
    for name in ("trajectory.tum", "groundtruth.tum", "metrics.json", "config.yaml", "map.ply"):
        assert (out / name).is_file(), name
    used = validation_sections(load_config(out / "config.yaml"))[0].mode
    if gating is None:
        assert used == validation_sections(load_config(config))[0].mode
    else:
        assert used == gating
        assert (out / "validation.csv").is_file()
        assert {"alarm_fraction", "isolation_precision", "isolation_recall", "detection_delay_s"} <= shown.keys()


@pytest.mark.parametrize("config", DATASET_CONFIGS, ids=lambda p: p.name)
def test_dataset_configs_load(config):
    cfg = load_config(config)
    assert cfg.input.format in {"carmen", "broad", "librsf", "rosbag", "auto"}
    assert validation_sections(cfg)[0].mode in {"off", "on", "oracle"}


def test_dataset_configs_found():
    assert {p.name for p in DATASET_CONFIGS} >= {"broad.yaml", "carmen.yaml", "librsf_corridor.yaml"}


def test_set_overrides_reach_the_run(capsys, short_run, tmp_path):
    out = tmp_path / "map"
    code, _, stderr = run_cli(
        capsys, "map", short_run.run_dir, "--config", TELEMAX_CONFIG, "--out", out,
        "--set", "backend.optimizer=isam2", "--set", "output.plots=false",
    )
    assert code == 0, stderr
    assert load_config(out / "config.yaml").backend.optimizer == "isam2"
    assert not list(out.glob("*.png"))


# --- simulate and demo ---------------------------------------------------------------


def test_simulate(capsys, short_scenario_yaml, short_run, tmp_path):
    out = tmp_path / "run"
    code, stdout, stderr = run_cli(capsys, "simulate", short_scenario_yaml, "--out", out, "--seed", short_run.seed)
    assert code == 0, stderr
    assert stdout.startswith(f"wrote {out} (")
    assert "true faults IMU_YAW" in stdout
    truth = json.loads((out / "truth.json").read_text())
    # The same scenario and seed as the session's run: the same faults.
    assert {c: [tuple(iv) for iv in v] for c, v in truth["faults"].items()} == short_run.faults
    # A second run into the same folder replaces the earlier simulate result.
    code, stdout, stderr = run_cli(capsys, "simulate", short_scenario_yaml, "--out", out, "--seed", short_run.seed)
    assert code == 0, stderr
    assert json.loads((out / "truth.json").read_text()) == truth


def test_demo_simulates_and_maps(capsys, short_scenario_yaml, tmp_path, monkeypatch):
    monkeypatch.chdir(REPO)  # the demo's default paths are relative to the repository
    out = tmp_path / "demo"
    code, stdout, stderr = run_cli(
        capsys, "demo", "--out", out, "--scenario", short_scenario_yaml, "--config", TELEMAX_CONFIG
    )
    assert code == 0, stderr
    assert stdout.startswith("simulated ")
    assert (out / Path(short_scenario_yaml).stem / "truth.json").is_file()
    results = [json.loads(p.read_text()) for p in out.rglob("metrics.json")]
    assert results and all(m["ate_rmse_m"] < 0.06 for m in results)


def test_demo_missing_scenario(capsys, tmp_path):
    code, stdout, stderr = run_cli(capsys, "demo", "--out", tmp_path / "d", "--scenario", tmp_path / "nope.yaml")
    assert code == 1 and stdout == ""
    assert stderr.count("\n") == 1 and "nope.yaml" in stderr
    assert not (tmp_path / "d").exists()


# --- errors ------------------------------------------------------------------------


@pytest.mark.parametrize(
    "extra, expected",
    [
        (["--set", "backend.optimiser=isam2"], "unknown config key 'backend.optimiser'"),
        (["--set", "validation.observers.typo=1"], "unknown key 'typo'"),
        (["--set", "input.topics.scan=/nope"], "'/nope'"),
        (["--set", "keyframes.period_s=1000"], "fewer than 2 keyframes"),  # fails after reading
        (["--set", "backend.optimizer"], "--set backend.optimizer: expected KEY=VALUE"),
    ],
    ids=["unknown-key", "unknown-observer-key", "missing-topic", "too-short", "bad-override"],
)
def test_errors_are_one_line(capsys, short_run, tmp_path, extra, expected):
    out = tmp_path / "map"
    code, stdout, stderr = run_cli(capsys, "map", short_run.run_dir, "--config", TELEMAX_CONFIG, "--out", out, *extra)
    assert code == 1
    assert stdout == ""
    errors = [line for line in stderr.splitlines() if line.startswith("gslam: error: ")]
    assert len(errors) == 1 and expected in errors[0], stderr
    assert "Traceback" not in stderr
    assert not out.exists() and list(tmp_path.iterdir()) == []


def test_missing_input_is_one_line(capsys, tmp_path):
    missing = tmp_path / "no_such_run"
    code, stdout, stderr = run_cli(capsys, "map", missing, "--config", TELEMAX_CONFIG, "--out", tmp_path / "map")
    assert code == 1 and stdout == ""
    assert stderr == f"gslam: error: {missing}: no such file or directory\n"
    assert not (tmp_path / "map").exists()


def test_missing_config_is_one_line(capsys, short_run, tmp_path):
    missing = tmp_path / "nope.yaml"
    code, _, stderr = run_cli(capsys, "map", short_run.run_dir, "--config", missing, "--out", tmp_path / "map")
    assert code == 1
    assert stderr.startswith(f"gslam: error: {missing}: cannot read config") and stderr.count("\n") == 1


# --- the entry point, out of process ---------------------------------------------------


def gslam(*argv) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "slam.cli", *map(str, argv)], cwd=REPO, capture_output=True, text=True, timeout=120
    )


def test_entry_point_maps_and_fails_cleanly(short_run, tmp_path):
    out = tmp_path / "map"
    done = gslam("-q", "map", short_run.run_dir, "--config", TELEMAX_CONFIG, "--out", out, "--gating", "on")
    assert done.returncode == 0, done.stderr
    assert printed_metrics(done.stdout)["n_poses"] > 10
    assert (out / "validation.csv").is_file()

    bad = gslam("map", short_run.run_dir, "--config", TELEMAX_CONFIG, "--out", tmp_path / "x", "--set", "backend.foo=1")
    assert bad.returncode == 1 and bad.stdout == ""
    assert bad.stderr == "gslam: error: --set backend.foo=1: unknown config key 'backend.foo'\n"
    assert not (tmp_path / "x").exists()
