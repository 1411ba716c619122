"""Malformed input for every reader and every command, as a hostile tester
would feed it.

Each case builds its inputs in a folder of its own and runs ``gslam``
in-process (``slam.cli.main``). Every case must end with

* exit code 1 (bad input) or 2 (bad arguments),
* exactly one error line (``gslam: error: ...``; warnings may precede it),
  containing what the case expects it to say,
* no traceback (an exception escaping ``main`` fails the case),
* no hang (each case has a time limit),
* no file of the user's changed, removed or added: checksums of the case
  folder, the shared run and the shipped configs before and after (so a
  half-written result or a leftover temporary folder fails the case too).

A few cases run as real processes as well, to show that nothing but the
error line reaches stderr. The corpus size and its result are printed by
``test_corpus_size``.
"""

from __future__ import annotations

import gzip
import hashlib
import json
import os
import random
import shutil
import signal
import subprocess
import sys
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import pytest
import yaml

from slam.cli import main
from tests.bagfactory import BagBuilder
from tests.conftest import CONFIGS, REPO, TELEMAX_CONFIG, short_scenario

TIME_LIMIT_S = 60
RANDOM = random.Random(11).randbytes(4096)


@dataclass(frozen=True)
class World:
    """Valid inputs the cases start from (never changed by a case)."""

    run: Path  # a simulated run folder
    scenario: Path  # its scenario YAML
    spec: Path  # a one-job ablation spec


@dataclass(frozen=True)
class Case:
    """``argv`` with ``{d}`` (the case folder), ``{run}``, ``{scen}``,
    ``{spec}``, ``{cfg}`` (configs/telemax.yaml) and ``{variants}``;
    ``make(d, world)`` writes the case's inputs; ``says``: a part of the
    error line."""

    id: str
    argv: tuple[str, ...]
    says: str
    make: Callable[[Path, World], None] | None = None
    code: int = 1


# --- input builders ------------------------------------------------------------------


def text(name: str, content: str) -> Callable[[Path, World], None]:
    def make(d: Path, world: World) -> None:
        (d / name).parent.mkdir(parents=True, exist_ok=True)
        (d / name).write_text(content)

    return make


def data(name: str, content: bytes) -> Callable[[Path, World], None]:
    def make(d: Path, world: World) -> None:
        (d / name).parent.mkdir(parents=True, exist_ok=True)
        (d / name).write_bytes(content)

    return make


def both(*makers: Callable[[Path, World], None]) -> Callable[[Path, World], None]:
    def make(d: Path, world: World) -> None:
        for m in makers:
            m(d, world)

    return make


def copy_run(change: Callable[[Path], None] | None = None) -> Callable[[Path, World], None]:
    """A copy of the run at ``{d}/run``, then ``change(run)``."""

    def make(d: Path, world: World) -> None:
        shutil.copytree(world.run, d / "run")
        if change is not None:
            change(d / "run")

    return make


def truncate(path: Path, fraction: float = 0.5) -> None:
    raw = path.read_bytes()
    path.write_bytes(raw[: int(len(raw) * fraction)])


def scenario(change: Callable[[dict], None]) -> Callable[[Path, World], None]:
    """The short scenario with ``change`` applied, at ``{d}/s.yaml``."""

    def make(d: Path, world: World) -> None:
        tree = yaml.safe_load(world.scenario.read_text())
        change(tree)
        (d / "s.yaml").write_text(yaml.safe_dump(tree, sort_keys=False))

    return make


def set_in(*path_value):
    *path, value = path_value

    def change(tree: dict) -> None:
        node = tree
        for k in path[:-1]:
            node = node[k]
        node[path[-1]] = value

    return change


def spec(**changes) -> Callable[[Path, World], None]:
    def make(d: Path, world: World) -> None:
        tree = yaml.safe_load(world.spec.read_text())
        tree.update(changes)
        (d / "spec.yaml").write_text(yaml.safe_dump(tree, sort_keys=False))

    return make


def ros1_bag(d: Path, world: World) -> None:
    bag = BagBuilder(ros=1)
    for k in range(20):
        bag.imu("/imu/data", t=100.0 + 0.01 * k, rate_z=0.1, yaw=0.3)
    bag.write(d / "r.bag")


def truncated_ros1_bag(d: Path, world: World) -> None:
    ros1_bag(d, world)
    truncate(d / "r.bag", 0.6)


def broad_mat(**fields) -> Callable[[Path, World], None]:
    def make(d: Path, world: World) -> None:
        import numpy as np
        from scipy.io import savemat

        base = {"imu_gyr": np.zeros((50, 3)), "imu_acc": np.tile([0, 0, 9.81], (50, 1)),
                "imu_mag": np.tile([0, 20, -40], (50, 1)), "opt_quat": np.tile([1, 0, 0, 0], (50, 1)),
                "opt_pos": np.zeros((50, 3)), "sampling_rate": np.array([[100.0]]),
                "movement": np.ones((50, 1), dtype=np.uint8)}
        base.update(fields)
        savemat(str(d / "t.mat"), {k: v for k, v in base.items() if v is not None})

    return make


def carmen_gz(d: Path, world: World) -> None:
    lines = [f"ODOM 0 0 0 0 0 0 {k} host {k}\nFLASER 3 1 2 3 0 0 0 0 0 0 {k} host {k}" for k in range(200)]
    (d / "c.log.gz").write_bytes(gzip.compress("\n".join(lines).encode()))


def symlink(name: str, to: str) -> Callable[[Path, World], None]:
    def make(d: Path, world: World) -> None:
        (d / to).mkdir(exist_ok=True)
        (d / name).symlink_to(d / to)

    return make


