"""How long a scenario's mission takes, estimated from its waypoints before
anything is simulated, and the bounds a simulation must stay within.

The estimate drives every leg at ``max_speed_m_s``, turns every corner on
the spot at ``max_turn_rate_deg_s`` and adds the pauses and the time to
accelerate and brake at each stop; it is within a few per cent of the
planned motion for the shipped scenarios (tests/test_sim.py). A mission
longer than :data:`MAX_DURATION_S`, or one whose streams would hold more
samples than the limits below, is refused with the estimate in the
message instead of running for hours.

The time the simulator computes grows with the world as well as with the
mission: every scan's beams are cast against the wall segments in range,
every GPS fix measures its distance to every wall, every sample looks up
its region and sums the steel's fields, and doors and the route check
walk the walls in Python. :func:`check_work` adds these up, each as a
count of elementary tests times what one costs (measured on one core of
the development machine, numpy 2), and refuses a simulation estimated at
more than :data:`MAX_WORK_S` naming the keys of its largest part. Memory
does not grow with the world: the ray casting and the distance and region
look-ups work in blocks (:mod:`slam.sim.world`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from slam.errors import GslamError
from validation.base.geometry import wrap_angle
from slam.sim.route import check_route
from slam.sim.scenario import RegionKind, RobotConfig, Scenario
from slam.sim.world import segments_near_count, wall_segments
from validation.base import bounds

MAX_DURATION_S = bounds.MAX_MISSION_S
"""Longest mission simulated: 4 h (the 2-hour benchmark run fits twice)."""
MAX_PATH_M = 100_000.0
"""Longest path: the motion is planned on 5 mm steps along it."""
MAX_MESSAGES = 20_000_000
"""Most messages of one stream (ground truth at 100 Hz for 4 h is 1.44 M)."""
MAX_LASER_VALUES = 100_000_000
"""Most laser ranges in all (scans x beams; 400 MB as float32)."""
MAX_WORK_S = 3600.0
"""Longest computation a simulation may be estimated at (:func:`check_work`): an hour."""

# Nanoseconds of one elementary test of the simulator, measured on one core:
# a beam against a segment (slam.sim.world.World.cast), a scan's position
# against a segment (its segments in range), a point's distance to a segment
# (GPS multipath, indoor regions), a point against a polygon corner (regions),
# a sample's field of one dipole, a door against a segment and a route leg
# against a segment (both Python loops).
_NS = {"ray": 20.0, "near": 100.0, "distance": 200.0, "corner": 20.0, "dipole": 65.0, "door": 4500.0,
       "crossing": 2000.0}


@dataclass(frozen=True)
class MissionEstimate:
    """``duration_s`` of the mission, ``path_m`` driven, ``scans`` of the laser."""

    duration_s: float
    path_m: float
    scans: int


def estimate_duration(robot: RobotConfig) -> tuple[float, float]:
    """Mission duration (s) and path length (m) from the waypoints alone:
    the legs at full speed, a stop (accelerate and brake) and a spot turn
    wherever :func:`slam.sim.robot.plan_motion` turns on the spot, and the
    pauses. Gentle corners are driven on arcs at speed. Laps are counted,
    not unrolled: each lap after the first adds what the second added."""
    if robot.laps == 1:
        return _estimate(robot, robot.waypoints)
    one = _estimate(robot, robot.waypoints)
    two = _estimate(robot, list(robot.waypoints) + list(robot.waypoints[1:]))
    more = robot.laps - 1
    return float(one[0] + more * (two[0] - one[0])), float(one[1] + more * (two[1] - one[1]))


def _estimate(robot: RobotConfig, path: list) -> tuple[float, float]:
    pts = np.array([w[:2] for w in path], dtype=float)
    pauses = [w[2] if len(w) > 2 else 0.0 for w in path]
    legs = np.diff(pts, axis=0)
    lengths = np.hypot(legs[:, 0], legs[:, 1])
    path_m = float(lengths.sum())
    v, a = robot.max_speed_m_s, robot.max_accel_m_s2
    w_max = np.radians(robot.max_turn_rate_deg_s)
    spot_limit = np.radians(robot.spot_turn_above_deg)
    alpha = np.radians(robot.max_turn_accel_deg_s2)
    driving = float(np.sum(lengths / _leg_speeds(robot, path)))
    seconds = driving + robot.start_pause_s + robot.end_pause_s + sum(pauses)
    yaw = np.radians(robot.start_yaw_deg)
    for i, (leg, length) in enumerate(zip(legs, lengths)):
        if length == 0.0:
            continue
        heading = float(np.arctan2(leg[1], leg[0]))
        turn = abs(float(wrap_angle(heading - yaw)))
        if i == 0 or pauses[i] > 0 or turn > spot_limit or robot.corner_radius_m == 0.0:
            # Stop, turn on the spot (a trapezoidal turn-rate profile), start again.
            w_peak = min(w_max, np.sqrt(turn * alpha))
            seconds += (turn / w_peak + w_peak / alpha if turn > 0 else 0.0) + v / a
        else:
            # An arc of radius at most corner_radius_m at a turn rate of at most
            # w_max: slower than the straight line when w_max * R < v.
            seconds += max(0.0, turn / w_max - robot.corner_radius_m * turn / v)
        yaw = heading
    return float(seconds), path_m


def _leg_speeds(robot: RobotConfig, path: list) -> np.ndarray:
    """The speed limit (m/s) of each leg of ``path``: the fourth value of
    the waypoint it ends at, else ``max_speed_m_s``."""
    return np.array([w[3] if len(w) > 3 else robot.max_speed_m_s for w in path[1:]], dtype=float)


def _hours(seconds: float) -> str:
    """``seconds`` in hours to a tenth, or to three digits once beyond a
    million hours (an acceleration of 1e-300 m/s^2 takes 1e300 s)."""
    hours = seconds / 3600
    return f"{hours:.1f}" if hours < 1e6 else f"{hours:.3g}"


def _longest_part(robot: RobotConfig, duration: float, path_m: float) -> str:
    """What takes most of a mission's ``duration``: driving, a pause
    (naming its waypoint) or turning, in the words of the scenario's keys."""
    laps = robot.laps
    pts = np.array([w[:2] for w in robot.waypoints], dtype=float)
    lengths = np.hypot(*np.diff(pts, axis=0).T)
    own = [i for i, w in enumerate(robot.waypoints) if len(w) > 3 and i > 0]
    rest_m = path_m - laps * sum(lengths[i - 1] for i in own)
    parts = {f"{rest_m:.1f} m of path at robot.max_speed_m_s {robot.max_speed_m_s:g}": rest_m / robot.max_speed_m_s}
    for i in own:
        speed = robot.waypoints[i][3]
        parts[f"the {lengths[i - 1]:.1f} m leg to robot.waypoints.{i} at its speed {speed:g} m/s (its fourth value)"
              + (f" (x {laps} laps)" if laps > 1 else "")] = laps * lengths[i - 1] / speed
    for i, w in enumerate(robot.waypoints):
        if len(w) > 2 and w[2] > 0:
            times = laps if i > 0 else 1
            parts[f"the pause of {w[2]:g} s at robot.waypoints.{i}" + (f" (x {laps} laps)" if times > 1 else "")] = w[2] * times
    parts[f"robot.start_pause_s {robot.start_pause_s:g}"] = robot.start_pause_s
    parts[f"robot.end_pause_s {robot.end_pause_s:g}"] = robot.end_pause_s
    turning = duration - sum(parts.values())
    parts[f"turning and accelerating (robot.max_turn_rate_deg_s {robot.max_turn_rate_deg_s:g}, "
          f"robot.max_turn_accel_deg_s2 {robot.max_turn_accel_deg_s2:g}, robot.max_accel_m_s2 {robot.max_accel_m_s2:g})"] = turning
    return max(parts, key=parts.get)


