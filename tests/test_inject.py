"""``gslam inject``: faults from physics added to recordings, with their
true intervals beside them (slam/commands/inject/)."""

from __future__ import annotations

import json
import logging

import numpy as np
import pytest

from slam.cli import main
from slam.config import InputConfig, StreamFrameConfig, load_config
from slam.errors import GslamError
from validation.base.geometry import heading_from_magnetometer, wrap_angle
from slam.commands.inject import inject, parse_fault
from slam.commands.inject import physics
from slam.commands.inject.spec import DipoleFault, SlipFault
from slam.readers.read import read_recording
from slam.readers.rosbag import open_bag
from slam.recording import Trajectory
from tests.bagfactory import driving_bag, ned_driving_bag, split_mcap, with_foreign_channel
from tests.conftest import CONFIGS, real_data
from tests.synthetic import wall_ranges


# --- the fault syntax ------------------------------------------------------------------


def test_faults_parse_with_their_parameters():
    f = parse_fault("dipole@100:120,moment_A_m2=800,side=right")
    assert isinstance(f, DipoleFault) and (f.start_s, f.end_s, f.moment_A_m2, f.side) == (100, 120, 800, "right")
    assert parse_fault("laser_cut@5.5:9").range_m == 4.0
    assert parse_fault(f.text()) == f  # the text a fault is reported by parses back to it


@pytest.mark.parametrize("text, says", [
    ("magnet@1:2", "unknown fault kind 'magnet'"),
    ("dipole@1", "expected KIND@T0:T1"),
    ("dipole@5:2", "must end after it starts"),
    ("dipole@1:2,momnt=5", "unknown parameter 'momnt' of dipole (known: moment_A_m2"),
    ("dipole@1:2,moment_A_m2=nan", "moment_A_m2"),
    ("slip@1:2,scale", "expected param=value"),
    ("laser_cut@-1:2", "start_s"),
])
def test_bad_faults_are_one_line_errors(text, says):
    with pytest.raises(GslamError, match=f"--fault {text}: .*") as e:
        parse_fault(text)
    assert says in str(e.value) and "\n" not in str(e.value)


# --- physics ---------------------------------------------------------------------------------


def test_heading_change_is_what_a_magnetometer_compass_reads():
    rng = np.random.default_rng(1)
    field = rng.normal(0, 20e-6, (50, 3))
    added = rng.normal(0, 5e-6, (50, 3))
    expected = wrap_angle(heading_from_magnetometer(field + added) - heading_from_magnetometer(field))
    assert physics.heading_change(field, added) == pytest.approx(expected)


def test_a_dipole_beside_the_path_disturbs_only_while_present_and_near():
    t = np.arange(0.0, 60.0, 0.1)
    path = Trajectory(t, 0.5 * t, np.zeros_like(t), np.zeros_like(t))  # east at 0.5 m/s
    fault = DipoleFault(start_s=20.0, end_s=40.0, moment_A_m2=500.0, distance_m=2.0, azimuth_deg=0.0)
    dipole = physics.Dipole(fault, path)
    assert dipole.position == pytest.approx([15.0, 2.0, 0.0])  # 2 m to the left of where the robot is at 30 s
    b = np.linalg.norm(dipole.field_path(t), axis=1)
    assert b[(t < 20.0) | (t > 40.0)].max() == 0.0
    closest = np.argmin(np.abs(t - 30.0))
    # The moment points along the path, across the line to the sensor: B = -mu0/4pi m/r^3 there.
    assert b[closest] == pytest.approx(1e-7 * 500.0 / 2.0**3, rel=1e-6)
    error = physics.heading_error(np.zeros_like(t), dipole.field_body(t), 20e-6)
    assert np.degrees(np.abs(error[closest])) > 5.0 and np.degrees(np.abs(error[t < 25.0])).max() < 5.0


def test_slip_scales_the_increments_of_its_interval_and_moves_what_follows():
    t = np.arange(0.0, 10.0, 1.0)
    x, y, yaw = t.copy(), np.zeros_like(t), np.zeros_like(t)
    nx, ny, _ = physics.reintegrate(t, x, y, yaw, SlipFault(start_s=2.0, end_s=4.5, scale=2.0))
    assert nx.tolist() == [0, 1, 2, 4, 6, 8, 9, 10, 11, 12] and np.abs(ny).max() < 1e-12
    same = physics.reintegrate(t, x, y + 0.1 * t**2, 0.2 * t, SlipFault(start_s=2.0, end_s=4.0, scale=1.0))
    assert same[0] == pytest.approx(x) and same[1] == pytest.approx(0.1 * t**2) and same[2] == pytest.approx(0.2 * t)


