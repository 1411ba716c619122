"""The commands, flags, configs and specs attacked as a user would misuse
them, after tests/test_fuzz.py and tests/test_hostile.py:

* a topic of one stream set to another stream's topic (the scan on the IMU's
  topic, the gyro on the laser's), whose messages are of another type;
* a flag that takes one value given twice (``--out a --out b``): argparse
  keeps the last in silence, where ``--set`` given twice is refused;
* a flag that only one choice of another flag reads (``--address`` without
  ``--backend ray``), ignored in silence;
* an ablation spec whose random integers no 64-bit integer holds, or that
  sets or sweeps ``scenario.seed``, which each job's own seed replaced in
  silence while summary.md showed the swept value;
* scenario worlds of a door that cuts no wall, two regions of one name, an
  obstacle or a region of no area;
* config numbers without a physical bound: RPE deltas (refused after the
  mapping, naming no key), negative or endless stream gaps, clock offsets
  no ROS time holds, a compass error correlated for 1e308 s, a submap or a
  loop search of 1e308 m, a validation rate of 1e308 Hz;
* scenario, ablation spec and fault numbers without a bound: 1e20 laps, a
  pause of 1e308 s, a seed beyond 64 bits or below 0, 1e20 seeds or random
  samples, a random range to 1e308, a fault from 1e308 s or from -1 s.

Each case runs as tests/test_fuzz.py's do: exit 1 or 2, one error line
saying what the case expects, no traceback, nothing outside ``--out``
changed (the case folder, the shared run, the scenario's folder and the
shipped configs are checksummed before and after), no hang.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from tests.conftest import REPO
from tests.test_fuzz import (  # noqa: F401 - world is a fixture
    Case, World, expand, run_case, scenario, set_in, spec, text, world,
)
from tests.test_hostile import checksums

pytestmark = pytest.mark.slow  # end to end: pytest -m 'not slow' leaves it out

TIME_LIMIT_S = 60
MAP = ("map", "{run}", "--config", "{cfg}")
QUICK = ("--set", "output.plots=false")
SIM = ("simulate", "{d}/s.yaml", "--out", "{d}/o")
ABLATE = ("ablate", "{d}/spec.yaml", "--out", "{d}/o", "--workers", "1")
CAL = ("calibrate", "{run}", "--config", "{cfg}")


def _map_set(*overrides: str) -> tuple[str, ...]:
    return (*MAP, *QUICK, *(a for kv in overrides for a in ("--set", kv)), "--out", "{d}/o")


def _map_cases(*rows: tuple[str, str, str]) -> list[Case]:
    """A case of ``gslam map`` with one ``--set`` per ``(id, KEY=VALUE, says)``."""
    return [Case(case_id, _map_set(override), says) for case_id, override, says in rows]


def _world(change):
    return scenario(lambda t: change(t["world"]))


CASES: list[Case] = [
    # -- a stream's topic set to another stream's, of another message type --
    *_map_cases(
        ("scan-topic-is-the-imus", "input.topics.scan=/imu/data",
         "scan topic '/imu/data': type is sensor_msgs/msg/Imu, expected sensor_msgs/msg/LaserScan"),
        ("gyro-topic-is-the-lasers", "input.topics.gyro=/scan",
         "gyro topic '/scan': type is sensor_msgs/msg/LaserScan, expected sensor_msgs/msg/Imu"),
        ("odometry-topic-is-the-imus", "input.topics.odometry=/imu/data",
         "odometry topic '/imu/data': type is sensor_msgs/msg/Imu"),
        ("compass-topic-is-the-odometrys", "input.topics.compass=/odom",
         "compass topic '/odom': type is nav_msgs/msg/Odometry"),
    ),
    Case("calibrate-scan-topic-is-the-imus", (*CAL, "--set", "input.topics.scan=/imu/data", "--out", "{d}/c.yaml"),
         "scan topic '/imu/data': type is sensor_msgs/msg/Imu"),
    # -- a flag of one value given twice --
    Case("map-out-twice", (*MAP, *QUICK, "--out", "{d}/a", "--out", "{d}/b"), "argument --out: given twice", code=2),
    Case("map-gating-twice", (*MAP, *QUICK, "--gating", "on", "--gating", "off", "--out", "{d}/o"),
         "argument --gating: given twice", code=2),
    Case("map-config-twice", (*MAP, "--config", "{cfg}", "--out", "{d}/o"), "argument --config: given twice", code=2),
    Case("map-out-twice-as-equals", (*MAP, "--out={d}/a", "--out={d}/b"), "argument --out: given twice", code=2),
    Case("compare-only-twice", ("compare", "{run}", "--config", "{cfg}", "--only", "gated", "--only", "ungated",
                                "--out", "{d}/o"), "argument --only: given twice", code=2),
    Case("compare-variants-twice", ("compare", "{run}", "--config", "{cfg}", "--variants", "{variants}",
                                    "--variants", "{variants}", "--out", "{d}/o"), "argument --variants: given twice",
         code=2),
    Case("simulate-seed-twice", ("simulate", "{scen}", "--seed", "1", "--seed", "2", "--out", "{d}/o"),
         "argument --seed: given twice", code=2),
    Case("demo-out-twice", ("demo", "--out", "{d}/a", "--out", "{d}/b"), "argument --out: given twice", code=2),
    Case("ablate-workers-twice", ("ablate", "{spec}", "--workers", "1", "--workers", "2", "--out", "{d}/o"),
         "argument --workers: given twice", code=2),
    Case("ablate-backend-twice", ("ablate", "{spec}", "--backend", "ray", "--backend", "local", "--out", "{d}/o"),
         "argument --backend: given twice", code=2),
    Case("calibrate-clean-twice", (*CAL, "--clean", "0:5", "--clean", "10:20", "--out", "{d}/c.yaml"),
         "argument --clean: given twice", code=2),
    Case("calibrate-false-alarm-twice", (*CAL, "--false-alarm", "0.01", "--false-alarm", "0.02", "--out", "{d}/c.yaml"),
         "argument --false-alarm: given twice", code=2),
    Case("calibrate-lag-reference-twice", (*CAL, "--lag-reference", "gyro", "--lag-reference", "none",
                                           "--out", "{d}/c.yaml"), "argument --lag-reference: given twice", code=2),
    Case("inspect-config-out-twice", ("inspect", "{run}", "--config-out", "{d}/a.yaml", "--config-out", "{d}/b.yaml"),
         "argument --config-out: given twice", code=2),
    Case("inject-config-twice", ("inject", "{run}", "--config", "{cfg}", "--config", "{cfg}", "--fault",
                                 "gyro_bias@2:4", "--out", "{d}/o"), "argument --config: given twice", code=2),
    # -- a flag only another flag's choice reads --
    Case("ablate-address-without-ray", ("ablate", "{spec}", "--address", "auto", "--out", "{d}/o"),
         "--address auto: a Ray cluster's address, but --backend is local"),
    Case("ablate-address-with-local", ("ablate", "{spec}", "--backend", "local", "--address", "10.0.0.1:6379",
                                       "--out", "{d}/o"), "--address 10.0.0.1:6379: a Ray cluster's address"),
    # -- ablation specs --
    Case("ablate-random-integer-beyond-int64", ABLATE, "sweep.random.params.backend.max_iterations.integer",
         spec(sweep={"random": {"samples": 2, "params": {"backend.max_iterations": {"integer": [1, 10**23]}}}})),
    Case("ablate-random-integer-below-int64", ABLATE, "sweep.random.params.backend.max_iterations.integer",
         spec(sweep={"random": {"samples": 2, "params": {"backend.max_iterations": {"integer": [-10**23, 5]}}}})),
    Case("ablate-set-scenario-seed", ABLATE, "scenario.seed: a job's seed is its input's",
         spec(set={"scenario.seed": 3})),
    Case("ablate-sweep-scenario-seed", ABLATE, "scenario.seed: a job's seed is its input's",
         spec(sweep={"grid": {"scenario.seed": [3, 4]}})),
    Case("ablate-variant-scenario-seed", ABLATE, "scenario.seed: a job's seed is its input's",
         spec(variants={"a": {"scenario.seed": 7}})),
    Case("ablate-set-rpe-delta-negative", ABLATE, "evaluation.rpe_deltas_m.0",
         spec(set={"evaluation.rpe_deltas_m": [-1.0]})),
    # -- scenario worlds --
    Case("scenario-door-in-no-wall", SIM, "world.doors.2: the door at (500, 500) cuts no wall",
         _world(lambda w: w["doors"].append({"center": [500.0, 500.0], "width_m": 1.0}))),
    Case("scenario-door-beside-a-wall", SIM, "world.doors.2: the door at (12.5, 3.5) cuts no wall",
         _world(lambda w: w["doors"].append({"center": [12.5, 3.5], "width_m": 0.5}))),
    Case("scenario-two-regions-of-one-name", SIM, "world: regions.3.name: 'lab' names regions.0 too",
         _world(lambda w: w["regions"].append(dict(w["regions"][0])))),
    Case("scenario-default-region-named-as-a-region", SIM, "world: default_region.name: 'lab' names regions.0 too",
         _world(lambda w: w["default_region"].update(name="lab"))),
    Case("scenario-obstacle-of-no-area", SIM, "world: obstacles.13: its points enclose no area",
         _world(lambda w: w["obstacles"].append([[1.0, 1.0], [2.0, 2.0], [3.0, 3.0]]))),
    Case("scenario-obstacle-one-point-thrice", SIM, "world: obstacles.13: its points enclose no area",
         _world(lambda w: w["obstacles"].append([[1.0, 1.0], [1.0, 1.0], [1.0, 1.0]]))),
    Case("scenario-region-of-no-area", SIM, "world: regions.3.polygon: its points enclose no area",
         _world(lambda w: w["regions"].append({"name": "flat", "kind": "indoor", "slip": 0.01,
                                               "polygon": [[0, 0], [1, 1], [2, 2]]}))),
    # -- config numbers without a physical bound --
    Case("rpe-delta-in-a-config-file", (*MAP[:2], "--config", "{d}/c.yaml", *QUICK, "--out", "{d}/o"),
         "c.yaml: evaluation.rpe_deltas_m.0", text("c.yaml", "evaluation: {rpe_deltas_m: [-1]}\n")),
    *_map_cases(
        ("rpe-delta-negative", "evaluation.rpe_deltas_m=[-5]",
         "--set evaluation.rpe_deltas_m=[-5]: evaluation.rpe_deltas_m.0: Input should be greater than 0"),
        ("rpe-delta-zero", "evaluation.rpe_deltas_m=[5, 0]", "evaluation.rpe_deltas_m.1"),
        ("rpe-delta-1e308", "evaluation.rpe_deltas_m=[1e308]", "evaluation.rpe_deltas_m.0: 1e+308 m is above"),
        ("stream-gap-negative", "validation.observers.stream_max_gap_s.gps_speed=-1",
         "validation.observers.stream_max_gap_s.gps_speed"),
        ("stream-gap-zero", "validation.observers.stream_max_gap_s.gps_sigma=0",
         "validation.observers.stream_max_gap_s.gps_sigma"),
        ("stream-gap-1e308", "validation.observers.stream_max_gap_s.gps_speed=1e308",
         "validation.observers.stream_max_gap_s.gps_speed"),
        ("time-offset-1e308", "input.time_offsets_s.gps=1e308", "input.time_offsets_s.gps: 1e+308 s is above"),
        ("time-offset-minus-1e300", "input.time_offsets_s.groundtruth=-1e300",
         "input.time_offsets_s.groundtruth: -1e+300 s is below"),
        ("extra-odometry-offset-1e308", "input.extra_odometry.vo={{topic: /odom, time_offset_s: 1e308}}",
         "input.extra_odometry.vo.time_offset_s: 1e+308 s is above"),
        ("compass-correlation-1e308", "backend.factors.compass.correlation_s=1e308",
         "backend.factors.compass.correlation_s: 1e+308 s is above"),
        ("compass-correlation-1e-300", "backend.factors.compass.correlation_s=1e-300",
         "backend.factors.compass.correlation_s: 1e-300 s is below"),
        # loops, submaps and the validation sections' numbers, bounded since (tests/test_config_bounds.py)
        ("submap-length-1e308", "submaps.length_m=1e308", "submaps.length_m: 1e+308 m is above 1e+06 m"),
        ("loop-separation-1e308", "loops.min_separation_m=1e308", "loops.min_separation_m: 1e+308 m is above"),
        ("validation-rate-1e308", "validation.rate_hz=1e308", "validation.rate_hz: 1e+308 Hz is above 10000 Hz"),
        ("gating-baseline-1e308", "gating.baseline_m=1e308", "gating.baseline_m: 1e+308 m is above"),
    ),
    # -- scenario, ablation spec and fault numbers without a bound (tests/test_config_bounds.py walks them since) --
    Case("scenario-laps-1e20", SIM, "s.yaml: robot.laps: 1e+20 laps is above 1000 laps",
         scenario(lambda t: t["robot"].update(waypoints=[[0, 0], [5, 0], [5, 5], [0, 0]], laps=10**20))),
    Case("scenario-laps-0", SIM, "s.yaml: robot.laps: 0 laps is below 1 laps", scenario(set_in("robot", "laps", 0))),
    Case("scenario-start-pause-1e308", SIM, "s.yaml: robot.start_pause_s: 1e+308 s is above 14400 s",
         scenario(set_in("robot", "start_pause_s", 1e308))),
    Case("scenario-end-pause-negative", SIM, "s.yaml: robot.end_pause_s: Input should be greater than or equal to 0",
         scenario(set_in("robot", "end_pause_s", -1.0))),
    Case("scenario-waypoint-pause-1e308", SIM,
         "s.yaml: robot.waypoints: waypoint 1's pause (third value) 1e+308 s is above 14400 s",
         scenario(lambda t: t["robot"]["waypoints"].__setitem__(1, [*t["robot"]["waypoints"][1][:2], 1e308]))),
    Case("scenario-seed-beyond-64-bits", SIM, "s.yaml: seed: 18446744073709551616 is above 18446744073709551615",
         scenario(set_in("seed", 2**64))),
    Case("scenario-seed-negative", SIM, "s.yaml: seed: -1 is below 0", scenario(set_in("seed", -1))),
    Case("scenario-laser-min-range-1e308", SIM, "s.yaml: sensors.laser.min_range_m: 1e+308 m is above 1000 m",
         scenario(lambda t: t.setdefault("sensors", {}).setdefault("laser", {}).update(min_range_m=1e308))),
    Case("scenario-disturber-direction-1e308", SIM, "s.yaml: world.disturbers.0.direction.0: 1e+308 is above 1e+06",
         _world(lambda w: w.__setitem__("disturbers", [{"name": "steel", "position": [1.0, 1.0, 0.5],
                                                          "moment_A_m2": 10.0, "direction": [1e308, 0.0, 0.0]}]))),
    Case("simulate-seed-flag-beyond-64-bits", ("simulate", "{scen}", "--seed", str(2**64), "--out", "{d}/o"),
         "argument --seed: expected at most 18446744073709551615", code=2),
    Case("ablate-seed-list-beyond-64-bits", ABLATE,
         "spec.yaml: inputs.scenarios.0.seeds.0: 18446744073709551616 is above 18446744073709551615",
         lambda d, w: spec(inputs={"scenarios": [{"path": str(w.scenario), "seeds": [2**64]}]})(d, w)),
    Case("ablate-seed-range-past-64-bits", ABLATE,
         "spec.yaml: inputs.scenarios.0.seeds: the last seed, 18446744073709551616, is above 18446744073709551615",
         lambda d, w: spec(inputs={"scenarios": [{"path": str(w.scenario), "seeds": {"first": 2**64 - 1,
                                                                                   "count": 2}}]})(d, w)),
    Case("ablate-seed-count-1e20", ABLATE, "spec.yaml: inputs.scenarios.0.seeds.count: 1e+20 is above 1e+06",
         lambda d, w: spec(inputs={"scenarios": [{"path": str(w.scenario), "seeds": {"count": 10**20}}]})(d, w)),
    Case("ablate-random-samples-1e20", ABLATE, "spec.yaml: sweep.random.samples: 1e+20 is above 1e+06",
         spec(sweep={"random": {"samples": 10**20, "params": {"gating.inflation": {"uniform": [1, 5]}}}})),
    Case("ablate-random-samples-0", ABLATE, "spec.yaml: sweep.random.samples: 0 is below 1",
         spec(sweep={"random": {"samples": 0, "params": {"gating.inflation": {"uniform": [1, 5]}}}})),
    Case("ablate-random-seed-negative", ABLATE, "spec.yaml: sweep.random.seed: -1 is below 0",
         spec(sweep={"random": {"samples": 2, "seed": -1, "params": {"gating.inflation": {"uniform": [1, 5]}}}})),
    Case("ablate-random-uniform-1e308", ABLATE,
         "spec.yaml: sweep.random.params.gating.inflation.uniform.1: 1e+308 is above 1e+15",
         spec(sweep={"random": {"samples": 2, "params": {"gating.inflation": {"uniform": [1, 1e308]}}}})),
    Case("ablate-random-log-uniform-1e308", ABLATE,
         "spec.yaml: sweep.random.params.gating.inflation.log_uniform.1: 1e+308 is above 1e+15",
         spec(sweep={"random": {"samples": 2, "params": {"gating.inflation": {"log_uniform": [1, 1e308]}}}})),
    *(Case(f"inject-{name}", ("inject", "{run}", "--fault", fault, "--out", "{d}/o"), f"--fault {fault}: {says}")
      for name, fault, says in (
          ("start-1e308", "gyro_bias@1e308:1e308", "start_s: 1e+308 s is above 4.29497e+09 s"),
          ("end-1e308", "slip@2:1e308", "end_s: 1e+308 s is above 4.29497e+09 s"),
          ("dipole-start-negative", "dipole@-1:5", "start_s: -1 s is below 0 s"),
      )),
]


@pytest.mark.parametrize("case", CASES, ids=[c.id for c in CASES])
def test_a_misused_command_gives_one_clean_error(case: Case, world: World, tmp_path: Path, capsys):
    run_case(case, world, tmp_path, capsys, checksums, TIME_LIMIT_S)


def test_a_submap_length_of_1e308_ends_the_process_with_one_line(world: World, tmp_path: Path):
    """As a user meets it: ``gslam map RUN --set submaps.length_m=1e308``
    in a process of its own loaded the config in silence and mapped."""
    d = tmp_path / "case"
    d.mkdir()
    argv = expand(_map_set("submaps.length_m=1e308"), d, world)
    done = subprocess.run([sys.executable, "-m", "slam.cli", *argv], cwd=tmp_path, capture_output=True, text=True,
                          timeout=TIME_LIMIT_S, env={**os.environ, "PYTHONPATH": str(REPO)})
    assert done.returncode != 0, done.stderr[-800:]
    assert done.stderr.count("\n") == 1 and "Traceback" not in done.stderr, done.stderr
    assert "submaps.length_m: 1e+308 m is above" in done.stderr, done.stderr
    assert not (d / "o").exists()


def test_a_pause_of_1e308_s_ends_the_process_with_one_line(world: World, tmp_path: Path):
    """As a user meets it: ``gslam simulate`` of a scenario whose
    ``robot.start_pause_s`` is 1e308 ended in an OverflowError traceback."""
    d = tmp_path / "case"
    d.mkdir()
    scenario(set_in("robot", "start_pause_s", 1e308))(d, world)
    before = checksums(d)
    done = subprocess.run([sys.executable, "-m", "slam.cli", *expand(SIM, d, world)], cwd=tmp_path,
                          capture_output=True, text=True, timeout=TIME_LIMIT_S,
                          env={**os.environ, "PYTHONPATH": str(REPO)})
    assert done.returncode == 1, done.stderr[-800:]
    assert done.stderr.count("\n") == 1 and "Traceback" not in done.stderr, done.stderr
    assert "s.yaml: robot.start_pause_s: 1e+308 s is above 14400 s" in done.stderr, done.stderr
    assert checksums(d) == before and not (d / "o").exists()


def test_corpus_counts():
    assert len(CASES) >= 40
    assert len({c.id for c in CASES}) == len(CASES)
