"""The ROS 1 / ROS 2 bag reader and the reader registry, on tiny bags built
with known values (tests/bagfactory.py) and on one real Husky bag."""

from __future__ import annotations

import json
import logging
from pathlib import Path

import numpy as np
import pytest

from bagfactory import IMU, BagBuilder, driving_bag, split_mcap, with_foreign_channel
from conftest import real_data
from slam.config import InputConfig
from slam.errors import GslamError
from validation.base.geometry import geodetic_from_enu, wrap_angle
from slam.readers.read import guess_format, read_recording
from slam.readers.rosbag import LASER_SCAN, MAGNETIC_FIELD, ODOMETRY, POSE_STAMPED, message_type_problem, read_rosbag

T0 = 1_700_000_000.0
NONE = {k: None for k in ("scan", "gyro", "compass", "odometry", "gps", "groundtruth")}


def only(**topics: str | None) -> dict:
    """A topics mapping with every stream off except those given."""
    return {**NONE, **topics}


def config(topics: dict | None = None, **sections: dict) -> InputConfig:
    return InputConfig.model_validate({"topics": topics if topics is not None else {}, **sections})


def error_of(fn, *args) -> str:
    """The message of the GslamError ``fn(*args)`` raises; it must be one line."""
    with pytest.raises(GslamError) as info:
        fn(*args)
    msg = str(info.value)
    assert "\n" not in msg and msg.strip() == msg and msg
    return msg


@pytest.fixture(params=[1, 2], ids=["ros1", "ros2"])
def ros(request) -> int:
    return request.param


# --- values round-trip -----------------------------------------------------


def test_scan_gyro_odometry_roundtrip(tmp_path, ros):
    bag = BagBuilder(ros)
    ranges = [[1.0, np.inf, 3.0, np.nan], [0.5, 0.6, 0.7, 0.8], [9.0, 8.0, 7.0, 6.0]]
    for i, r in enumerate(ranges):
        bag.scan(
            "/scan", T0 + 0.1 + 0.1 * i, r, angle_min=-0.3, angle_increment=0.2, range_min=0.2, range_max=20.0
        )
    for i in range(5):
        bag.imu("/imu/data", T0 + 0.01 * i, rate_z=0.1 * i - 0.2)
    bag.odom("/odom", T0 + 0.05, 1.0, 2.0, 0.3)
    bag.odom("/odom", T0 + 0.25, 1.5, -2.0, -3.0)
    path = bag.write_in(tmp_path)
    rec = read_rosbag(path, config(only(scan="/scan", gyro="/imu/data", odometry="/odom")))

    assert rec.name == "run"
    assert rec.t0 == pytest.approx(T0, abs=1e-6)
    np.testing.assert_allclose(rec.scans.t, [0.1, 0.2, 0.3], atol=1e-6)
    assert rec.scans.ranges.dtype == np.float32 and rec.scans.ranges.shape == (3, 4)
    np.testing.assert_array_equal(rec.scans.ranges, np.asarray(ranges, dtype=np.float32))
    np.testing.assert_allclose(rec.scans.angles, [-0.3, -0.1, 0.1, 0.3], atol=1e-6)
    assert rec.scans.range_min == pytest.approx(0.2) and rec.scans.range_max == pytest.approx(20.0)
    np.testing.assert_allclose(rec.gyro.t, [0.0, 0.01, 0.02, 0.03, 0.04], atol=1e-6)
    np.testing.assert_allclose(rec.gyro.rate, [-0.2, -0.1, 0.0, 0.1, 0.2], atol=1e-12)
    np.testing.assert_allclose(rec.odometry.t, [0.05, 0.25], atol=1e-6)
    np.testing.assert_allclose(rec.odometry.x, [1.0, 1.5])
    np.testing.assert_allclose(rec.odometry.y, [2.0, -2.0])
    np.testing.assert_allclose(rec.odometry.yaw, [0.3, -3.0], atol=1e-12)
    assert rec.compass is None and rec.gps is None and rec.groundtruth is None
    assert rec.duration == pytest.approx(0.3, abs=1e-6)


def test_t0_is_earliest_used_stream_and_header_stamps_are_used(tmp_path, ros):
    bag = BagBuilder(ros)
    bag.imu("/early", T0 - 5.0, rate_z=1.0)  # present but not configured
    bag.imu("/imu/data", T0 + 2.0, rate_z=1.0, log_t=T0 + 9.0)
    bag.imu("/imu/data", T0 + 3.0, rate_z=1.0, log_t=T0 + 9.5)
    bag.odom("/odom", T0 + 1.25, 0.0, 0.0, 0.0)
    rec = read_rosbag(bag.write_in(tmp_path), config(only(gyro="/imu/data", odometry="/odom")))
    assert rec.t0 == pytest.approx(T0 + 1.25, abs=1e-6)
    assert rec.gyro.t.dtype == np.float64
    np.testing.assert_allclose(rec.gyro.t, [0.75, 1.75], atol=1e-6)
    np.testing.assert_allclose(rec.odometry.t, [0.0], atol=1e-6)