def foreign(name: str) -> Callable[[Path, World], None]:
    return text(f"{name}/notes.txt", "a user's notes\n")


def result_of(command: str, name: str) -> Callable[[Path, World], None]:
    return text(f"{name}/.gslam-result.json", json.dumps({"command": command}))


MAP = ("map", "{run}", "--config", "{cfg}")
YAML_BOMB = "a: &a [" + ",".join(["x"] * 10) + "]\n" + "".join(
    f"{chr(98 + i)}: &{chr(98 + i)} [" + ",".join([f"*{chr(97 + i)}"] * 10) + "]\n" for i in range(8)
)


# --- the corpus ------------------------------------------------------------------


CASES: list[Case] = [
    # -- configs (gslam map) --
    Case("config-random-bytes", (*MAP[:2], "--config", "{d}/c.yaml", "--out", "{d}/o"), "binary content", data("c.yaml", RANDOM)),
    Case("config-nul-bytes", (*MAP[:2], "--config", "{d}/c.yaml", "--out", "{d}/o"), "binary content", data("c.yaml", b"backend:\0\0")),
    Case("config-latin1", (*MAP[:2], "--config", "{d}/c.yaml", "--out", "{d}/o"), "not UTF-8", data("c.yaml", "# caf\xe9\n".encode("latin-1"))),
    Case("config-list", (*MAP[:2], "--config", "{d}/c.yaml", "--out", "{d}/o"), "expected a YAML mapping", text("c.yaml", "- 1\n- 2\n")),
    Case("config-scalar", (*MAP[:2], "--config", "{d}/c.yaml", "--out", "{d}/o"), "expected a YAML mapping", text("c.yaml", "42\n")),
    Case("config-syntax", (*MAP[:2], "--config", "{d}/c.yaml", "--out", "{d}/o"), "line 3: invalid YAML",
         text("c.yaml", "backend:\n  factors: [1, 2\n")),
    Case("config-nan", (*MAP[:2], "--config", "{d}/c.yaml", "--out", "{d}/o"), "backend.robust_param: expected a finite number",
         text("c.yaml", "backend:\n  robust_param: .nan\n")),
    Case("config-1e400", (*MAP[:2], "--config", "{d}/c.yaml", "--out", "{d}/o"), "keyframes.period_s: Input should be a finite number",
         text("c.yaml", "keyframes:\n  period_s: 1e400\n")),
    Case("config-wrong-type", (*MAP[:2], "--config", "{d}/c.yaml", "--out", "{d}/o"), "keyframes.period_s",
         text("c.yaml", "keyframes:\n  period_s: fast\n")),
    Case("config-negative-sigma", (*MAP[:2], "--config", "{d}/c.yaml", "--out", "{d}/o"), "sigma_yaw_deg",
         text("c.yaml", "backend:\n  factors:\n    compass: {sigma_yaw_deg: -1}\n")),
    Case("config-section-is-a-list", (*MAP[:2], "--config", "{d}/c.yaml", "--out", "{d}/o"), "frontend",
         text("c.yaml", "frontend: [1, 2]\n")),
    Case("config-unknown-key", (*MAP[:2], "--config", "{d}/c.yaml", "--out", "{d}/o"), "unknown config key 'colour'", text("c.yaml", "colour: red\n")),
    Case("config-python-tag", (*MAP[:2], "--config", "{d}/c.yaml", "--out", "{d}/o"), "invalid YAML",
         text("c.yaml", "a: !!python/object/apply:os.system ['true']\n")),
    Case("config-deep-nesting", (*MAP[:2], "--config", "{d}/c.yaml", "--out", "{d}/o"), "c.yaml", text("c.yaml", "[" * 5000 + "]" * 5000)),
    Case("config-alias-bomb", (*MAP[:2], "--config", "{d}/c.yaml", "--out", "{d}/o"), "expands to more than 1,000,000 values", text("c.yaml", YAML_BOMB)),
    Case("config-is-a-scenario", (*MAP[:2], "--config", "{scen}", "--out", "{d}/o"), "unknown config key"),
    Case("config-is-a-folder", (*MAP[:2], "--config", "{d}", "--out", "{d}/o"), "cannot read config"),
    Case("config-missing", (*MAP[:2], "--config", "{d}/none.yaml", "--out", "{d}/o"), "none.yaml: cannot read config"),
    Case("config-model-missing", (*MAP[:2], "--config", "{d}/c.yaml", "--out", "{d}/o"), "nope.yaml",
         text("c.yaml", "validation:\n  model: nope.yaml\n")),
    Case("config-model-random", (*MAP[:2], "--config", "{d}/c.yaml", "--out", "{d}/o"), "m.yaml",
         both(text("c.yaml", "validation:\n  model: m.yaml\n"), data("m.yaml", RANDOM))),
    Case("config-gating-on-without-model", (*MAP[:2], "--config", "{d}/c.yaml", "--out", "{d}/o", "--gating", "on"),
         "a system model is needed", text("c.yaml", "keyframes: {period_s: 0.5}\n")),
    # -- --set --
    Case("set-no-equals", (*MAP, "--out", "{d}/o", "--set", "backend.optimizer"), "--set backend.optimizer: expected KEY=VALUE"),
    Case("set-empty-key", (*MAP, "--out", "{d}/o", "--set", "=3"), "--set =3: expected KEY=VALUE"),
    Case("set-unknown-key", (*MAP, "--out", "{d}/o", "--set", "backend.optimiser=isam2"), "--set backend.optimiser=isam2: unknown config key"),
    Case("set-through-a-value", (*MAP, "--out", "{d}/o", "--set", "backend.optimizer.x=1"), "'backend.optimizer' is a value"),
    Case("set-inf", (*MAP, "--out", "{d}/o", "--set", "keyframes.period_s=.inf"),
         "--set keyframes.period_s=.inf: keyframes.period_s: expected a finite number, got .inf"),
    Case("set-nan", (*MAP, "--out", "{d}/o", "--set", "gating.inflation=.nan"), "--set gating.inflation=.nan"),
    Case("set-wrong-type", (*MAP, "--out", "{d}/o", "--set", "backend.max_iterations=many"), "--set backend.max_iterations=many"),
    Case("set-mode-maybe", (*MAP, "--out", "{d}/o", "--set", "validation.mode=maybe"), "--set validation.mode=maybe"),
    Case("set-observer-typo", (*MAP, "--out", "{d}/o", "--set", "validation.observers.typo=1"), "--set validation.observers.typo=1: "),
    Case("set-period-too-long", (*MAP, "--out", "{d}/o", "--set", "keyframes.period_s=1000"), "fewer than 2 keyframes"),
    Case("gating-invalid", (*MAP, "--out", "{d}/o", "--gating", "maybe"), "invalid choice", code=2),
    # -- recordings (gslam map) --
    Case("input-missing", ("map", "{d}/none", "--config", "{cfg}", "--out", "{d}/o"), "no such file or directory"),
    Case("input-empty-folder", ("map", "{d}/e", "--config", "{cfg}", "--out", "{d}/o"), "unknown recording format", text("e/.keep", "")),
    Case("input-junk-folder", ("map", "{d}/junk", "--config", "{cfg}", "--out", "{d}/o"), "unknown recording format",
         both(data("junk/a.bin", RANDOM), text("junk/b.txt", "hello\n"))),
    Case("input-folder-with-junk-db3", ("map", "{d}/junk", "--config", "{cfg}", "--out", "{d}/o"), "x.db3: not a readable ROS bag",
         data("junk/x.db3", RANDOM)),
    Case("input-folder-with-two-bags", ("map", "{d}/junk", "--config", "{cfg}", "--out", "{d}/o"), "it holds 2 entries (a.db3, b.bag)",
         both(data("junk/a.db3", RANDOM), data("junk/b.bag", RANDOM))),
    Case("run-truth-json-missing-t0", ("map", "{d}/junk", "--config", "{cfg}", "--out", "{d}/o"), "truth.json: t0: Field required",
         both(data("junk/bag/x.db3", RANDOM), text("junk/truth.json", "{}"))),
    Case("run-truth-json-deep", ("map", "{d}/run", "--config", "{cfg}", "--out", "{d}/o"), "truth.json",
         copy_run(lambda r: (r / "truth.json").write_text("[" * 100000 + "]" * 100000))),
    Case("run-truth-json-junk", ("map", "{d}/run", "--config", "{cfg}", "--out", "{d}/o"), "truth.json: binary content",
         copy_run(lambda r: (r / "truth.json").write_bytes(RANDOM[:200]))),
    Case("run-truth-json-empty", ("map", "{d}/run", "--config", "{cfg}", "--out", "{d}/o"), "truth.json",
         copy_run(lambda r: (r / "truth.json").write_text(""))),
    Case("run-truth-json-wrong-types", ("map", "{d}/run", "--config", "{cfg}", "--out", "{d}/o"), "truth.json: faults",
         copy_run(lambda r: (r / "truth.json").write_text('{"t0": 1700000000, "faults": "many"}'))),
    Case("run-truth-json-nan-t0", ("map", "{d}/run", "--config", "{cfg}", "--out", "{d}/o"), "truth.json: NaN is not a number",
         copy_run(lambda r: (r / "truth.json").write_text('{"t0": NaN}'))),
    Case("run-truth-json-interval-backwards", ("map", "{d}/run", "--config", "{cfg}", "--out", "{d}/o"), "ends before it starts",
         copy_run(lambda r: (r / "truth.json").write_text('{"t0": 1700000000, "faults": {"SM": [[5, 1]]}}'))),
    Case("run-db3-truncated", ("map", "{d}/run", "--config", "{cfg}", "--out", "{d}/o"), "bag",
         copy_run(lambda r: truncate(r / "bag" / "bag.db3", 0.3))),
    Case("run-db3-random", ("map", "{d}/run", "--config", "{cfg}", "--out", "{d}/o"), "bag",
         copy_run(lambda r: (r / "bag" / "bag.db3").write_bytes(RANDOM))),
    Case("run-db3-empty", ("map", "{d}/run", "--config", "{cfg}", "--out", "{d}/o"), "bag",
         copy_run(lambda r: (r / "bag" / "bag.db3").write_bytes(b""))),
    Case("run-metadata-junk", ("map", "{d}/run", "--config", "{cfg}", "--out", "{d}/o"), "bag",
         copy_run(lambda r: (r / "bag" / "metadata.yaml").write_bytes(RANDOM[:300]))),
    Case("ros1-random", ("map", "{d}/r.bag", "--config", "{cfg}", "--out", "{d}/o"), "not a readable ROS bag", data("r.bag", RANDOM)),
    Case("ros1-empty", ("map", "{d}/r.bag", "--config", "{cfg}", "--out", "{d}/o"), "not a readable ROS bag", data("r.bag", b"")),
    Case("ros1-truncated", ("map", "{d}/r.bag", "--config", "{cfg}", "--out", "{d}/o"), "r.bag", truncated_ros1_bag),
    Case("ros1-missing-topic", ("map", "{d}/r.bag", "--config", "{cfg}", "--out", "{d}/o"), "'/scan': not in the bag", ros1_bag),
    Case("mcap-random", ("map", "{d}/r.mcap", "--config", "{cfg}", "--out", "{d}/o"), "not a readable ROS bag", data("r.mcap", RANDOM)),
    Case("carmen-empty", ("map", "{d}/c.log", "--config", "{cfg}", "--out", "{d}/o"), "no FLASER", text("c.log", "")),
    Case("carmen-random", ("map", "{d}/c.log", "--config", "{cfg}", "--out", "{d}/o"), "binary", data("c.log", RANDOM)),
    Case("carmen-nan", ("map", "{d}/c.log", "--config", "{cfg}", "--out", "{d}/o"), "expected finite numbers",
         text("c.log", "ODOM 1.0 nan 0 0 0 0 1.0 host 1.0\n")),
    Case("carmen-stamps-after-2038", ("map", "{d}/c.log", "--config", "{cfg}", "--out", "{d}/o"), "what a ROS 2 time holds",
         text("c.log", "".join(f"ODOM 0 0 0 0 0 0 {3e9 + k} host {k}\nFLASER 3 1 2 3 0 0 0 0 0 0 {3e9 + k} host {k}\n"
                               for k in range(200)))),
    Case("carmen-stamps-before-1901", ("map", "{d}/c.log", "--config", "{cfg}", "--out", "{d}/o"), "what a ROS 2 time holds",
         text("c.log", "".join(f"ODOM 0 0 0 0 0 0 {-2.2e9 + k} host {k}\nFLASER 3 1 2 3 0 0 0 0 0 0 {-2.2e9 + k} host {k}\n"
                               for k in range(200)))),
    Case("librsf-stamps-after-2038", ("map", "{d}/X_Input.txt", "--config", "{cfg}", "--out", "{d}/o"), "what a ROS 2 time holds",
         text("X_Input.txt", "".join(f"odom2 {4e9 + 0.1 * k} 0.5 0 0 1 1 1\n" for k in range(50)))),
    Case("scenario-t0-after-2038", ("simulate", "{d}/s.yaml", "--out", "{d}/o"), "environment.t0_s",
         scenario(set_in("environment", "t0_s", 3e9))),
    Case("carmen-wrong-fields", ("map", "{d}/c.log", "--config", "{cfg}", "--out", "{d}/o"), "expected FLASER",
         text("c.log", "FLASER four 1.0\n")),
    Case("carmen-gz-truncated", ("map", "{d}/c.log.gz", "--config", "{cfg}", "--out", "{d}/o"), "truncated gzip file",
         both(carmen_gz, lambda d, w: truncate(d / "c.log.gz", 0.5))),
    Case("carmen-gz-random", ("map", "{d}/c.log.gz", "--config", "{cfg}", "--out", "{d}/o"), "not a valid gzip file", data("c.log.gz", RANDOM)),
    Case("broad-random", ("map", "{d}/t.mat", "--config", "{cfg}", "--out", "{d}/o"), "t.mat", data("t.mat", RANDOM)),
    Case("broad-empty", ("map", "{d}/t.mat", "--config", "{cfg}", "--out", "{d}/o"), "t.mat", data("t.mat", b"")),
    Case("broad-missing-field", ("map", "{d}/t.mat", "--config", "{cfg}", "--out", "{d}/o"), "imu_mag", broad_mat(imu_mag=None)),
    Case("broad-nan-rate", ("map", "{d}/t.mat", "--config", "{cfg}", "--out", "{d}/o"), "sampling_rate",
         broad_mat(sampling_rate=[[float("nan")]])),
    Case("broad-wrong-shape", ("map", "{d}/t.mat", "--config", "{cfg}", "--out", "{d}/o"), "N x 3 IMU arrays", broad_mat(imu_gyr=[[1.0, 2.0]])),
    Case("broad-short-field", ("map", "{d}/t.mat", "--config", "{cfg}", "--out", "{d}/o"), "imu_acc: expected shape (50, 3)",
         broad_mat(imu_acc=[[0.0, 0.0, 9.81]] * 20)),
    Case("librsf-empty", ("map", "{d}/X_Input.txt", "--config", "{cfg}", "--out", "{d}/o"), "X_Input.txt", text("X_Input.txt", "")),
    Case("librsf-random", ("map", "{d}/X_Input.txt", "--config", "{cfg}", "--out", "{d}/o"), "binary content", data("X_Input.txt", RANDOM)),
    Case("librsf-nan", ("map", "{d}/X_Input.txt", "--config", "{cfg}", "--out", "{d}/o"), "X_Input.txt",
         text("X_Input.txt", "odom2 0 0 0 0 1 1 1\nodom2 0.1 nan 0 0 1 1 1\n")),
    Case("librsf-wrong-columns", ("map", "{d}/X_Input.txt", "--config", "{cfg}", "--out", "{d}/o"), "expected odom2",
         text("X_Input.txt", "odom2 0 0 0 0 1 1 1\nodom2 0.1 0.5\n")),
    # -- --out of map --
    Case("map-out-is-a-file", (*MAP, "--out", "{d}/f.txt"), "exists and is not a folder", text("f.txt", "precious\n")),
    Case("map-out-is-the-input", ("map", "{d}/run", "--config", "{cfg}", "--out", "{d}/run"), "is the input", copy_run()),
    Case("map-out-holds-the-input", ("map", "{d}/run", "--config", "{cfg}", "--out", "{d}"), "holds the input", copy_run()),
    Case("map-out-inside-the-input", ("map", "{d}/run", "--config", "{cfg}", "--out", "{d}/run/m"), "inside the input folder", copy_run()),
    Case("map-out-holds-the-config", (*MAP[:2], "--config", "{d}/c/c.yaml", "--out", "{d}/c"), "holds the input",
         text("c/c.yaml", "keyframes: {period_s: 0.5}\n")),
    Case("map-out-foreign-folder", (*MAP, "--out", "{d}/mine"), "not a gslam map result", foreign("mine")),
    Case("map-out-other-result", (*MAP, "--out", "{d}/sim"), "a gslam simulate result, not a map result", result_of("simulate", "sim")),
    Case("map-out-proc", (*MAP, "--out", "/proc/gslam-x"), "cannot be written"),
    Case("map-out-under-a-file", (*MAP, "--out", "{d}/f.txt/o"), "f.txt", text("f.txt", "precious\n")),
    Case("map-out-symlink", (*MAP, "--out", "{d}/link"), "symbolic link", symlink("link", "target")),
    Case("map-out-root", (*MAP, "--out", "/"), "file system root"),
    # -- simulate --
    Case("scenario-random", ("simulate", "{d}/s.yaml", "--out", "{d}/o"), "binary content", data("s.yaml", RANDOM)),
    Case("scenario-empty", ("simulate", "{d}/s.yaml", "--out", "{d}/o"), "a scenario needs at least 'name' and 'robot'",
         text("s.yaml", "")),
    Case("scenario-nan-waypoint", ("simulate", "{d}/s.yaml", "--out", "{d}/o"), "robot.waypoints.1.0: expected a finite number",
         scenario(lambda t: t["robot"]["waypoints"].__setitem__(1, [float("nan"), 1.2]))),
    Case("scenario-inf-speed", ("simulate", "{d}/s.yaml", "--out", "{d}/o"), "robot.max_speed_m_s: expected a finite number",
         scenario(set_in("robot", "max_speed_m_s", float("inf")))),
    Case("scenario-one-point-wall", ("simulate", "{d}/s.yaml", "--out", "{d}/o"), "world.walls",
         scenario(lambda t: t["world"]["walls"].append([[0.0, 0.0]]))),
    Case("scenario-two-point-obstacle", ("simulate", "{d}/s.yaml", "--out", "{d}/o"), "world.obstacles",
         scenario(set_in("world", "obstacles", [[[0, 0], [1, 1]]]))),
    Case("scenario-one-waypoint", ("simulate", "{d}/s.yaml", "--out", "{d}/o"), "robot.waypoints",
         scenario(set_in("robot", "waypoints", [[1.0, 1.0]]))),
    Case("scenario-waypoints-wrong-type", ("simulate", "{d}/s.yaml", "--out", "{d}/o"), "robot.waypoints",
         scenario(set_in("robot", "waypoints", "abc"))),
    Case("scenario-slow-mission", ("simulate", "{d}/s.yaml", "--out", "{d}/o"), "the mission would take about 21.",
         scenario(set_in("robot", "max_speed_m_s", 0.0001))),
    Case("scenario-many-laps", ("simulate", "{d}/s.yaml", "--out", "{d}/o"), "at most",
         scenario(lambda t: t["robot"].update(waypoints=[[0, 0], [5, 0], [5, 5], [0, 0]], laps=1000))),
    Case("scenario-billion-laps", ("simulate", "{d}/s.yaml", "--out", "{d}/o"), "robot.laps: 1e+09 laps is above 1000 laps",
         scenario(lambda t: t["robot"].update(waypoints=[[0, 0], [5, 0], [5, 5], [0, 0]], laps=10**9))),
    Case("scenario-slow-turns", ("simulate", "{d}/s.yaml", "--out", "{d}/o"), "robot.max_turn_rate_deg_s 1e-06",
         scenario(set_in("robot", "max_turn_rate_deg_s", 1e-6))),
    Case("scenario-slow-turn-accel", ("simulate", "{d}/s.yaml", "--out", "{d}/o"), "the mission would take",
         scenario(lambda t: t["robot"].update(max_turn_accel_deg_s2=1e-9, start_yaw_deg=0.0))),  # a spot turn first
    Case("scenario-truth-rate", ("simulate", "{d}/s.yaml", "--out", "{d}/o"), "robot.truth_rate_hz",
         scenario(set_in("robot", "truth_rate_hz", 1e9))),
    Case("scenario-beams", ("simulate", "{d}/s.yaml", "--out", "{d}/o"), "sensors.laser",
         scenario(lambda t: t.setdefault("sensors", {}).setdefault("laser", {}).update(beams=10**8))),
    Case("scenario-negative-pause", ("simulate", "{d}/s.yaml", "--out", "{d}/o"), "pause",
         scenario(lambda t: t["robot"]["waypoints"].__setitem__(1, [1.0, 1.2, -3.0]))),
    Case("scenario-unknown-key", ("simulate", "{d}/s.yaml", "--out", "{d}/o"), "unknown scenario key 'robot.speed'",
         scenario(set_in("robot", "speed", 1.0))),
    Case("simulate-seed-text", ("simulate", "{scen}", "--out", "{d}/o", "--seed", "abc"), "expected a whole number", code=2),
    Case("simulate-seed-negative", ("simulate", "{scen}", "--out", "{d}/o", "--seed", "-1"), "expected 0 or more", code=2),
    Case("simulate-out-is-a-file", ("simulate", "{scen}", "--out", "{d}/f.txt"), "not a folder", text("f.txt", "precious\n")),
    Case("simulate-out-holds-the-scenario", ("simulate", "{d}/s/s.yaml", "--out", "{d}/s"), "holds the input",
         lambda d, w: (d / "s").mkdir() or shutil.copy(w.scenario, d / "s" / "s.yaml")),
    Case("simulate-out-foreign", ("simulate", "{scen}", "--out", "{d}/mine"), "not a gslam simulate result", foreign("mine")),
    Case("simulate-out-proc", ("simulate", "{scen}", "--out", "/proc/gslam-x"), "cannot be written"),
    # -- compare --
    Case("compare-variants-random", ("compare", "{run}", "--config", "{cfg}", "--out", "{d}/o", "--variants", "{d}/v.yaml"),
         "binary content", data("v.yaml", RANDOM)),
    Case("compare-variant-not-a-mapping", ("compare", "{run}", "--config", "{cfg}", "--out", "{d}/o", "--variants", "{d}/v.yaml"),
         "variant 'a': expected a mapping", text("v.yaml", "a: 3\n")),
    Case("compare-variant-bad-key", ("compare", "{run}", "--config", "{cfg}", "--out", "{d}/o", "--variants", "{d}/v.yaml"),
         "v.yaml: variant 'a': backend.optimiser=isam2: unknown config key", text("v.yaml", "a: {backend.optimiser: isam2}\n")),
    Case("compare-only-unknown", ("compare", "{run}", "--config", "{cfg}", "--out", "{d}/o", "--only", "nope"), "unknown variant 'nope'"),
    Case("compare-out-is-the-input", ("compare", "{d}/run", "--config", "{cfg}", "--out", "{d}/run"), "is the input", copy_run()),
    Case("compare-out-inside-the-input", ("compare", "{d}/run", "--config", "{cfg}", "--out", "{d}/run/cmp"),
         "inside the input folder", copy_run()),
    Case("compare-out-is-a-file", ("compare", "{run}", "--config", "{cfg}", "--out", "{d}/f.txt"), "not a folder", text("f.txt", "x\n")),
    Case("compare-out-map-result", ("compare", "{run}", "--config", "{cfg}", "--out", "{d}/m"), "a gslam map result, not a compare result",
         result_of("map", "m")),
    # -- demo --
    Case("demo-out-is-a-file", ("demo", "--out", "{d}/f.txt"), "not a folder", text("f.txt", "x\n")),
    Case("demo-scenario-random", ("demo", "--out", "{d}/o", "--scenario", "{d}/s.yaml"), "binary content", data("s.yaml", RANDOM)),
    Case("demo-out-holds-the-scenario", ("demo", "--out", "{d}", "--scenario", "{d}/s.yaml"), "holds the input",
         lambda d, w: shutil.copy(w.scenario, d / "s.yaml")),
    Case("demo-out-foreign", ("demo", "--out", "{d}/mine"), "not a gslam demo result", foreign("mine")),
    # -- ablate --
    Case("ablate-spec-random", ("ablate", "{d}/spec.yaml", "--out", "{d}/o"), "binary content", data("spec.yaml", RANDOM)),
    Case("ablate-spec-empty", ("ablate", "{d}/spec.yaml", "--out", "{d}/o"), "spec.yaml", text("spec.yaml", "")),
    Case("ablate-spec-unknown-key", ("ablate", "{d}/spec.yaml", "--out", "{d}/o"), "variant", spec(variant={"a": {}})),
    Case("ablate-spec-nan-sweep", ("ablate", "{d}/spec.yaml", "--out", "{d}/o"), "expected a finite number",
         spec(sweep={"grid": {"gating.inflation": [float("nan")]}})),
    Case("ablate-spec-inf-scenario-key", ("ablate", "{d}/spec.yaml", "--out", "{d}/o"), "expected a finite number",
         spec(sweep={"grid": {"scenario.robot.max_speed_m_s": [float("inf")]}})),
    Case("ablate-spec-slow-scenario", ("ablate", "{d}/spec.yaml", "--out", "{d}/o"), "the mission would take",
         spec(sweep={"grid": {"scenario.robot.max_speed_m_s": [0.0001]}})),
    Case("ablate-recorded-glob-empty", ("ablate", "{d}/spec.yaml", "--out", "{d}/o"), "nothing*.bag",
         spec(inputs={"recorded": [{"path": "nothing*.bag"}]})),
    Case("ablate-negative-seed", ("ablate", "{d}/spec.yaml", "--out", "{d}/o"), "seeds",
         lambda d, w: spec(inputs={"scenarios": [{"path": str(w.scenario), "seeds": [-1]}]})(d, w)),
    Case("ablate-scenario-name-absolute", ("ablate", "{d}/spec.yaml", "--out", "{d}/o"), "a scenario's name names its run folders",
         lambda d, w: (scenario(set_in("name", "/tmp/gslam-escape"))(d, w),
                       spec(inputs={"scenarios": [{"path": str(d / "s.yaml"), "seeds": [1]}]})(d, w))),
    Case("ablate-scenario-name-slash", ("ablate", "{d}/spec.yaml", "--out", "{d}/o"), "a scenario's name names its run folders",
         spec(sweep={"grid": {"scenario.name": ["../escape"]}})),
    Case("scenario-name-dots", ("simulate", "{d}/s.yaml", "--out", "{d}/o"), "name: '..': a scenario's name",
         scenario(set_in("name", ".."))),
    Case("ablate-ray-address-closed", ("ablate", "{spec}", "--backend", "ray", "--address", "127.0.0.1:9", "--out", "{d}/o"),
         "no Ray cluster answers there"),
    Case("ablate-workers-zero", ("ablate", "{spec}", "--out", "{d}/o", "--workers", "0"), "expected 1 or more", code=2),
    Case("ablate-out-is-a-file", ("ablate", "{spec}", "--out", "{d}/f.txt"), "not a folder", text("f.txt", "x\n")),
    Case("ablate-out-holds-the-spec", ("ablate", "{d}/spec.yaml", "--out", "{d}"), "holds the input", spec()),
    Case("ablate-out-foreign", ("ablate", "{spec}", "--out", "{d}/mine"), "not a gslam ablate result", foreign("mine")),
    Case("ablate-out-proc", ("ablate", "{spec}", "--out", "/proc/gslam-x"), "cannot be written"),
    # -- inject --
    Case("inject-unknown-kind", ("inject", "{run}", "--fault", "magnet@1:2", "--out", "{d}/o"), "unknown fault kind 'magnet'"),
    Case("inject-no-fault", ("inject", "{run}", "--out", "{d}/o"), "no fault given"),
    Case("inject-unknown-param", ("inject", "{run}", "--fault", "gyro_bias@1:2,bias=3", "--out", "{d}/o"),
         "unknown parameter 'bias' of gyro_bias"),
    Case("inject-nan-time", ("inject", "{run}", "--fault", "gyro_bias@nan:2", "--out", "{d}/o"), "start_s"),
    Case("inject-reversed", ("inject", "{run}", "--fault", "slip@5:2", "--out", "{d}/o"), "must end after it starts"),
    Case("inject-after-the-end", ("inject", "{run}", "--fault", "gyro_bias@1000:1001", "--out", "{d}/o"),
         "starts after the recording ends"),
    Case("inject-no-such-sensor", ("inject", "{d}/c.log.gz", "--fault", "dipole@10:20", "--out", "{d}/o"),
         "a CARMEN log has a laser and odometry only", carmen_gz),
    Case("inject-librsf", ("inject", "{d}/X_Input.txt", "--fault", "slip@0:1", "--out", "{d}/o"), "not libRSF",
         text("X_Input.txt", "odom2 0 0 0 0 1 1 1\nodom2 0.1 0 0 0 1 1 1\n")),
    Case("inject-random-bag", ("inject", "{d}/r.bag", "--fault", "gyro_bias@1:2", "--out", "{d}/o"),
         "not a readable ROS bag", data("r.bag", RANDOM)),
    Case("inject-bad-config", ("inject", "{run}", "--config", "{d}/c.yaml", "--fault", "gyro_bias@1:2", "--out", "{d}/o"),
         "unknown config key 'input.topic'", text("c.yaml", "input: {topic: {}}\n")),
    Case("inject-out-is-the-input", ("inject", "{d}/run", "--fault", "gyro_bias@1:2", "--out", "{d}/run"), "is the input",
         copy_run()),
    Case("inject-out-foreign", ("inject", "{run}", "--fault", "gyro_bias@1:2", "--out", "{d}/mine"),
         "not a gslam inject result", foreign("mine")),
    # -- calibrate --
    Case("calibrate-out-exists", ("calibrate", "{run}", "--config", "{cfg}", "--out", "{d}/c.yaml"),
         "not a gslam calibrate result", text("c.yaml", "mine\n")),
    Case("calibrate-out-is-the-config", ("calibrate", "{run}", "--config", "{d}/c.yaml", "--out", "{d}/c.yaml"), "is the input",
         lambda d, w: shutil.copy(TELEMAX_CONFIG, d / "c.yaml")),
    Case("calibrate-out-is-a-folder", ("calibrate", "{run}", "--config", "{cfg}", "--out", "{d}"), "is a folder"),
    Case("calibrate-out-under-a-file", ("calibrate", "{run}", "--config", "{cfg}", "--out", "{d}/f.txt/sub/c.yaml"),
         "f.txt is not a folder", text("f.txt", "mine\n")),
    Case("calibrate-clean-reversed", ("calibrate", "{run}", "--config", "{cfg}", "--clean", "9:3", "--out", "{d}/c.yaml"),
         "--clean 9:3"),
    Case("calibrate-clean-outside", ("calibrate", "{run}", "--config", "{cfg}", "--clean", "900:end", "--out", "{d}/c.yaml"),
         "holds no validation step"),
    Case("calibrate-false-alarm-nan", ("calibrate", "{run}", "--config", "{cfg}", "--false-alarm", "nan", "--out", "{d}/c.yaml"),
         "--false-alarm"),
    Case("calibrate-random-bag", ("calibrate", "{d}/r.bag", "--config", "{cfg}", "--out", "{d}/c.yaml"),
         "not a readable ROS bag", data("r.bag", RANDOM)),
    # -- inspect --
    Case("inspect-random-bag", ("inspect", "{d}/r.bag"), "not a readable ROS bag", data("r.bag", RANDOM)),
    Case("inspect-junk-folder", ("inspect", "{d}/junk"), "unknown recording format", data("junk/a.bin", RANDOM)),
    Case("inspect-missing", ("inspect", "{d}/none.bag"), "no such file"),
    Case("inspect-config-out-exists", ("inspect", "{run}", "--config-out", "{d}/c.yaml"), "exists", text("c.yaml", "mine\n")),
    Case("inspect-config-out-is-the-input", ("inspect", "{d}/r.bag", "--config-out", "{d}/r.bag"), "is the input", ros1_bag),
    Case("inspect-config-out-under-a-file", ("inspect", "{run}", "--config-out", "{d}/f.txt/c.yaml"), "f.txt is not a folder",
         text("f.txt", "mine\n")),
    # -- the command line itself --
    Case("unknown-command", ("frobnicate",), "invalid choice", code=2),
    Case("map-without-config", ("map", "{run}", "--out", "{d}/o"), "--config", code=2),
]