def check_bounded(scenario: Scenario, source: str) -> MissionEstimate:
    """The mission estimate, or a one-line :class:`GslamError` naming
    ``source`` if the mission would exceed a bound."""
    duration, path_m = estimate_duration(scenario.robot)
    sensors = scenario.sensors
    scans = int(duration * sensors.laser.rate_hz)
    if path_m > MAX_PATH_M:
        raise GslamError(f"{source}: the path is {path_m / 1000:.1f} km long; at most {MAX_PATH_M / 1000:.0f} km "
                         "can be simulated (robot.waypoints, robot.laps)")
    if duration > MAX_DURATION_S:
        raise GslamError(
            f"{source}: the mission would take about {_hours(duration)} h, most of it {_longest_part(scenario.robot, duration, path_m)}; "
            f"at most {MAX_DURATION_S / 3600:.0f} h can be simulated"
        )
    rates = {
        "robot.truth_rate_hz": scenario.robot.truth_rate_hz,
        "sensors.laser.rate_hz": sensors.laser.rate_hz,
        "sensors.gyro.rate_hz": sensors.gyro.rate_hz,
        "sensors.magnetometer.rate_hz": sensors.magnetometer.rate_hz,
        "sensors.odometry.rate_hz": sensors.odometry.rate_hz,
        "sensors.gps.rate_hz": sensors.gps.rate_hz,
    }
    for key, rate in rates.items():
        if duration * rate > MAX_MESSAGES:
            raise GslamError(f"{source}: {key} {rate:g} over about {duration:.0f} s gives {duration * rate:.3g} "
                             f"messages; at most {MAX_MESSAGES:.0e} per stream")
    if scans * sensors.laser.beams > MAX_LASER_VALUES:
        raise GslamError(f"{source}: {scans} scans of {sensors.laser.beams} beams (sensors.laser) over about "
                         f"{duration:.0f} s; at most {MAX_LASER_VALUES:.0e} ranges in all")
    check_work(scenario, source, duration, scans)
    check_doors(scenario, source)
    check_route(scenario, source)
    return MissionEstimate(duration, path_m, scans)