def test_groundtruth_from_pose_stamped_and_odometry(tmp_path):
    bag = BagBuilder(2)
    bag.pose("/gt_pose", T0, 3.0, 4.0, 1.0)
    bag.odom("/gt_odom", T0, -3.0, 4.0, -1.0)
    path = bag.write_in(tmp_path)
    for topic, x, yaw in (("/gt_pose", 3.0, 1.0), ("/gt_odom", -3.0, -1.0)):
        rec = read_rosbag(path, config(only(groundtruth=topic)))
        assert (rec.groundtruth.x[0], rec.groundtruth.y[0]) == pytest.approx((x, 4.0))
        assert rec.groundtruth.yaw[0] == pytest.approx(yaw)


def _field_seen_by_sensor(robot_yaw: float, declination: float, mounting: float) -> tuple[float, ...]:
    """The Earth field (20 uT horizontal, 40 uT down) in the frame of a level
    sensor mounted at ``mounting`` on a robot at world yaw ``robot_yaw``."""
    north_world = np.pi / 2 - declination  # magnetic north lies east of true north
    a = north_world - (robot_yaw + mounting)
    return 20e-6 * np.cos(a), 20e-6 * np.sin(a), -40e-6


def test_compass_from_magnetic_field_with_declination_and_mounting(tmp_path, ros):
    declination, mounting = np.radians(10.0), np.radians(90.0)
    yaws = [0.0, 1.0, -2.5, 3.1]
    bag = BagBuilder(ros)
    for i, yaw in enumerate(yaws):
        bag.mag("/mag", T0 + i, _field_seen_by_sensor(yaw, declination, mounting))
    cfg = config(only(compass="/mag"), compass={"declination_deg": 10.0, "mounting_yaw_deg": 90.0})
    rec = read_rosbag(bag.write_in(tmp_path), cfg)
    np.testing.assert_allclose(wrap_angle(rec.compass.yaw - np.array(yaws)), 0.0, atol=1e-9)
    assert rec.compass.field.shape == (4, 3)
    np.testing.assert_allclose(rec.compass.field[0], _field_seen_by_sensor(0.0, declination, mounting))


def test_compass_from_imu_orientation(tmp_path, ros):
    declination, mounting = np.radians(-7.0), np.radians(30.0)
    yaws = [0.0, 1.0, -2.5, 3.1]
    bag = BagBuilder(ros)
    for i, yaw in enumerate(yaws):
        # The AHRS measures yaw from magnetic east: a sensor at true yaw y
        # reports y + declination (magnetic north is declination east of north).
        bag.imu("/imu", T0 + i, yaw=yaw + mounting + declination)
    cfg = config(
        only(compass="/imu"),
        compass={"source": "imu_orientation", "declination_deg": -7.0, "mounting_yaw_deg": 30.0},
    )
    rec = read_rosbag(bag.write_in(tmp_path), cfg)
    np.testing.assert_allclose(wrap_angle(rec.compass.yaw - np.array(yaws)), 0.0, atol=1e-9)
    assert rec.compass.field is None


def test_gyro_and_compass_share_one_imu_topic(tmp_path):
    bag = BagBuilder(1)
    bag.imu("/imu", T0, rate_z=0.5, yaw=0.25)
    cfg = config(only(gyro="/imu", compass="/imu"), compass={"source": "imu_orientation"})
    rec = read_rosbag(bag.write_in(tmp_path), cfg)
    assert rec.gyro.rate[0] == pytest.approx(0.5) and rec.compass.yaw[0] == pytest.approx(0.25)


def test_gps_about_configured_datum_drops_no_fix(tmp_path, ros, caplog):
    lat0, lon0 = 48.1, 11.5
    east, north = [0.0, 10.0, -25.0, 40.0], [0.0, 5.0, 30.0, -12.0]
    lat, lon = geodetic_from_enu(np.array(east), np.array(north), lat0, lon0)
    bag = BagBuilder(ros)
    bag.fix("/fix", T0 + 0.0, lat[0] + 1.0, lon[0], status=-1)  # NO_FIX: dropped
    bag.fix("/fix", T0 + 1.0, lat[0], lon[0], status=0, variance_m2=(4.0, 9.0))
    bag.fix("/fix", T0 + 2.0, lat[1], lon[1], status=1, variance_m2=(1.0, 1.0))
    bag.fix("/fix", T0 + 2.5, float("nan"), float("nan"), status=0)  # no position: dropped
    bag.fix("/fix", T0 + 3.0, lat[2], lon[2], status=2, covariance_type=0)
    bag.fix("/fix", T0 + 4.0, lat[3], lon[3], status=0, variance_m2=(0.25, 0.25))
    cfg = config(only(gps="/fix"), gps={"datum_lat_deg": lat0, "datum_lon_deg": lon0})
    with caplog.at_level(logging.INFO, logger="slam.readers.rosbag"):
        rec = read_rosbag(bag.write_in(tmp_path), cfg)
    assert "dropped 2 fixes" in caplog.text
    gps = rec.gps
    np.testing.assert_allclose(gps.x, east, atol=1e-6)
    np.testing.assert_allclose(gps.y, north, atol=1e-6)
    np.testing.assert_allclose(gps.t, [0.0, 1.0, 2.0, 3.0], atol=1e-6)  # t0 = first kept fix
    assert rec.t0 == pytest.approx(T0 + 1.0, abs=1e-6)
    np.testing.assert_allclose(gps.sigma[[0, 1, 3]], [np.sqrt(6.5), 1.0, 0.5])
    assert np.isnan(gps.sigma[2])  # covariance type unknown
    np.testing.assert_array_equal(gps.status, [0, 1, 2, 0])