# --- running a case ----------------------------------------------------------------


def checksums(*roots: Path) -> dict[str, str]:
    """Every file (and folder) under ``roots``, with its content's hash."""
    out = {}
    for root in roots:
        for p in sorted(root.rglob("*")):
            if p.is_symlink() or p.is_dir():
                out[str(p)] = "->" + os.readlink(p) if p.is_symlink() else "dir"
            else:
                out[str(p)] = hashlib.sha1(p.read_bytes()).hexdigest()
    return out


@contextmanager
def time_limit(seconds: int) -> Iterator[None]:
    def hang(signum, frame):
        raise TimeoutError(f"no answer within {seconds} s")

    old = signal.signal(signal.SIGALRM, hang)
    signal.alarm(seconds)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, old)


@pytest.fixture(scope="module")
def world(tmp_path_factory: pytest.TempPathFactory, short_run) -> World:
    root = tmp_path_factory.mktemp("world")
    run = root / "run"
    shutil.copytree(short_run.run_dir, run)
    scen = root / "short.yaml"
    scen.write_text(yaml.safe_dump(short_scenario().model_dump(mode="json"), sort_keys=False))
    spec_path = root / "spec.yaml"
    spec_path.write_text(yaml.safe_dump({
        "name": "fuzz", "config": str(TELEMAX_CONFIG),
        "inputs": {"scenarios": [{"path": str(scen), "seeds": [1]}]},
        "variants": {"ungated": {"validation.mode": "off"}},
    }, sort_keys=False))
    return World(run, scen, spec_path)