def _scan(walls: list[tuple[float, float, float]]) -> tuple[np.ndarray, np.ndarray]:
    """One scan (1, n) of a laser at the origin to the lines ``walls``, and its angles."""
    r, angles = wall_ranges(walls)
    return r[None], angles


def test_scan_geometry_finds_a_corridor_and_a_blind_scan():
    corridor, angles = _scan([(0.0, 1.0, 1.5), (0.0, -1.0, 1.5)])
    room, _ = _scan([(0.0, 1.0, 1.5), (0.0, -1.0, 1.5), (1.0, 0.0, 3.0), (-1.0, 0.0, 2.0)])
    cut = physics.cut_ranges(room, 0.5, np.inf)
    fault = parse_fault("laser_cut@0:1")
    labels = {name: physics.laser_labels(r, angles, 0.1, 30.0, fault) for name, r in
              (("corridor", corridor), ("room", room), ("cut", cut))}
    assert {m: bool(v[0]) for m, v in labels["corridor"].items()} == {"SM_DIST": True, "SM_LAT": False, "SM_YAW": False}
    assert not any(v[0] for v in labels["room"].values())
    assert all(v[0] for v in labels["cut"].values())  # nothing within 0.5 m: no returns


# --- writing and reading back -------------------------------------------------------------


def test_a_simulated_run_gets_the_faults_and_keeps_its_own_truth(short_run, tmp_path):
    cfg = InputConfig()
    before = read_recording(short_run.run_dir, cfg)
    res = inject(short_run.run_dir, ["dipole@3:9,moment_A_m2=50,distance_m=1", "gyro_bias@12:16,bias_deg_s=3",
                                     "laser_cut@16:20,range_m=0.3"], tmp_path / "run", cfg)
    after = read_recording(tmp_path / "run", cfg)
    truth = json.loads((tmp_path / "run" / "truth.json").read_text())
    assert truth["t0"] == before.t0 and [f["fault"].split("@")[0] for f in truth["injected"]] == ["dipole", "gyro_bias", "laser_cut"]
    # The compass changes inside the dipole's interval only.
    change = np.degrees(np.abs(wrap_angle(after.compass.yaw - before.compass.yaw)))
    outside = (before.compass.t < 3.0) | (before.compass.t > 9.0)
    assert change[outside].max() < 1e-9 and change.max() > 5.0
    assert res.injected["IMU_YAW"] and all(3.0 <= a <= b <= 9.0 for a, b in res.injected["IMU_YAW"])
    # The simulator's own compass fault is still there (union).
    for a, b in before.faults["IMU_YAW"]:
        assert any(x <= a and b <= y for x, y in after.faults["IMU_YAW"])
    rate = after.gyro.rate - before.gyro.rate
    assert rate[(before.gyro.t > 12.1) & (before.gyro.t < 15.9)] == pytest.approx(np.radians(3.0))
    assert res.injected["IMU_GYRO"] == [pytest.approx((12.0, 16.0), abs=0.02)]
    cut = (before.scans.t >= 16.0) & (before.scans.t <= 20.0)
    assert np.isinf(after.scans.ranges[cut]).all() and np.array_equal(after.scans.ranges[~cut], before.scans.ranges[~cut])
    assert {"SM_DIST", "SM_LAT", "SM_YAW"} <= set(res.injected)


def test_labels_follow_the_time_offset_of_the_stream_they_were_written_into(short_run, tmp_path):
    """The fault goes into the messages as stamped; its labels are moved by the
    stream's ``input.time_offsets_s``, as the samples are when mapped."""
    faults = ["dipole@3:9,moment_A_m2=50,distance_m=1", "gyro_bias@12:16,bias_deg_s=3"]
    plain = inject(short_run.run_dir, faults, tmp_path / "plain", InputConfig())
    shifted_config = InputConfig(time_offsets_s={"compass": 0.25})
    shifted = inject(short_run.run_dir, faults, tmp_path / "shifted", shifted_config)
    assert plain.injected["IMU_YAW"] and shifted.injected["IMU_YAW"] == [
        pytest.approx((a + 0.25, b + 0.25)) for a, b in plain.injected["IMU_YAW"]
    ]
    assert shifted.injected["IMU_GYRO"] == plain.injected["IMU_GYRO"]  # the gyro's stamps are right
    # Mapped with the same offset, the disturbed compass samples lie in the labels.
    before = read_recording(short_run.run_dir, shifted_config)
    after = read_recording(tmp_path / "shifted", shifted_config)
    disturbed = after.compass.t[np.abs(wrap_angle(after.compass.yaw - before.compass.yaw)) > np.radians(5.0)]
    assert len(disturbed) and all(any(a <= t <= b for a, b in after.faults["IMU_YAW"]) for t in disturbed)