def test_gps_first_fix_datum(tmp_path):
    lat, lon = geodetic_from_enu(np.array([7.0, 10.0]), np.array([-3.0, 1.0]), 40.0, -3.0)
    bag = BagBuilder(1)
    bag.fix("/fix", T0, lat[0], lon[0])
    bag.fix("/fix", T0 + 1, lat[1], lon[1])
    rec = read_rosbag(bag.write_in(tmp_path), config(only(gps="/fix")))
    np.testing.assert_allclose(rec.gps.x, [0.0, 3.0], atol=1e-6)
    np.testing.assert_allclose(rec.gps.y, [0.0, 4.0], atol=1e-6)


def test_gps_all_without_fix_gives_no_stream(tmp_path):
    bag = BagBuilder(2)
    bag.fix("/fix", T0, 48.0, 11.0, status=-1)
    bag.odom("/odom", T0, 0, 0, 0)
    rec = read_rosbag(bag.write_in(tmp_path), config(only(gps="/fix", odometry="/odom")))
    assert rec.gps is None and len(rec.odometry) == 1


# --- formats, remapping, run folders --------------------------------------


def test_default_topics_and_every_rosbag2_form(tmp_path):
    bag = driving_bag(ros=2, duration_s=1.0)
    folder = bag.write(tmp_path / "drive_mcap", storage="mcap")
    sqlite = bag.write(tmp_path / "drive_db3")
    paths = [folder, sqlite, next(folder.glob("*.mcap")), next(sqlite.glob("*.db3"))]
    for path in paths:
        assert guess_format(path) == "rosbag"
        rec = read_recording(path, InputConfig())
        assert (len(rec.scans), len(rec.gyro.t), len(rec.compass.t)) == (10, 100, 20)
        assert (len(rec.odometry), len(rec.gps.t), len(rec.groundtruth)) == (20, 5, 100)
        np.testing.assert_allclose(rec.compass.yaw, 0.5, atol=1e-9)
        np.testing.assert_allclose(rec.gps.x, rec.groundtruth.x[::20], atol=1e-6)
        np.testing.assert_allclose(rec.gps.y, rec.groundtruth.y[::20], atol=1e-6)
    assert guess_format(driving_bag(ros=1, duration_s=0.1).write(tmp_path / "a.bag")) == "rosbag"


@pytest.fixture
def drive_mcap(tmp_path) -> Path:
    """The MCAP file of a short ROS 2 drive."""
    pytest.importorskip("mcap.writer", reason="the test extra installs mcap")
    return next(driving_bag(ros=2, duration_s=1.0).write(tmp_path / "drive", storage="mcap").glob("*.mcap"))


@pytest.mark.parametrize("encoding, schema", [("json", "jsonschema"), ("json", ""), ("protobuf", "protobuf")],
                         ids=["json", "json-schemaless", "protobuf"])
def test_an_mcap_channel_of_another_encoding_is_skipped_with_one_warning(drive_mcap, tmp_path, caplog, encoding,
                                                                         schema):
    """A tool's own channel in a ROS 2 MCAP file (rosbags refuses the file
    when the channel has a schema that is not a ROS 2 definition): the
    needed topics are read as without it, the channel named in a warning."""
    mixed = with_foreign_channel(drive_mcap, tmp_path / "mixed.mcap", "/diagnostics", encoding, schema)
    plain = read_recording(drive_mcap, InputConfig())
    with caplog.at_level(logging.WARNING):
        rec = read_recording(mixed, InputConfig())
    said = [r.getMessage() for r in caplog.records if r.levelno >= logging.WARNING]
    assert said == [f"{mixed}: topic '/diagnostics' skipped: its messages are {encoding}, not ROS 2's CDR"]
    assert rec.t0 == plain.t0 and len(rec.scans) == len(plain.scans)
    for a, b in ((rec.gyro.t, plain.gyro.t), (rec.compass.yaw, plain.compass.yaw), (rec.odometry.x, plain.odometry.x),
                 (rec.gps.x, plain.gps.x), (rec.groundtruth.y, plain.groundtruth.y)):
        assert np.array_equal(a, b)