def expand(argv: tuple[str, ...], d: Path, world: World) -> list[str]:
    names = {"d": d, "run": world.run, "scen": world.scenario, "spec": world.spec, "cfg": TELEMAX_CONFIG,
             "variants": CONFIGS / "variants.yaml"}
    return [a.format(**names) for a in argv]


def check_error_output(code: int, err: str, case: Case) -> None:
    lines = err.splitlines()
    assert "Traceback" not in err, err
    errors = [ln for ln in lines if ": error: " in ln]
    assert len(errors) == 1, err
    assert case.says in errors[0], f"expected {case.says!r} in: {errors[0]}"
    if code == 1:
        assert errors[0].startswith("gslam: error: ")
        assert all(ln.startswith("WARNING ") for ln in lines if ln not in errors), err
    else:  # argparse: usage, then the error line
        assert lines[-1] == errors[0] and lines[0].startswith("usage: gslam")


def prepare(case: Case, world: World, tmp_path: Path, fingerprint=None):
    """The case's folder with its inputs made, the places a failed command
    must leave as they were, and their fingerprint before it runs
    (``fingerprint``, :func:`checksums` by default)."""
    d = tmp_path / "case"
    d.mkdir()
    if case.make is not None:
        case.make(d, world)
    watched = (d, world.run, world.scenario.parent, CONFIGS)
    return d, watched, (fingerprint or checksums)(*watched)