def _route_points(robot: RobotConfig, count: int = 200) -> np.ndarray:
    """``count`` points (count, 2) m spread evenly along one lap's legs."""
    pts = np.array([w[:2] for w in robot.waypoints], dtype=float)
    along = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(pts, axis=0).T))])
    at = np.linspace(0.0, along[-1], count)
    return np.column_stack([np.interp(at, along, pts[:, 0]), np.interp(at, along, pts[:, 1])])


def check_doors(scenario: Scenario, source: str) -> None:
    """A one-line :class:`GslamError` naming ``source`` for a door that cuts
    no wall: :mod:`slam.sim.world` cuts a segment whose line passes within
    1 cm of a door's centre, beside the segment; a door that does so for no
    segment was ignored in silence (a typo of its centre, a wall moved)."""
    segs = wall_segments(scenario.world)
    if not scenario.world.doors:
        return
    a, d = segs[:, 0], segs[:, 1] - segs[:, 0]
    length = np.hypot(d[:, 0], d[:, 1])
    for i, door in enumerate(scenario.world.doors):
        c = np.asarray(door.center, dtype=float) - a
        along = (c[:, 0] * d[:, 0] + c[:, 1] * d[:, 1]) / length
        off = np.abs(d[:, 0] * c[:, 1] - d[:, 1] * c[:, 0]) / length
        cuts = (off <= 0.01) & (along >= -door.width_m / 2) & (along <= length + door.width_m / 2)
        if not cuts.any():
            raise GslamError(f"{source}: world.doors.{i}: the door at ({door.center[0]:g}, {door.center[1]:g}) cuts "
                             "no wall: its centre lies on none (within 1 cm); give a point of the wall it opens")


