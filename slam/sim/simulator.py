"""Run one scenario end to end and write its run folder.

Layout of the run folder ``OUT``:

* ``OUT/bag/``          the ROS 2 bag (see :mod:`slam.sim.bagwriter`)
* ``OUT/truth.json``    scenario name, seed, ``t0`` (absolute start, s),
  ``duration_s``, the true ``faults`` per component (intervals in s relative
  to ``t0``), the ``magnetic_reference`` and the ``gps_datum``
* ``OUT/scenario.yaml`` the scenario actually used, every default spelled out

``OUT`` follows the rule of :mod:`slam.results.outdir`: new, or an earlier
simulate result (replaced), checked before any work; the folder is built
beside ``OUT`` and renamed at the end, so a killed run leaves a complete
folder or none.
"""

from __future__ import annotations

import json
import logging
import time
from dataclasses import dataclass, field
from enum import IntEnum
from pathlib import Path

import numpy as np
from tqdm import tqdm

from slam.results.outdir import result_folder
from slam.recording import Interval
from slam.sim.budget import bag_bytes, check_bounded
from slam.sim.bagwriter import Streams, write_bag
from slam.sim.faults import true_faults
from slam.sim.magnetics import reference
from slam.sim.robot import plan_motion
from slam.sim.scenario import Scenario, dump_scenario, load_scenario
from slam.sim.sensors import (
    sample_times,
    simulate_gps,
    simulate_gyro,
    simulate_laser,
    simulate_magnetometer,
    simulate_odometry,
)
from slam.sim.world import World

log = logging.getLogger(__name__)

RESULT_NAMES = ("bag/", "truth.json", "scenario.yaml")
"""What a simulated run folder holds."""


class Stream(IntEnum):
    """Fixed spawn key of each sensor's random stream: changing one sensor's
    rate or noise never reshuffles the draws of another."""

    LASER = 0
    GYRO = 1
    MAGNETOMETER = 2
    ODOMETRY = 3
    GPS = 4


@dataclass
class SimulationResult:
    """What :func:`simulate` produced: the run folder, the simulated
    ``duration_s``, messages per topic, the true fault intervals (s relative
    to ``t0``) and the wall-clock time it took."""

    run_dir: Path
    scenario: str
    seed: int
    t0: float
    duration_s: float
    message_counts: dict[str, int]
    faults: dict[str, list[Interval]] = field(default_factory=dict)
    wall_time_s: float = 0.0


def sensor_rng(seed: int, stream: Stream) -> np.random.Generator:
    """The random generator of one sensor for a run seed."""
    return np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(int(stream),)))


def simulate(
    scenario_path: str | Path,
    out_dir: str | Path,
    seed: int | None = None,
    progress: bool = False,
    force: bool = False,
) -> SimulationResult:
    """Simulate the scenario YAML ``scenario_path`` into the run folder
    ``out_dir`` (new, or an earlier simulate result; ``force``: see
    :mod:`slam.results.outdir`). ``seed`` overrides the scenario's seed; the same
    seed gives identical messages and stamps."""
    started = time.perf_counter()
    scenario = load_scenario(scenario_path)
    if seed is not None:
        scenario = scenario.model_copy(update={"seed": seed})
    return _run(scenario, Path(out_dir), progress, started, str(scenario_path), force)


def simulate_scenario(
    scenario: Scenario, out_dir: str | Path, progress: bool = False, force: bool = False
) -> SimulationResult:
    """As :func:`simulate`, for a scenario already in memory."""
    return _run(scenario, Path(out_dir), progress, time.perf_counter(), None, force)


def _run(
    scenario: Scenario, out: Path, progress: bool, started: float, source: str | None, force: bool
) -> SimulationResult:
    estimate = check_bounded(scenario, source or f"scenario '{scenario.name}'")
    log.info("%s: about %.0f s of mission, %.0f m", scenario.name, estimate.duration_s, estimate.path_m)
    need = bag_bytes(scenario, estimate)
    with result_folder(out, "simulate", [source] if source else [], force, RESULT_NAMES, need) as tmp:
        result = _simulate_into(scenario, tmp, progress)
    result.run_dir = out
    result.wall_time_s = time.perf_counter() - started
    log.info("%s: wrote %s in %.1f s", scenario.name, out, result.wall_time_s)
    return result


def _simulate_into(scenario: Scenario, tmp: Path, progress: bool) -> SimulationResult:
    # 1. World and ground-truth motion.
    world = World.from_config(scenario.world)
    motion = plan_motion(scenario.robot)
    seed, sensors, env = scenario.seed, scenario.sensors, scenario.environment
    ref = reference(env)
    log.info("%s: %.1f s, %.1f m, seed %d", scenario.name, motion.duration, motion.s[-1], seed)
    # 2. Sensors, each from its own random stream.
    n_scans = len(sample_times(motion.duration, sensors.laser.rate_hz))
    desc = f"{scenario.name}, {motion.duration:.0f} s: ray casting"
    # disable=None: a bar only on a terminal, never into a piped log.
    shown = None if progress else True
    with tqdm(total=n_scans, unit="scan", desc=desc, disable=shown) as bar:
        laser = simulate_laser(motion, world, sensors.laser, sensor_rng(seed, Stream.LASER), bar)
    gyro = simulate_gyro(motion, sensors.gyro, sensor_rng(seed, Stream.GYRO))
    mag_rng = sensor_rng(seed, Stream.MAGNETOMETER)
    mag = simulate_magnetometer(motion, sensors.magnetometer, ref, scenario.world.disturbers, mag_rng)
    odom = simulate_odometry(motion, world, sensors.odometry, sensor_rng(seed, Stream.ODOMETRY))
    gps = simulate_gps(motion, world, sensors.gps, env, sensor_rng(seed, Stream.GPS))
    # 3. True fault intervals from the physics.
    faults = true_faults(scenario, world, motion, laser, gyro, gps)
    duration = round(motion.duration, 6)
    # 4. Write everything into the temporary folder (renamed by the caller).
    streams = Streams(motion, laser, gyro, mag, odom, gps)
    n_msgs = sum(len(s.t) for s in (motion, laser, gyro, mag, odom, gps))
    with tqdm(total=n_msgs, unit="msg", desc="writing bag", disable=shown) as bar:
        counts = write_bag(tmp / "bag", streams, env.t0_s, bar)
    truth = {
        "scenario": scenario.name,
        "seed": seed,
        "t0": env.t0_s,
        "duration_s": duration,
        "faults": {k: [list(iv) for iv in v] for k, v in faults.items()},
        "magnetic_reference": {
            "strength_T": ref.strength_T,
            "dip_rad": ref.dip_rad,
            "declination_rad": ref.declination_rad,
        },
        "gps_datum": {"lat_deg": env.datum_lat_deg, "lon_deg": env.datum_lon_deg},
    }
    (tmp / "truth.json").write_text(json.dumps(truth, indent=2) + "\n")
    (tmp / "scenario.yaml").write_text(dump_scenario(scenario))
    return SimulationResult(tmp, scenario.name, seed, env.t0_s, duration, counts, faults)