def run_case(case: Case, world: World, tmp_path: Path, capsys, fingerprint=None, time_limit_s: int = TIME_LIMIT_S):
    """Run ``case`` as ``gslam -q ...`` in this process and check what a
    refused command must do: exit ``case.code``, one error line saying
    ``case.says``, no traceback, its inputs and ``--out``'s surroundings as
    they were (by ``fingerprint``, :func:`checksums` by default)."""
    fingerprint = fingerprint or checksums
    d, watched, before = prepare(case, world, tmp_path, fingerprint)
    capsys.readouterr()
    with time_limit(time_limit_s):
        try:
            code = main(["-q", *expand(case.argv, d, world)])
        except SystemExit as e:  # argparse
            code = e.code
    out, err = capsys.readouterr()
    assert code == case.code, f"exit {code}, stdout: {out[-500:]}, stderr: {err[-500:]}"
    check_error_output(code, err, case)
    assert fingerprint(*watched) == before, "an input changed, or something was left behind"


@pytest.mark.parametrize("case", CASES, ids=[c.id for c in CASES])
def test_malformed_input_gives_one_clean_error(case: Case, world: World, tmp_path: Path, capsys):
    run_case(case, world, tmp_path, capsys)
    assert not Path("/proc/gslam-x").exists()


def test_corpus_size():
    assert len(CASES) >= 60
    commands = {c.argv[0] for c in CASES}
    assert {"simulate", "map", "compare", "demo", "ablate", "inspect", "inject", "calibrate"} <= commands


# --- real processes: nothing but the error line reaches stderr ---------------------


PROCESS_CASES = ["config-random-bytes", "scenario-nan-waypoint", "map-out-proc", "map-out-is-the-input",
                 "compare-out-is-a-file", "ablate-out-is-a-file"]


@pytest.mark.slow
@pytest.mark.parametrize("case_id", PROCESS_CASES)
def test_as_a_process(case_id: str, world: World, tmp_path: Path):
    case = next(c for c in CASES if c.id == case_id)
    d = tmp_path / "case"
    d.mkdir()
    if case.make is not None:
        case.make(d, world)
    before = checksums(d, world.run)
    done = subprocess.run([sys.executable, "-m", "slam.cli", *expand(case.argv, d, world)], cwd=tmp_path,
                          capture_output=True, text=True, timeout=TIME_LIMIT_S,
                          env={**os.environ, "PYTHONPATH": str(REPO)})
    assert done.returncode == case.code
    assert done.stdout == ""
    assert done.stderr.startswith("gslam: error: ") and done.stderr.count("\n") == 1, done.stderr
    assert case.says in done.stderr
    assert checksums(d, world.run) == before