@pytest.mark.parametrize("schema", ["jsonschema", ""], ids=["json", "json-schemaless"])
def test_a_needed_mcap_topic_of_another_encoding_is_one_error(drive_mcap, tmp_path, schema):
    mixed = with_foreign_channel(drive_mcap, tmp_path / "mixed.mcap", "/odom", "json", schema)
    msg = error_of(read_recording, mixed, InputConfig())
    assert msg == (f"{mixed}: odometry topic '/odom': its messages are json, expected ROS 2's CDR "
                   "(a nav_msgs/msg/Odometry)")


@pytest.mark.parametrize("foreign", [
    {1: ("/diagnostics", "json", "jsonschema")},
    {0: ("/foxglove", "protobuf", "protobuf")},
    {0: ("/diagnostics", "json", ""), 1: ("/diagnostics", "json", "jsonschema")},
], ids=["json-in-the-second", "protobuf-in-the-first", "json-in-both"])
def test_a_split_bag_with_foreign_channels_is_read_for_its_ros2_topics(tmp_path, caplog, foreign):
    """A rosbag2 folder split into two MCAP files, another tool's channel
    in one or both (rosbags refused the folder: 'not a readable ROS bag
    ('jsonschema')'): the needed topics of both files are read as from the
    folder unsplit, and each foreign topic named in one warning."""
    pytest.importorskip("mcap.writer", reason="the test extra installs mcap")
    whole = driving_bag(ros=2, duration_s=1.0).write(tmp_path / "drive", storage="mcap")
    split = split_mcap(whole, tmp_path / "split", foreign=foreign)
    assert len(list(split.glob("*.mcap"))) == 2
    plain = read_recording(whole, InputConfig())
    with caplog.at_level(logging.WARNING):
        rec = read_recording(split, InputConfig())
    said = [r.getMessage() for r in caplog.records if r.levelno >= logging.WARNING]
    topics = sorted({topic: encoding for topic, encoding, _ in foreign.values()}.items())
    assert said == [f"{split}: topic '{t}' skipped: its messages are {e}, not ROS 2's CDR" for t, e in topics]
    assert rec.t0 == plain.t0 and len(rec.scans) == len(plain.scans)
    for a, b in ((rec.gyro.t, plain.gyro.t), (rec.compass.yaw, plain.compass.yaw), (rec.odometry.x, plain.odometry.x),
                 (rec.gps.x, plain.gps.x), (rec.groundtruth.y, plain.groundtruth.y), (rec.scans.t, plain.scans.t),
                 (rec.scans.ranges, plain.scans.ranges)):
        assert np.array_equal(a, b)


def test_a_needed_topic_of_another_encoding_in_one_file_of_a_split_bag_is_one_error(tmp_path):
    pytest.importorskip("mcap.writer", reason="the test extra installs mcap")
    whole = driving_bag(ros=2, duration_s=1.0).write(tmp_path / "drive", storage="mcap")
    split = split_mcap(whole, tmp_path / "split", foreign={1: ("/odom", "json", "jsonschema")})
    msg = error_of(read_recording, split, InputConfig())
    assert msg == (f"{split}: odometry topic '/odom': its messages are json, expected ROS 2's CDR "
                   "(a nav_msgs/msg/Odometry)")


def test_topic_remapping_by_config_alone(tmp_path, ros):
    bag = BagBuilder(ros)
    bag.scan("/front_laser/scan", T0, [1.0, 2.0])
    bag.imu("/xsens/imu", T0, rate_z=0.3)
    bag.mag("/xsens/mag", T0, (0.0, 2e-5, 0.0))
    bag.odom("/tracks/odom", T0, 1.0, 0.0, 0.0)
    bag.fix("/ublox/fix", T0, 48.0, 11.0)
    bag.pose("/vicon/pose", T0, 2.0, 0.0, 0.0)
    path = bag.write_in(tmp_path)
    with pytest.raises(GslamError):
        read_rosbag(path, InputConfig())
    topics = {
        "scan": "/front_laser/scan",
        "gyro": "/xsens/imu",
        "compass": "/xsens/mag",
        "odometry": "/tracks/odom",
        "gps": "/ublox/fix",
        "groundtruth": "/vicon/pose",
    }
    rec = read_rosbag(path, config(topics))
    assert rec.scans.ranges.shape == (1, 2) and rec.gyro.rate[0] == pytest.approx(0.3)
    assert rec.compass.yaw[0] == pytest.approx(0.0, abs=1e-12)  # field along +y: facing east
    assert rec.odometry.x[0] == 1.0 and rec.gps.x[0] == 0.0 and rec.groundtruth.x[0] == 2.0