def check_work(scenario: Scenario, source: str, duration: float, scans: int) -> None:
    """A one-line :class:`GslamError` naming ``source`` if the simulation
    of a mission of ``duration`` s and ``scans`` laser scans would compute
    for longer than :data:`MAX_WORK_S` (module docstring). The beams are
    counted against the segments within the laser's range of points along
    the route, on average; a world of many walls far from the route costs
    only their look-up."""
    world, robot, sensors = scenario.world, scenario.robot, scenario.sensors
    laser = sensors.laser
    walls_xy = wall_segments(world)
    segments = len(walls_xy)
    walls = f"{segments:,} wall segments (world.walls, world.obstacles)"
    near = segments_near_count(walls_xy, _route_points(robot), laser.max_range_m)
    fixes = duration * sensors.gps.rate_hz
    truth = duration * robot.truth_rate_hz
    located = truth + duration * sensors.odometry.rate_hz + 3 * fixes
    corners = sum(len(r.polygon) for r in world.regions) + len(world.default_region.polygon)
    indoor = sum(len(r.polygon) for r in world.regions if r.kind is RegionKind.INDOOR)
    fields = truth + duration * sensors.magnetometer.rate_hz
    legs = len(robot.waypoints) - 1 + (robot.laps > 1)
    parts = {  # what each part is, its elementary tests, their kind
        f"ray casting {scans:,} scans (sensors.laser.rate_hz {laser.rate_hz:g} over about {duration:.0f} s) of "
        f"{laser.beams:,} beams (sensors.laser.beams) against the {near:,.0f} of {walls} within "
        f"sensors.laser.max_range_m {laser.max_range_m:g}": [(scans * laser.beams * near, "ray"), (scans * segments, "near")],
        f"the distance of {fixes:,.0f} GPS fixes (sensors.gps.rate_hz {sensors.gps.rate_hz:g}) to {walls}":
            [(fixes * segments, "distance"), (fixes * indoor, "distance")],
        f"the region of {located:,.0f} samples (robot.truth_rate_hz, sensors.odometry.rate_hz, sensors.gps.rate_hz) "
        f"among {corners:,} region corners (world.regions)": [(located * corners, "corner")],
        f"the field of {len(world.disturbers):,} steel structures (world.disturbers) at {fields:,.0f} samples "
        "(robot.truth_rate_hz, sensors.magnetometer.rate_hz)": [(fields * len(world.disturbers), "dipole")],
        f"cutting {len(world.doors):,} doors (world.doors) into {walls}": [(2 * len(world.doors) * segments, "door")],
        f"checking {legs:,} legs (robot.waypoints) against {walls}": [(legs * segments, "crossing")],
    }
    seconds = {what: sum(n * _NS[kind] for n, kind in tests) / 1e9 for what, tests in parts.items()}
    total = sum(seconds.values())
    if total > MAX_WORK_S:
        largest = max(seconds, key=seconds.get)
        raise GslamError(f"{source}: simulating would compute for about {_hours(total)} h, most of it "
                         f"{largest}; at most {MAX_WORK_S / 3600:.0f} h of it is started (a smaller world, fewer "
                         "beams or samples, or a shorter mission)")


# Bytes of one message of each stream as the simulator writes it (CDR), measured on its bags.
_MESSAGE_BYTES = {"truth": 716, "gyro": 324, "magnetometer": 124, "odometry": 724, "gps": 125}
_SCAN_BYTES_PER_BEAM, _SCAN_BYTES = 4, 60


def bag_bytes(scenario: Scenario, estimate: MissionEstimate) -> int:
    """At least the size of the simulated bag: the messages themselves
    (the SQLite file adds about a fifth), checked against the free space
    before anything is simulated."""
    s = scenario.sensors
    rates = {"truth": scenario.robot.truth_rate_hz, "gyro": s.gyro.rate_hz, "magnetometer": s.magnetometer.rate_hz,
             "odometry": s.odometry.rate_hz, "gps": s.gps.rate_hz}
    per_s = sum(rates[k] * _MESSAGE_BYTES[k] for k in rates)
    return int(estimate.duration_s * per_s + estimate.scans * (_SCAN_BYTES + _SCAN_BYTES_PER_BEAM * s.laser.beams))