@pytest.mark.slow
def test_a_ned_bag_takes_a_heading_fault_in_its_own_frame(tmp_path):
    bag = ned_driving_bag(duration_s=40.0)[0].write(tmp_path / "ned.bag")
    frames = {"compass": StreamFrameConfig(world="ned"), "odometry": StreamFrameConfig(world="ned"),
              "groundtruth": StreamFrameConfig(world="ned"), "gyro": StreamFrameConfig(body="frd")}
    cfg = InputConfig.model_validate({
        "topics": {"scan": None, "gyro": "/imu/data", "compass": "/imu/data", "odometry": "/odom", "gps": "/fix",
                   "groundtruth": "/ground_truth"},
        "compass": {"source": "imu_orientation"}, "frames": frames})
    before = read_recording(bag, cfg)
    inject(bag, ["dipole@10:20,moment_A_m2=300,distance_m=1.5"], tmp_path / "run", cfg)
    after = read_recording(tmp_path / "run", cfg)
    dipole = physics.Dipole(parse_fault("dipole@10:20,moment_A_m2=300,distance_m=1.5"), before.groundtruth)
    expected = physics.heading_error(before.compass.yaw, dipole.field_body(before.compass.t), 20e-6)
    assert wrap_angle(after.compass.yaw - before.compass.yaw) == pytest.approx(expected, abs=1e-6)
    assert np.degrees(np.abs(expected)).max() > 5.0
    assert np.array_equal(after.odometry.x, before.odometry.x)


def test_an_mcap_file_with_a_json_channel_takes_faults_and_the_copy_leaves_the_channel_out(tmp_path, caplog):
    pytest.importorskip("mcap.writer", reason="the test extra installs mcap")
    drive = next(driving_bag(ros=2, duration_s=1.0).write(tmp_path / "drive", storage="mcap").glob("*.mcap"))
    mixed = with_foreign_channel(drive, tmp_path / "mixed.mcap", "/diagnostics")
    with caplog.at_level(logging.WARNING):
        inject(mixed, ["gyro_bias@0.2:0.6"], tmp_path / "run", InputConfig())
    said = [r.getMessage() for r in caplog.records if r.levelno >= logging.WARNING]
    assert f"{mixed}: topic '/diagnostics' not copied: its messages are json, not ROS 2's CDR" in said
    reader = open_bag(tmp_path / "run" / "bag")
    try:
        topics = {c.topic for c in reader.connections}
    finally:
        reader.close()
    assert "/diagnostics" not in topics and {"/imu/data", "/odom", "/scan"} <= topics
    before, after = read_recording(drive, InputConfig()), read_recording(tmp_path / "run", InputConfig())
    assert np.array_equal(after.odometry.x, before.odometry.x)
    assert not np.array_equal(after.gyro.rate, before.gyro.rate)


def test_a_split_bag_with_a_json_channel_takes_faults_into_one_bag(tmp_path):
    """Both MCAP files of a split bag are copied as one bag, a topic of both
    files one connection (rosbags' writer refuses a connection added twice)."""
    pytest.importorskip("mcap.writer", reason="the test extra installs mcap")
    whole = driving_bag(ros=2, duration_s=1.0).write(tmp_path / "drive", storage="mcap")
    split = split_mcap(whole, tmp_path / "split", foreign={1: ("/diagnostics", "json", "jsonschema")})
    inject(split, ["gyro_bias@0.2:0.6"], tmp_path / "run", InputConfig())
    before, after = read_recording(whole, InputConfig()), read_recording(tmp_path / "run", InputConfig())
    assert np.array_equal(after.odometry.x, before.odometry.x) and np.array_equal(after.scans.t, before.scans.t)
    assert not np.array_equal(after.gyro.rate, before.gyro.rate)