def _run_folder(tmp_path: Path, ros: int, truth_t0: float, gps_datum: bool = True) -> Path:
    run = tmp_path / "straight_42"
    if ros == 1:
        (run / "bag").mkdir(parents=True)
        driving_bag(ros=1, t0=T0, duration_s=1.0, datum=(48.0, 11.0)).write(run / "bag" / "run.bag")
    else:
        run.mkdir()
        driving_bag(ros=2, t0=T0, duration_s=1.0, datum=(48.0, 11.0)).write(run / "bag")
    truth = {
        "scenario": "straight",
        "seed": 42,
        "t0": truth_t0,
        "duration_s": 1.0,
        "faults": {"SM": [[0.2, 0.6]], "GPS": [[0.0, 0.1], [0.5, 0.9]], "ODO": []},
        "magnetic_reference": {"strength_T": 4.5e-5, "dip_rad": 1.1, "declination_rad": 0.05},
        "future_key": "ignored",
    }
    if gps_datum:
        # A datum 10 m south-west of the bag's, so the offset is visible.
        lat, lon = geodetic_from_enu(-10.0, -10.0, 48.0, 11.0)
        truth["gps_datum"] = {"lat_deg": float(lat), "lon_deg": float(lon)}
    (run / "truth.json").write_text(json.dumps(truth))
    return run


def test_run_folder_shifts_faults_and_attaches_sidecar(tmp_path, ros):
    run = _run_folder(tmp_path, ros, truth_t0=T0 - 2.0)
    assert guess_format(run) == "rosbag"
    rec = read_recording(run, InputConfig())
    assert rec.name == "straight_42"
    assert rec.t0 == pytest.approx(T0, abs=1e-6)
    # A whole-sensor label (as older run folders have) stands for every modality.
    for modality in ("SM_DIST", "SM_LAT", "SM_YAW"):
        assert rec.faults[modality] == [pytest.approx((-1.8, -1.4))]
    assert rec.faults["GPS"] == [pytest.approx((-2.0, -1.9)), pytest.approx((-1.5, -1.1))]
    assert rec.faults["ODO_DIST"] == [] and rec.faults["ODO_YAW"] == []
    ref = rec.magnetic_reference
    assert (ref.strength_T, ref.dip_rad, ref.declination_rad) == (4.5e-5, 1.1, 0.05)
    # The sidecar datum is used: the first fix (at the bag datum) is 10 m NE of it.
    assert (rec.gps.x[0], rec.gps.y[0]) == pytest.approx((10.0, 10.0), abs=1e-3)
    # A datum in the config wins over the sidecar's.
    own = read_recording(run, config(gps={"datum_lat_deg": 48.0, "datum_lon_deg": 11.0}))
    assert (own.gps.x[0], own.gps.y[0]) == pytest.approx((0.0, 0.0), abs=1e-6)


def test_run_folder_without_datum_uses_first_fix(tmp_path):
    rec = read_recording(_run_folder(tmp_path, 2, truth_t0=T0 + 0.5, gps_datum=False), InputConfig())
    assert rec.faults["SM_YAW"] == [pytest.approx((0.7, 1.1))]
    assert (rec.gps.x[0], rec.gps.y[0]) == (0.0, 0.0)


def test_bad_sidecar_is_one_line(tmp_path):
    run = _run_folder(tmp_path, 2, truth_t0=T0)
    (run / "truth.json").write_text('{"t0": 1,\n "faults": ')
    msg = error_of(read_recording, run, InputConfig())
    assert "truth.json" in msg and "line 2" in msg
    (run / "truth.json").write_text(json.dumps({"t0": 1.0, "faults": {"LIDAR": [[0, 1]]}}))
    msg = error_of(read_recording, run, InputConfig())
    assert "truth.json" in msg and "LIDAR" in msg
    (run / "truth.json").write_text(json.dumps({"faults": {}}))
    assert "t0" in error_of(read_recording, run, InputConfig())


def test_missing_groundtruth_is_optional(tmp_path, caplog):
    bag = BagBuilder(1)
    bag.odom("/odom", T0, 0, 0, 0)
    with caplog.at_level(logging.WARNING):
        rec = read_rosbag(bag.write_in(tmp_path), config(only(odometry="/odom", groundtruth="/gt")))
    assert rec.groundtruth is None and "/gt" in caplog.text


# --- errors: one line, naming topic and file --------------------------------


def test_missing_topic_names_it_and_lists_topics(tmp_path, ros):
    bag = BagBuilder(ros)
    bag.imu("/imu/data", T0)
    bag.odom("/odom", T0, 0, 0, 0)
    path = bag.write_in(tmp_path)
    msg = error_of(read_rosbag, path, config(only(gyro="/imu/data", scan="/laser")))
    assert str(path) in msg and "'/laser'" in msg and "/imu/data, /odom" in msg


