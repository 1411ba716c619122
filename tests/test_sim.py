"""Tests of the simulator: sensor models against physics with known answers,
true fault definitions, determinism, scenario loading and the bag layout."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import yaml

from slam.errors import GslamError
from validation.base.geometry import enu_from_geodetic
from slam.sim import load_scenario, simulate, simulate_scenario
from slam.sim.faults import compass_heading_error, intervals_from_mask
from slam.sim.world import scan_constraint
from slam.sim.magnetics import MU0_OVER_4PI, body_field, dip_angle, dipole_field, reference
from slam.sim.robot import Motion, plan_motion
from slam.sim.scenario import (
    Disturber,
    EnvironmentConfig,
    GpsConfig,
    GyroConfig,
    LaserConfig,
    OdometryConfig,
    RobotConfig,
    WorldConfig,
)
from slam.sim.sensors import simulate_gps, simulate_gyro, simulate_laser, simulate_odometry
from slam.sim.world import World
from tests.conftest import CONFIGS

SCENARIOS = Path(__file__).resolve().parents[1] / "configs" / "scenarios"
ENV = EnvironmentConfig()
REF = reference(ENV)
ROOM = [[0, 0], [10, 0], [10, 10], [0, 10]]


def still(duration_s: float, x: float = 0.0, y: float = 0.0, yaw: float = 0.0, w: float = 0.0) -> Motion:
    """A robot at (x, y) turning on the spot at constant rate ``w``, 100 Hz."""
    t = np.arange(0.0, duration_s + 1e-9, 0.01)
    n = len(t)
    zeros = np.zeros(n)
    return Motion(t, np.full(n, x), np.full(n, y), yaw + w * t, zeros, np.full(n, w), zeros)


def room_world() -> World:
    """A 10 x 10 m room with a 2 m door in its east wall, plus a yard."""
    cfg = {
        "walls": [[[0, 0], [10, 0], [10, 10], [0, 10], [0, 0]]],
        "doors": [{"center": [10, 5], "width_m": 2.0}],
        "regions": [{"name": "room", "kind": "indoor", "slip": 0.02, "polygon": ROOM}],
    }
    return World.from_config(WorldConfig.model_validate(cfg))


# --- magnetics -----------------------------------------------------------


def test_dipole_law_on_axis_and_equator():
    m = np.array([0.0, 0.0, 10.0])
    pts = np.array([[0.0, 0.0, 2.0], [2.0, 0.0, 0.0]])
    b = dipole_field(pts, np.zeros(3), m)
    np.testing.assert_allclose(b[0], [0, 0, MU0_OVER_4PI * 2 * 10 / 8], rtol=1e-12)
    np.testing.assert_allclose(b[1], [0, 0, -MU0_OVER_4PI * 10 / 8], rtol=1e-12)


def test_compass_exact_without_steel_and_wrong_near_steel():
    yaws = np.radians([-170.0, -45.0, 0.0, 30.0, 120.0])
    xy = np.zeros((len(yaws), 2))
    err = compass_heading_error(body_field(xy, yaws, 0.3, REF, []), yaws, REF.declination_rad)
    np.testing.assert_allclose(err, 0.0, atol=1e-12)

    # Steel 0.7 m east of the robot: its field has a large east component.
    cabinet = Disturber(name="c", position=(0.7, 0.0, 0.6), moment_A_m2=150.0, direction=(0, 0.43, -0.9))
    near = np.zeros((1, 2))
    far = np.array([[0.0, 40.0]])
    yaw = np.zeros(1)
    def error_deg(xy: np.ndarray) -> float:
        field = body_field(xy, yaw, 0.3, REF, [cabinet])
        return float(np.degrees(abs(compass_heading_error(field, yaw, REF.declination_rad)[0])))

    e_near, e_far = error_deg(near), error_deg(far)
    assert e_near > 10.0
    assert e_far < 0.05


def test_field_strength_and_dip_change_near_steel():
    cabinet = Disturber(name="c", position=(0.0, 0.7, 0.6), moment_A_m2=150.0, direction=(0, 0.43, -0.9))
    xy = np.array([[0.0, 0.0], [0.0, 50.0]])
    b = body_field(xy, np.zeros(2), 0.3, REF, [cabinet])
    strength = np.linalg.norm(b, axis=1)
    dip = dip_angle(b)
    assert abs(strength[1] - REF.strength_T) < 1e-9
    assert abs(dip[1] - REF.dip_rad) < 1e-3
    assert abs(strength[0] - REF.strength_T) > 5e-6  # > 10 % of Earth's field
    assert abs(dip[0] - REF.dip_rad) > np.radians(5.0)


# --- laser ---------------------------------------------------------------


def test_ray_cast_exact_range_and_inf_beyond_max_range():
    world = World.from_config(WorldConfig(walls=[[(5.0, -20.0), (5.0, 20.0)]]))
    angles = np.radians([0.0, 60.0, 80.0, 180.0])
    rng, hit = world.cast(np.zeros(2), angles, max_range=12.0)
    assert rng[0] == pytest.approx(5.0, abs=1e-12)
    assert rng[1] == pytest.approx(10.0, abs=1e-9)  # 5 / cos 60
    assert np.isinf(rng[2]) and hit[2] == -1  # 28.8 m > max range
    assert np.isinf(rng[3]) and hit[3] == -1  # nothing behind


def test_laser_scan_in_room_and_doors_cut_gaps():
    world = room_world()
    cfg = LaserConfig(beams=361, fov_deg=360.0, max_range_m=30.0, range_noise_m=0.0)
    scans = simulate_laser(still(0.0, x=5.0, y=5.0), world, cfg, np.random.default_rng(0))
    r = scans.ranges[0]
    i0 = np.argmin(np.abs(scans.angles))  # beam straight east, through the door
    i90 = np.argmin(np.abs(scans.angles - np.pi / 2))
    assert np.isinf(r[i0])
    assert r[i90] == pytest.approx(5.0, abs=1e-5)
    assert scans.ranges.dtype == np.float32


def test_scan_geometry_single_wall_is_degenerate_room_is_not():
    laser = LaserConfig(beams=271, max_range_m=10.0, range_noise_m=0.0)
    wall = World.from_config(WorldConfig(walls=[[(-20.0, 2.0), (20.0, 2.0)]]))
    s_wall = simulate_laser(still(0.0, yaw=np.pi / 2), wall, laser, np.random.default_rng(0))
    s_room = simulate_laser(still(0.0, x=3.0, y=4.0), room_world(), laser, np.random.default_rng(0))
    assert s_wall.returns[0] > 20 and s_wall.min_eigenvalue[0] < 1e-9
    assert s_room.min_eigenvalue[0] > 0.05


def test_scan_constraint_counts_returns():
    ranges = np.array([[1.0, np.inf, 2.0]])
    hit = np.array([[0, -1, 1]])
    count, eig, _ = scan_constraint(ranges, hit, np.zeros((1, 3)), np.array([[1.0, 0.0], [0.0, 1.0]]))
    assert count[0] == 2
    assert abs(eig[0]) < 1e-12  # two points cannot constrain three degrees of freedom


# --- gyro, odometry, GPS -------------------------------------------------------


def test_gyro_bias_random_walk_statistics():
    cfg = GyroConfig(noise_rad_s=0.003, bias_initial_rad_s=0.001, bias_walk_rad_s_sqrt_s=1e-4)
    g = simulate_gyro(still(600.0, w=0.2), cfg, np.random.default_rng(7))
    steps = np.diff(g.bias)
    assert np.std(steps) == pytest.approx(1e-4 * np.sqrt(0.01), rel=0.03)
    assert g.bias[0] == pytest.approx(0.001)
    white = g.rate - 0.2 - g.bias
    assert np.std(white) == pytest.approx(0.003, rel=0.03)
    assert abs(np.mean(white)) < 1e-4


def test_odometry_slip_grows_with_turn_rate():
    world = World.from_config(WorldConfig())  # default outdoor terrain, slip 0.03
    cfg = OdometryConfig(rotation_overreport=0.03, turn_slip_per_rad_s=0.1, yaw_noise_rad_sqrt_rad=0.0)
    ratios = []
    for w in (0.1, 0.5):
        o = simulate_odometry(still(10.0, w=w), world, cfg, np.random.default_rng(0))
        ratios.append(o.yaw[-1] / (w * 10.0))
        assert ratios[-1] == pytest.approx(1.0 + 0.03 + 0.03 + 0.1 * w, rel=1e-9)
    assert ratios[1] > ratios[0]
    assert o.x[0] == 0.0 and o.y[0] == 0.0 and o.yaw[0] == 0.0


def test_gps_no_fix_indoors_and_multipath_near_walls():
    world = room_world()
    robot = RobotConfig(waypoints=[(5.0, 5.0), (30.0, 5.0)], start_pause_s=0.0, end_pause_s=0.0)
    motion = plan_motion(robot)
    cfg = GpsConfig(sigma_m=1.0, outage_distance_m=2.0, multipath_max_m=8.0, multipath_scale_m=5.0)
    fix = simulate_gps(motion, world, cfg, ENV, np.random.default_rng(0))
    x_true = np.interp(fix.t, motion.t, motion.x)
    inside = x_true < 12.0
    assert np.all(fix.status[inside] == -1) and np.all(np.isnan(fix.lat[inside]))
    assert np.all(fix.status[x_true > 12.5] == 0)
    # Multipath decays with the distance from the building.
    assert fix.multipath[np.argmin(np.abs(x_true - 13))] > fix.multipath[-1]
    east, north = enu_from_geodetic(fix.lat[-1], fix.lon[-1], ENV.datum_lat_deg, ENV.datum_lon_deg)
    assert abs(east - x_true[-1]) < 5.0 and abs(north - 5.0) < 5.0


# --- trajectory and faults ------------------------------------------------------


def test_trajectory_respects_limits_and_reaches_goal():
    cfg = RobotConfig(waypoints=[(0, 0), (6, 0), (6, 4), (0, 4, 1.0), (0, 0)], max_speed_m_s=0.5)
    m = plan_motion(cfg)
    assert m.t[1] - m.t[0] == pytest.approx(0.01)
    assert np.max(m.v) <= 0.5 + 1e-9
    assert np.max(np.abs(m.w)) <= np.radians(cfg.max_turn_rate_deg_s) + 1e-3
    assert np.max(np.abs(np.diff(m.v))) / 0.01 <= cfg.max_accel_m_s2 + 1e-6
    assert np.hypot(m.x[-1], m.y[-1]) < 0.05
    # The integrated pose passes the waypoints (arcs cut corners by < 0.5 m).
    for wx, wy in [(6, 0), (6, 4), (0, 4)]:
        assert np.min(np.hypot(m.x - wx, m.y - wy)) < 0.5


def test_intervals_from_mask_merge_and_minimum_duration():
    t = np.arange(0, 10, 0.1)
    mask = ((t > 1) & (t < 3)) | ((t > 3.3) & (t < 4)) | ((t > 8) & (t < 8.15))
    assert intervals_from_mask(t, mask, merge_gap_s=0.5, min_duration_s=0.3) == [(1.1, 3.9)]
    assert intervals_from_mask(t, np.zeros_like(t, bool), 0.5, 0.3) == []


# --- scenarios and the run folder ----------------------------------------------


@pytest.mark.parametrize("name", ["telemax_lab", "telemax_lab_clean", "telemax_compass"])
def test_shipped_scenarios_load(name):
    sc = load_scenario(SCENARIOS / f"{name}.yaml")
    assert sc.name == name
    assert sc.environment.datum_lat_deg == 49.0 and sc.environment.datum_lon_deg == 8.4


def test_bad_scenarios_name_the_file(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("name: x\nrobot: {waypoints: [[0, 0], [1, 0]]}\nsensors: {laser: {beam: 10}}\n")
    with pytest.raises(GslamError, match=r"bad\.yaml.*sensors\.laser\.beam"):
        load_scenario(bad)
    with pytest.raises(GslamError, match="missing.yaml"):
        simulate(tmp_path / "missing.yaml", tmp_path / "out")


def tiny_scenario(path: Path) -> Path:
    """A 15 s run from a room out through its door."""
    tree = {
        "name": "tiny",
        "seed": 5,
        "world": {
            "walls": [[[0, 0], [10, 0], [10, 10], [0, 10], [0, 0]]],
            "doors": [{"center": [10, 5], "width_m": 2.0}],
            "regions": [
                {"name": "room", "kind": "indoor", "polygon": ROOM},
                {"name": "mud", "kind": "outdoor", "slip": 0.3, "polygon": [[12, 0], [14, 0], [14, 10], [12, 10]]},
            ],
            "disturbers": [{"name": "steel", "position": [6.0, 5.7, 0.5], "moment_A_m2": 150.0}],
        },
        "robot": {"waypoints": [[5, 5], [16, 5]], "max_speed_m_s": 1.0, "start_pause_s": 0.5},
        "sensors": {"laser": {"beams": 91}},
    }
    path.write_text(yaml.safe_dump(tree))
    return path


def read_bag(bag: Path) -> list[tuple[str, int, bytes]]:
    from rosbags.highlevel import AnyReader

    with AnyReader([bag]) as reader:
        return [(c.topic, ts, bytes(raw)) for c, ts, raw in reader.messages()]


def test_short_run_writes_a_valid_bag_and_truth(tmp_path):
    from rosbags.highlevel import AnyReader

    result = simulate(tiny_scenario(tmp_path / "tiny.yaml"), tmp_path / "run")
    run = tmp_path / "run"
    assert result.run_dir == run and not any(p.name.startswith(".run") for p in tmp_path.iterdir())
    truth = json.loads((run / "truth.json").read_text())
    assert truth["seed"] == 5 and truth["t0"] == 1_700_000_000.0
    assert load_scenario(run / "scenario.yaml") == load_scenario(tmp_path / "tiny.yaml")
    assert set(truth["faults"]) == {"ODO_DIST", "ODO_YAW", "IMU_GYRO", "IMU_YAW", "SM_DIST", "SM_LAT", "SM_YAW", "GPS"}
    assert truth["faults"]["IMU_YAW"], "passing 0.7 m from the steel must bend the compass"
    assert truth["gps_datum"] == {"lat_deg": 49.0, "lon_deg": 8.4}
    # Only the mud patch (x 12..14 m) makes the tracks slip beyond nominal.
    motion = plan_motion(load_scenario(tmp_path / "tiny.yaml").robot)
    (odo,) = truth["faults"]["ODO_DIST"]
    x_at = np.interp(odo, motion.t, motion.x)
    assert x_at[0] == pytest.approx(12.0, abs=0.05) and x_at[1] == pytest.approx(14.0, abs=0.05)
    with AnyReader([run / "bag"]) as reader:
        counts = {c.topic: c.msgcount for c in reader.connections}
        assert counts == result.message_counts
        assert counts["/ground_truth"] == round(result.duration_s * 100) + 1
        assert counts["/scan"] == int(result.duration_s * 10) + 1
        seen = set()
        for conn, ts, raw in reader.messages():
            msg = reader.deserialize(raw, conn.msgtype)
            assert msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec == ts
            if conn.topic in seen:
                continue
            seen.add(conn.topic)
            if conn.topic == "/scan":
                assert msg.header.frame_id == "laser" and len(msg.ranges) == 91
            elif conn.topic == "/imu/data":
                assert msg.orientation_covariance[0] == -1
                assert msg.linear_acceleration.z == pytest.approx(9.81)
            elif conn.topic == "/gps/fix":
                assert msg.status.status == -1 and np.isnan(msg.latitude)  # starts indoors
                assert msg.position_covariance_type == 2
            elif conn.topic == "/odom":
                assert (msg.header.frame_id, msg.child_frame_id) == ("odom", "base_link")
            elif conn.topic == "/ground_truth":
                assert msg.header.frame_id == "map" and msg.pose.pose.position.x == pytest.approx(5.0)
        assert seen == set(counts)
    first = min(ts for _, ts, _ in read_bag(run / "bag"))
    assert first == 1_700_000_000 * 10**9
    # Again into the same folder: an earlier simulate result, replaced.
    again = simulate(tmp_path / "tiny.yaml", run)
    assert again.message_counts == result.message_counts
    # Into a folder of something else: refused before any work.
    other = tmp_path / "other"
    other.mkdir()
    (other / "notes.txt").write_text("mine")
    with pytest.raises(GslamError, match="not a gslam simulate result"):
        simulate(tmp_path / "tiny.yaml", other)
    assert [p.name for p in other.iterdir()] == ["notes.txt"]


def test_same_seed_same_messages_different_seed_differs(tmp_path):
    scenario = tiny_scenario(tmp_path / "tiny.yaml")
    simulate(scenario, tmp_path / "a", seed=11)
    simulate(scenario, tmp_path / "b", seed=11)
    simulate(scenario, tmp_path / "c", seed=12)
    a, b, c = (read_bag(tmp_path / n / "bag") for n in "abc")
    assert a == b
    assert [m[:2] for m in a] == [m[:2] for m in c]  # same topics and stamps ...
    assert a != c  # ... but other noise
    gt = [m for m in a if m[0] == "/ground_truth"]
    assert gt == [m for m in c if m[0] == "/ground_truth"]  # truth has no noise


def test_laps_repeat_a_closed_path_and_refuse_an_open_one():
    from pydantic import ValidationError

    from slam.sim.scenario import RobotConfig

    square = [(0.0, 0.0), (4.0, 0.0), (4.0, 4.0), (0.0, 4.0), (0.0, 0.0)]
    one = plan_motion(RobotConfig(waypoints=square, start_pause_s=0.0, end_pause_s=0.0))
    three = plan_motion(RobotConfig(waypoints=square, laps=3, start_pause_s=0.0, end_pause_s=0.0))
    assert RobotConfig(waypoints=square, laps=3).path() == square + square[1:] * 2
    # Three laps: nearly three times the time (the robot does not stop at the
    # start corner between laps, it takes it on an arc), back at the start.
    assert 2.7 * one.duration < three.duration < 3.0 * one.duration
    assert np.hypot(three.x[-1], three.y[-1]) < 0.01  # integrated at 100 Hz
    with pytest.raises(ValidationError, match="closed path"):
        RobotConfig(waypoints=square[:-1], laps=2)


# --- the mission budget ----------------------------------------------------------


@pytest.mark.parametrize("name, laps", [("telemax_lab", 1), ("telemax_loop", 1), ("telemax_loop", 3)])
def test_duration_estimate_is_close_to_the_planned_motion(name, laps):
    from slam.sim.budget import estimate_duration

    robot = load_scenario(CONFIGS / "scenarios" / f"{name}.yaml").robot.model_copy(update={"laps": laps})
    estimate, path_m = estimate_duration(robot)
    motion = plan_motion(robot)
    assert estimate == pytest.approx(motion.duration, rel=0.03)  # measured 1.4-1.6 % over
    assert path_m == pytest.approx(motion.s[-1], rel=0.05)  # corners are cut on arcs


def test_unbounded_missions_are_refused_before_simulating(tmp_path):
    from slam.sim.budget import MAX_DURATION_S, check_bounded

    base = load_scenario(CONFIGS / "scenarios" / "telemax_lab.yaml")
    assert check_bounded(base, "lab").duration_s < MAX_DURATION_S
    slow = base.model_copy(update={"robot": base.robot.model_copy(update={"max_speed_m_s": 0.001})})
    with pytest.raises(GslamError, match=r"lab: the mission would take about 2\d\.\d h, most of it 88.7 m of path at robot.max_speed_m_s 0.001; at most 4 h"):
        check_bounded(slow, "lab")
    with pytest.raises(GslamError, match="at most 4 h"):
        simulate_scenario(slow, tmp_path / "run")
    assert not (tmp_path / "run").exists() and list(tmp_path.iterdir()) == []


def test_the_blocks_of_the_world_look_ups_give_what_one_at_a_time_gives():
    """Ray casting, wall distances and regions work in blocks of at most a
    million tests (slam/sim/world.py): a world of 4,000 segments in range
    takes several blocks per scan, and each beam, point and region comes out
    exactly as cast or looked up alone."""
    from slam.sim.world import World, distance_to_segments, point_in_polygon

    rng = np.random.default_rng(3)
    segments = rng.uniform(-5.0, 5.0, (4000, 2, 2))
    world = World(segments, np.zeros((4000, 2)), [], None)
    angles = np.linspace(-np.pi, np.pi, 541)
    ranges, hits = world.cast(np.zeros(2), angles, 10.0)
    alone = [world.cast(np.zeros(2), angles[i : i + 1], 10.0) for i in range(len(angles))]
    assert np.array_equal(ranges, [r[0] for r, _ in alone]) and np.array_equal(hits, [h[0] for _, h in alone])
    points = rng.uniform(-6.0, 6.0, (600, 2))
    dist, away = distance_to_segments(points, segments)
    one = [distance_to_segments(p[None], segments) for p in points]
    assert np.array_equal(dist, [d[0] for d, _ in one]) and np.array_equal(away, [a[0] for _, a in one])
    polygon = np.column_stack([np.cos(np.linspace(0, 6.2, 3000)), np.sin(np.linspace(0, 6.2, 3000))]) * 4
    inside = point_in_polygon(points, polygon)
    assert np.array_equal(inside, [point_in_polygon(p[None], polygon)[0] for p in points]) and 0 < inside.sum() < 600