def test_faults_a_recording_cannot_have_are_refused(short_run, tmp_path):
    with pytest.raises(GslamError, match="the recording has no gps"):
        inject(short_run.run_dir, ["multipath@1:3"], tmp_path / "x", InputConfig(topics={"gps": None}))
    with pytest.raises(GslamError, match="starts after the recording ends"):
        inject(short_run.run_dir, ["gyro_bias@1000:1001"], tmp_path / "x", InputConfig())
    assert not (tmp_path / "x").exists()


@pytest.mark.slow
def test_the_command_writes_a_run_folder_map_reads(short_run, tmp_path, capsys):
    out = tmp_path / "run"
    argv = ["-q", "inject", str(short_run.run_dir), "--fault", "gyro_bias@5:10,bias_deg_s=4", "--out", str(out)]
    assert main(argv) == 0
    assert "injected faults IMU_GYRO: 5.0-10.0 s" in capsys.readouterr().out
    assert json.loads((out / ".gslam-result.json").read_text())["command"] == "inject"
    assert main(argv) == 0  # its own earlier result is replaced
    assert main(["-q", "map", str(out), "--config", str(CONFIGS / "telemax.yaml"), "--out", str(tmp_path / "m"),
                 "--set", "output.plots=false"]) == 0


# --- real recordings ------------------------------------------------------------------------


def test_real_carmen_log_laser_cut_and_slip(tmp_path):
    log = real_data("carmen/aces-corrected.log.gz")
    cfg = load_config(CONFIGS / "datasets" / "carmen.yaml").input
    before = read_recording(log, cfg)
    res = inject(log, ["laser_cut@200:400,range_m=4", "slip@800:900,scale=1.5"], tmp_path / "run", cfg)
    after = read_recording(tmp_path / "run", cfg)
    cut = (before.scans.t >= 200) & (before.scans.t <= 400)
    kept = after.scans.ranges[cut][after.scans.ranges[cut] < after.scans.range_max]
    assert kept.max() <= 4.0 and np.array_equal(after.scans.ranges[~cut], before.scans.ranges[~cut])
    assert after.scans.range_max == before.scans.range_max
    early = before.odometry.t < 800
    assert np.array_equal(after.odometry.x[early], before.odometry.x[early])
    assert not np.allclose(after.odometry.x[~early], before.odometry.x[~early])
    assert res.injected["ODO_DIST"] and all(800 <= a and b <= 900 for a, b in res.injected["ODO_DIST"])


@pytest.mark.slow
def test_real_broad_trial_magnetometer_dipole(tmp_path):
    trial = real_data("broad/02_undisturbed_slow_rotation_B.mat")
    cfg = InputConfig(format="broad")
    before = read_recording(trial, cfg)
    res = inject(trial, ["dipole@60:70,moment_A_m2=5,distance_m=0.3"], tmp_path / "run", cfg)
    after = read_recording(tmp_path / "run", cfg)
    assert after.faults["IMU_YAW"] == res.faults["IMU_YAW"] and res.injected["IMU_YAW"]
    t = np.intersect1d(before.compass.t, after.compass.t)
    change = np.degrees(np.abs(wrap_angle(np.interp(t, after.compass.t, np.unwrap(after.compass.yaw))
                                          - np.interp(t, before.compass.t, np.unwrap(before.compass.yaw)))))
    assert change[(t < 59.9) | (t > 70.1)].max() < 1e-6 and change[(t > 60) & (t < 70)].max() > 10.0


@pytest.mark.slow
def test_real_husky_bag_compass_dipole(tmp_path):
    bag = real_data("rosbag/test1_husky_2015.bag")
    cfg = load_config(CONFIGS / "datasets" / "husky.yaml").input
    before = read_recording(bag, cfg)
    res = inject(bag, ["dipole@100:115,moment_A_m2=2000,distance_m=3"], tmp_path / "run", cfg)
    after = read_recording(tmp_path / "run", cfg)
    change = np.degrees(np.abs(wrap_angle(after.compass.yaw - before.compass.yaw)))
    assert change[(before.compass.t < 100) | (before.compass.t > 115)].max() < 1e-6 and change.max() > 20.0
    assert after.gyro.rate == pytest.approx(before.gyro.rate, abs=1e-12)  # the vertical rate ignores a turn about the vertical
    (a, b), = res.injected["IMU_YAW"]
    assert 100 <= a < b <= 115