def test_empty_stream(tmp_path, ros):
    bag = BagBuilder(ros)
    bag.topic("/scan", "sensor_msgs/msg/LaserScan")
    bag.imu("/imu/data", T0)
    path = bag.write_in(tmp_path)
    msg = error_of(read_rosbag, path, config(only(gyro="/imu/data", scan="/scan")))
    assert "'/scan'" in msg and "no messages" in msg and str(path) in msg


@pytest.mark.parametrize("second,kind", [(T0, "duplicate"), (T0 - 0.5, "decreasing")])
def test_unsorted_or_duplicate_stamps(tmp_path, ros, second, kind):
    bag = BagBuilder(ros)
    bag.imu("/imu/data", T0, log_t=T0)
    bag.imu("/imu/data", second, log_t=T0 + 1)
    msg = error_of(read_rosbag, bag.write_in(tmp_path), config(only(gyro="/imu/data")))
    assert kind in msg and "'/imu/data'" in msg and "message 1" in msg


def test_non_finite_values_name_topic_and_field(tmp_path, ros):
    bag = BagBuilder(ros)
    bag.imu("/imu/data", T0, rate_z=0.0)
    bag.imu("/imu/data", T0 + 1, rate_z=np.nan)
    bag.odom("/odom", T0, 0, 0, 0)
    bag.odom("/odom", T0 + 1, np.inf, 0, 0)
    path = bag.write_in(tmp_path)
    msg = error_of(read_rosbag, path, config(only(gyro="/imu/data")))
    assert "'/imu/data'" in msg and "angular_velocity.z" in msg and "message 1" in msg
    msg = error_of(read_rosbag, path, config(only(odometry="/odom")))
    assert "'/odom'" in msg and "pose.position" in msg


def test_wrong_message_type(tmp_path, ros):
    bag = BagBuilder(ros)
    bag.imu("/scan", T0)
    path = bag.write_in(tmp_path)
    msg = error_of(read_rosbag, path, config(only(scan="/scan")))
    assert "'/scan'" in msg and IMU in msg and "expected sensor_msgs/msg/LaserScan" in msg
    msg = error_of(read_rosbag, path, config(only(groundtruth="/scan")))
    assert "expected nav_msgs/msg/Odometry or geometry_msgs/msg/PoseStamped" in msg
    msg = error_of(read_rosbag, path, config(only(compass="/scan")))
    assert "expected sensor_msgs/msg/MagneticField" in msg


CUSTOM = "my_driver/msg/YawRate"


@pytest.mark.parametrize("ros, storage", [(1, "sqlite3"), (2, "sqlite3"), (2, "mcap")], ids=["ros1", "db3", "mcap"])
def test_a_message_type_of_another_package_is_named_with_the_one_expected(tmp_path, ros, storage):
    """A driver's own message type on the configured topic: the error names
    the type found and the type expected, never 'no messages'."""
    from rosbags.typesys import get_types_from_msg

    bag = BagBuilder(ros)
    bag.typestore.register(get_types_from_msg("std_msgs/Header header\nfloat64 yaw_rate\n", CUSTOM))
    for i in range(5):
        bag.add("/imu/data", CUSTOM, bag.typestore.types[CUSTOM](header=bag.header(T0 + i), yaw_rate=0.1), T0 + i)
        bag.odom("/odom", T0 + i, 0.1 * i, 0, 0)
    path = bag.write(tmp_path / ("run.bag" if ros == 1 else "run"), storage)
    msg = error_of(read_rosbag, path, config(only(gyro="/imu/data", odometry="/odom")))
    assert msg == f"{path}: gyro topic '/imu/data': type is {CUSTOM}, expected {IMU}", msg
    msg = error_of(read_rosbag, path, config(only(compass="/imu/data", odometry="/odom")))
    assert f"type is {CUSTOM}, expected {MAGNETIC_FIELD}" in msg and "no messages" not in msg


def test_the_decision_on_a_topics_message_types():
    assert message_type_problem([IMU], (IMU,)) is None
    assert message_type_problem([ODOMETRY], (ODOMETRY, POSE_STAMPED)) is None
    assert message_type_problem([CUSTOM], (IMU,)) == f"type is {CUSTOM}, expected {IMU}"
    assert message_type_problem([CUSTOM], (ODOMETRY, POSE_STAMPED)) == \
        f"type is {CUSTOM}, expected {ODOMETRY} or {POSE_STAMPED}"
    assert message_type_problem(sorted([CUSTOM, IMU]), (IMU,)) == \
        f"carries {IMU} and also {CUSTOM} (two publishers?); expected only {IMU}"
    assert message_type_problem(sorted([CUSTOM, LASER_SCAN]), (IMU,)) == \
        f"type is {CUSTOM} and {LASER_SCAN}, expected {IMU}"


def test_an_empty_topic_names_its_declared_type(tmp_path, ros):
    bag = BagBuilder(ros)
    bag.topic("/scan", LASER_SCAN)
    bag.imu("/imu/data", T0)
    path = bag.write_in(tmp_path)
    msg = error_of(read_rosbag, path, config(only(gyro="/imu/data", scan="/scan")))
    assert msg.endswith(f"scan topic '/scan': no messages (the bag declares the topic as {LASER_SCAN}, with none "
                        "recorded)"), msg


