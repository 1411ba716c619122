"""``gslam`` smoke tests: help texts, every shipped pipeline config on the
short simulated run (conftest.py), one-line errors, the entry point."""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from slam.cli import build_parser, main
from slam.config import load_config, validation_sections
from tests.conftest import CONFIGS, REPO, TELEMAX_CONFIG

# Top-level configs/*.yaml are pipeline configs, except these.
NOT_PIPELINE_CONFIGS = {"variants.yaml", "bench_variants.yaml"}
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


@pytest.mark.slow
@pytest.mark.parametrize("gating", [None, "on", "oracle", "interval_oracle"])
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
    # The written config is the config used: it loads back equal.
    assert load_config(out / "config.yaml") == load_config(config, [] if gating is None else [f"validation.mode={gating}"])
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
    assert validation_sections(cfg)[0].mode in {"off", "on", "oracle", "interval_oracle"}


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


@pytest.mark.slow
def test_demo_simulates_and_maps_from_any_folder(capsys, short_scenario_yaml, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # the default config and variants are the shipped ones
    code, stdout, stderr = run_cli(capsys, "demo", "--scenario", short_scenario_yaml)
    assert code == 0, stderr
    assert stdout.startswith("simulated ")
    out = tmp_path / "runs" / "demo"
    assert (out / Path(short_scenario_yaml).stem / "truth.json").is_file()
    results = [json.loads(p.read_text()) for p in out.rglob("metrics.json")]
    assert len(results) == 3 and all(m["ate_rmse_m"] < 0.06 for m in results)
    # Again: the same scenario and seed reuse the simulated run; another seed does not.
    code, stdout, _ = run_cli(capsys, "demo", "--scenario", short_scenario_yaml, "--only", "ungated")
    assert code == 0 and stdout.startswith("reused ")
    code, stdout, _ = run_cli(capsys, "demo", "--scenario", short_scenario_yaml, "--only", "ungated", "--seed", "7")
    assert code == 0 and stdout.startswith("simulated ")
    assert json.loads((out / Path(short_scenario_yaml).stem / "truth.json").read_text())["seed"] == 7


def test_demo_missing_scenario(capsys, tmp_path):
    code, stdout, stderr = run_cli(capsys, "demo", "--out", tmp_path / "d", "--scenario", tmp_path / "nope.yaml")
    assert code == 1 and stdout == ""
    assert stderr.count("\n") == 1 and "nope.yaml" in stderr
    assert not (tmp_path / "d").exists()


# --- first contact ---------------------------------------------------------------------


def test_version(capsys):
    from slam import __version__

    with pytest.raises(SystemExit) as e:
        main(["--version"])
    assert e.value.code == 0
    assert capsys.readouterr().out.startswith(f"gslam {__version__} ")


def test_global_flags_work_after_the_command(capsys, short_scenario_yaml, tmp_path):
    assert main(["simulate", str(short_scenario_yaml), "--out", str(tmp_path / "a"), "-q"]) == 0
    assert "ray casting" not in capsys.readouterr().err  # -q after the command: no progress bars
    parser = build_parser()
    for argv in (["-v", "-q", "inspect", "x"], ["inspect", "x", "-v", "-q"], ["-v", "inspect", "x", "--quiet"]):
        args = parser.parse_args(argv)
        assert args.verbose and args.quiet, argv
    args = parser.parse_args(["-q", "inspect", "x"])  # a flag before the command stays set
    assert args.quiet and not args.verbose


@pytest.mark.parametrize("command", ["map", "compare", "inspect"])
def test_help_lists_every_input_format(capsys, command):
    with pytest.raises(SystemExit):
        main([command, "--help"])
    out = " ".join(capsys.readouterr().out.split())
    for fmt in ("ROS 1 .bag", "ROS 2 bag", ".db3", ".mcap", "simulated run folder", "CARMEN .log or .log.gz",
                "BROAD trial .mat", "libRSF *_Input.txt"):
        assert fmt in out, fmt


@pytest.mark.slow
def test_compare_works_from_any_folder(capsys, short_run, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # configs/... names the shipped configs; the variants are the shipped ones
    code, stdout, stderr = run_cli(capsys, "compare", short_run.run_dir, "--config", "configs/telemax.yaml",
                                   "--out", "cmp", "--only", "ungated,dcs", "--set", "output.plots=false")
    assert code == 0, stderr
    assert "| dcs |" in stdout and (tmp_path / "cmp" / "dcs" / "metrics.json").is_file()


@pytest.mark.slow
def test_inspect_lists_topics_and_its_starter_config_maps_the_run(capsys, short_run, tmp_path):
    starter = tmp_path / "starter.yaml"
    code, stdout, stderr = run_cli(capsys, "inspect", short_run.run_dir, "--config-out", starter)
    assert code == 0, stderr
    lines = stdout.splitlines()
    assert "run folder (ROS 2 bag + truth.json)" in lines[0] and "24.0 s" in lines[0] and "6 topics" in lines[0]
    scan = next(ln.split() for ln in lines if ln.strip().startswith("/scan"))
    assert scan[1:4] == ["sensor_msgs/msg/LaserScan", "240", "10.00"]
    tree = yaml.safe_load(starter.read_text())
    assert tree["input"]["topics"] == {"scan": "/scan", "gyro": "/imu/data", "compass": "/imu/mag", "odometry": "/odom",
                                       "gps": "/gps/fix", "groundtruth": "/ground_truth"}
    assert "# " in starter.read_text()  # commented
    code, stdout, stderr = run_cli(capsys, "map", short_run.run_dir, "--config", starter, "--out", tmp_path / "m")
    assert code == 0, stderr
    assert printed_metrics(stdout)["ate_rmse_m"] < 0.5


def test_inspect_a_ros1_bag(capsys, tmp_path):
    from tests.bagfactory import BagBuilder

    bag = BagBuilder(ros=1)
    for k in range(11):
        bag.imu("/imu/data", t=100.0 + 0.1 * k, rate_z=0.1, yaw=0.3)
        bag.odom("/wheel_odom", t=100.0 + 0.2 * k, x=0.1 * k, y=0.0, yaw=0.0)
    path = bag.write(tmp_path / "r.bag")
    code, stdout, stderr = run_cli(capsys, "inspect", path, "--config-out", tmp_path / "s.yaml")
    assert code == 0, stderr
    assert "ROS 1 bag, 2.0 s" in stdout
    imu = next(ln.split() for ln in stdout.splitlines() if ln.strip().startswith("/imu/data"))
    assert imu[1:4] == ["sensor_msgs/msg/Imu", "11", "10.00"]
    topics = yaml.safe_load((tmp_path / "s.yaml").read_text())["input"]["topics"]
    assert topics == {"scan": None, "gyro": "/imu/data", "compass": "/imu/data", "odometry": "/wheel_odom",
                      "gps": None, "groundtruth": None}


# --- errors ------------------------------------------------------------------------


@pytest.mark.slow
@pytest.mark.parametrize(
    "extra, expected",
    [
        (["--set", "backend.optimiser=isam2"], "unknown config key 'backend.optimiser'"),
        (["--set", "validation.observers.typo=1"], "unknown config key 'validation.observers.typo'"),
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


@pytest.mark.slow
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


def test_a_reader_that_leaves_early_gets_no_error(short_run):
    """``gslam inspect RUN | head -1``: the pipe closes before gslam writes."""
    proc = subprocess.Popen(
        [sys.executable, "-m", "slam.cli", "inspect", str(short_run.run_dir)],
        cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
    )
    proc.stdout.close()  # long before the interpreter has imported anything
    stderr = proc.stderr.read().decode()
    assert proc.wait(timeout=120) == 141
    assert stderr == ""


@pytest.mark.parametrize("argv", [
    ["scripts/datasets.py", "list"],
    ["-m", "slam.cli", "--help"],
    ["-m", "slam.cli", "map", "--help"],
    ["-m", "scripts.bench", "all", "--quick", "--only", "husky"],  # its first line is before any bench runs
    ["-m", "scripts.bench.kiss_only", "{run}", "--threads", "1"],
], ids=["datasets-list", "gslam-help", "gslam-map-help", "bench-all", "bench-kiss-only"])
def test_a_script_whose_reader_leaves_early_ends_quietly(argv, short_run):
    """``python scripts/datasets.py list | head -1``: no BrokenPipeError
    traceback, and the code of a process a closed pipe ended (141) or 0."""
    argv = [a.format(run=short_run.run_dir) for a in argv]
    proc = subprocess.Popen([sys.executable, *argv], cwd=REPO, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE)
    proc.stdout.close()  # long before the interpreter has imported anything
    stderr = proc.stderr.read().decode()
    assert proc.wait(timeout=120) in (0, 141), stderr
    assert stderr == ""


def test_a_bench_says_its_usage_as_its_docs_write_the_command():
    """``python -m scripts.bench real_faults --help`` says that command, not
    ``__main__.py``, whose usage line no one can run."""
    proc = subprocess.run([sys.executable, "-m", "scripts.bench", "real_faults", "--help"], cwd=REPO,
                          stdin=subprocess.DEVNULL, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0 and proc.stdout.startswith("usage: python -m scripts.bench real_faults ["), proc.stdout[:200]


@pytest.mark.parametrize("given, says", [("nowhere", "no such file or directory"),
                                         ("notes.yaml", "not a readable ROS bag (")])
def test_kiss_only_without_a_bag_says_so_in_one_line(tmp_path, given, says):
    (tmp_path / "notes.yaml").write_text("a: 1\n")
    proc = subprocess.run([sys.executable, "-m", "scripts.bench.kiss_only", str(tmp_path / given)], cwd=REPO,
                          stdin=subprocess.DEVNULL, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 1 and proc.stderr.startswith(f"kiss_only: {tmp_path / given}: {says}"), proc.stderr
    assert proc.stderr.count("\n") == 1


def test_a_full_or_closed_standard_output_is_named_or_harmless(short_run, tmp_path):
    """``gslam ... > /dev/full`` says that standard output failed, in one
    line; ``gslam ... >&-`` (no standard output at all) maps as usual."""
    import os

    argv = [sys.executable, "-m", "slam.cli", "-q", "inject", str(short_run.run_dir), "--fault", "gyro_bias@2:4"]
    with open("/dev/full", "w") as full:
        done = subprocess.run([*argv, "--out", str(tmp_path / "full")], cwd=REPO, stdout=full, stderr=subprocess.PIPE,
                              text=True, timeout=120)
    errors = [line for line in done.stderr.splitlines() if not line.startswith("WARNING ")]
    assert done.returncode == 1 and errors == ["gslam: error: standard output: No space left on device"], done.stderr
    done = subprocess.run([*argv, "--out", str(tmp_path / "closed")], cwd=REPO, stderr=subprocess.PIPE, text=True,
                          timeout=120, preexec_fn=lambda: os.close(1))
    assert done.returncode == 0 and "Traceback" not in done.stderr, done.stderr
    assert (tmp_path / "closed" / "truth.json").is_file()


@pytest.mark.slow
@pytest.mark.parametrize("argv", [
    ["husky_faults", "--faults", "bogus@1:2"],   # checked before any work
    ["husky_faults", "--data", "{tmp}"],          # no bag there
    ["perf", "--sections", "speed", "--repeats", "0"],
])
def test_benchmarks_fail_on_bad_input_with_one_line(argv, tmp_path):
    name, *args = argv
    done = subprocess.run([sys.executable, "-m", "scripts.bench", name, *(a.format(tmp=tmp_path) for a in args)],
                          cwd=REPO, capture_output=True, text=True, timeout=120)
    assert done.returncode == 1
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"bench {name}: "), done.stderr

def test_a_python_warning_is_one_line_naming_where_it_arose(capsys):
    """numpy's RuntimeWarning on a hostile value reaches the user as one
    line, like the command's own warnings, not as the interpreter's two."""
    import warnings

    import numpy as np

    from slam import cli

    previous = warnings.showwarning
    try:
        warnings.showwarning = cli._show_warning
        with warnings.catch_warnings():
            warnings.simplefilter("always")
            warnings.showwarning = cli._show_warning
            np.exp(np.array([1e300]))
    finally:
        warnings.showwarning = previous
    err = capsys.readouterr().err
    assert err.count("\n") == 1
    assert err.startswith("gslam: warning: overflow encountered in exp (RuntimeWarning, test_cli.py:")


def test_a_latin1_terminal_gets_what_it_cannot_show_escaped(tmp_path, short_run):
    """A path the terminal's encoding cannot show (Greek on a Latin-1
    terminal) is escaped in what the command prints, not a UnicodeEncodeError."""
    import os

    out = tmp_path / "χάρτης.yaml"
    env = {**os.environ, "PYTHONIOENCODING": "latin-1"}
    run = subprocess.run([sys.executable, "-m", "slam.cli", "inspect", str(short_run.run_dir), "--config-out", str(out)],
                         capture_output=True, env=env, cwd=Path(__file__).resolve().parents[1], stdin=subprocess.DEVNULL)
    said = (run.stdout + run.stderr).decode("latin-1")
    assert run.returncode == 0 and "Traceback" not in said and out.is_file()
    assert "\\u03c7\\u03ac\\u03c1" in said  # the name, escaped


def test_a_result_line_stays_one_line_whatever_its_path_holds(capsys):
    from slam.cli import _say

    _say("wrote runs/a\nb (2.0 s simulated)")
    assert capsys.readouterr().out == "wrote runs/a b (2.0 s simulated)\n"