def test_scan_geometry_must_not_change(tmp_path):
    bag = BagBuilder(1)
    bag.scan("/scan", T0, [1.0, 2.0, 3.0])
    bag.scan("/scan", T0 + 0.1, [1.0, 2.0])
    bag.scan("/other", T0, [1.0, 2.0], angle_min=0.0)
    bag.scan("/other", T0 + 0.1, [1.0, 2.0], angle_min=0.1)
    path = bag.write_in(tmp_path)
    msg = error_of(read_rosbag, path, config(only(scan="/scan")))
    assert "'/scan'" in msg and "2 beams" in msg and "had 3" in msg
    msg = error_of(read_rosbag, path, config(only(scan="/other")))
    assert "'/other'" in msg and "angles change at message 1" in msg


def test_imu_without_orientation_cannot_be_a_compass(tmp_path):
    bag = BagBuilder(2)
    bag.imu("/imu", T0, has_orientation=False)
    cfg = config(only(compass="/imu"), compass={"source": "imu_orientation"})
    msg = error_of(read_rosbag, bag.write_in(tmp_path), cfg)
    assert "'/imu'" in msg and "no orientation" in msg


def test_unreadable_files(tmp_path):
    missing = tmp_path / "nope.bag"
    assert "no such file" in error_of(read_recording, missing, InputConfig())
    assert str(missing) in error_of(read_rosbag, missing, InputConfig())

    fake = tmp_path / "fake.bag"
    fake.write_text("this is not a bag\n")
    msg = error_of(read_recording, fake, InputConfig())
    assert str(fake) in msg and "not a readable ROS bag" in msg

    fake_db3 = tmp_path / "fake.db3"
    fake_db3.write_bytes(b"\x00" * 2048)
    assert str(fake_db3) in error_of(read_recording, fake_db3, InputConfig())

    other = tmp_path / "notes.txt"
    other.write_text("hello")
    assert "unknown recording format" in error_of(read_recording, other, InputConfig())
    empty_dir = tmp_path / "empty"
    empty_dir.mkdir()
    assert str(empty_dir) in error_of(read_recording, empty_dir, InputConfig())


def test_truncated_or_damaged_bag(tmp_path):
    whole = driving_bag(ros=1, duration_s=2.0).write(tmp_path / "whole.bag")
    data = whole.read_bytes()
    n = len(data)
    for keep in (0.5, 0.9):
        cut = tmp_path / f"cut{keep}.bag"
        cut.write_bytes(data[: int(n * keep)])
        msg = error_of(read_recording, cut, InputConfig())
        assert str(cut) in msg and "not a readable ROS bag" in msg
    # Garbage inside a chunk: the index is intact, the messages are not.
    damaged = tmp_path / "damaged.bag"
    damaged.write_bytes(data[: int(n * 0.45)] + b"\xff" * 64 + data[int(n * 0.45) + 64 :])
    msg = error_of(read_recording, damaged, InputConfig())
    assert str(damaged) in msg and "corrupt bag" in msg


# --- real data ----------------------------------------------------------------


def test_real_husky_bag():
    path = real_data("rosbag/test1_husky_2015.bag")
    cfg = config(
        {
            "scan": None,
            "gyro": "/imu/data",
            "compass": "/imu/data",
            "odometry": "/husky_velocity_controller/odom",
            "gps": "/fix",
            "groundtruth": None,
        },
        compass={"source": "imu_orientation"},
    )
    rec = read_recording(path, cfg)
    assert rec.name == "test1_husky_2015"
    assert 390.0 < rec.duration < 400.0
    assert rec.t0 == pytest.approx(1432235497.99, abs=0.01)
    assert len(rec.gyro.t) == len(rec.compass.t) == 11865
    assert len(rec.odometry) == 3952 and 0 < len(rec.gps.t) <= 989
    assert 25.0 < len(rec.gyro.t) / rec.duration < 35.0  # a 30 Hz IMU
    for t in (rec.gyro.t, rec.odometry.t, rec.gps.t):
        assert t[0] >= 0.0 and np.all(np.diff(t) > 0)
    assert np.all(np.abs(rec.gyro.rate) < 3.0)
    assert np.all(np.abs(rec.compass.yaw) <= np.pi)
    # A drive of ~360 m that stays within a few hundred metres of its start.
    step = np.hypot(np.diff(rec.gps.x), np.diff(rec.gps.y))
    assert 250.0 < step.sum() < 500.0
    assert np.max(np.hypot(rec.gps.x, rec.gps.y)) < 300.0
    assert np.all(np.isfinite(rec.gps.sigma)) and np.all(rec.gps.sigma > 0.0)


# --- gyro axis --------------------------------------------------------------


def _rolled_imu(bag: BagBuilder, t: float, omega_body, yaw: float, roll: float, has_orientation: bool = True) -> None:
    """An Imu whose body is rolled by ``roll`` about its x axis, then yawed
    by ``yaw`` (orientation = Rz(yaw) Rx(roll)), turning at ``omega_body``."""
    cy, sy, cr, sr = np.cos(yaw / 2), np.sin(yaw / 2), np.cos(roll / 2), np.sin(roll / 2)
    # q_yaw * q_roll, (x, y, z, w)
    qx, qy, qz, qw = cy * sr, sy * sr, sy * cr, cy * cr
    types = bag.types
    cov = np.zeros(9)
    ocov = cov.copy()
    if not has_orientation:
        ocov[0] = -1.0
    msg = types[IMU](
        header=bag.header(t, "imu"),
        orientation=types["geometry_msgs/msg/Quaternion"](x=qx, y=qy, z=qz, w=qw),
        orientation_covariance=ocov,
        angular_velocity=bag._vec(*omega_body),
        angular_velocity_covariance=cov.copy(),
        linear_acceleration=bag._vec(0.0, 0.0, 9.81),
        linear_acceleration_covariance=cov.copy(),
    )
    bag.add("/imu/data", IMU, msg, t)


def test_gyro_axis_world_z_on_a_rolled_imu(tmp_path, ros):
    # Rolled +90 deg about x, body y points up: a yaw rate shows on body y.
    bag = BagBuilder(ros)
    rates = [0.3, -0.2, 0.0, 0.5]
    for i, r in enumerate(rates):
        _rolled_imu(bag, T0 + 0.1 * i, (0.0, r, 0.0), yaw=0.7 * i, roll=np.pi / 2)
    path = bag.write_in(tmp_path)
    body = read_rosbag(path, config(only(gyro="/imu/data")))
    np.testing.assert_allclose(body.gyro.rate, 0.0, atol=1e-12)  # body z is horizontal
    world = read_rosbag(path, config(only(gyro="/imu/data"), gyro={"axis": "world_z"}))
    np.testing.assert_allclose(world.gyro.rate, rates, atol=1e-9)


def test_gyro_axis_world_z_tilted_mix(tmp_path):
    # Rolled 30 deg: world z = cos(30) * body z + sin(30) * body y.
    bag = BagBuilder(1)
    roll = np.radians(30.0)
    _rolled_imu(bag, T0, (0.4, 0.2, 1.0), yaw=-2.0, roll=roll)
    _rolled_imu(bag, T0 + 0.1, (0.0, 0.0, 1.0), yaw=1.0, roll=roll)
    path = bag.write_in(tmp_path)
    rec = read_rosbag(path, config(only(gyro="/imu/data"), gyro={"axis": "world_z"}))
    expected = [np.cos(roll) * 1.0 + np.sin(roll) * 0.2, np.cos(roll)]
    np.testing.assert_allclose(rec.gyro.rate, expected, atol=1e-9)


def test_gyro_axis_errors(tmp_path):
    bag = BagBuilder(1)
    _rolled_imu(bag, T0, (0.0, 0.1, 0.0), yaw=0.0, roll=0.0)
    _rolled_imu(bag, T0 + 0.1, (0.0, 0.1, 0.0), yaw=0.0, roll=0.0, has_orientation=False)
    path = bag.write_in(tmp_path)
    msg = error_of(read_rosbag, path, config(only(gyro="/imu/data"), gyro={"axis": "world_z"}))
    assert "gyro topic '/imu/data'" in msg and "message 1 has no orientation" in msg
    # Without world_z the orientation is not needed.
    assert len(read_rosbag(path, config(only(gyro="/imu/data"))).gyro.t) == 2
    # An IMU on its side: the rate about its y axis, as a bag stores it.
    assert read_rosbag(path, config(only(gyro="/imu/data"), gyro={"axis": "y"})).gyro.rate == pytest.approx([0.1, 0.1])
    with pytest.raises(Exception):
        config(only(gyro="/imu/data"), gyro={"axis": "w"})


def test_real_husky_gyro_world_z_matches_orientation_yaw():
    path = real_data("rosbag/test1_husky_2015.bag")
    topics = only(gyro="/imu/data", compass="/imu/data")
    cfg = config(topics, gyro={"axis": "world_z"}, compass={"source": "imu_orientation"})
    rec = read_rosbag(path, cfg)
    d_yaw = wrap_angle(np.diff(rec.compass.yaw)) / np.diff(rec.compass.t)
    rate = 0.5 * (rec.gyro.rate[1:] + rec.gyro.rate[:-1])
    assert np.corrcoef(d_yaw, rate)[0, 1] > 0.95
    body = read_rosbag(path, config(topics, compass={"source": "imu_orientation"}))
    assert abs(np.corrcoef(d_yaw, 0.5 * (body.gyro.rate[1:] + body.gyro.rate[:-1]))[0, 1]) < 0.3
