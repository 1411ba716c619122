"""Fast paths against their obviously-correct reference versions, and the
iSAM2 latency bookkeeping."""

import gtsam
import numpy as np
import pytest

from slam.graph.backend import optimise
from slam.config import BackendConfig, PipelineConfig
from slam.frontend.kiss import ScanProjector, scan_points
from slam.outputs.pointcloud import map_points, voxel_downsample
from slam.graph.measurements import BetweenMeasurement, Measurements
from slam.recording import Recording, Scans, Trajectory


def _ranges(rng, n, beams):
    r = rng.uniform(0.0, 12.0, size=(n, beams)).astype(np.float32)
    r[rng.random((n, beams)) < 0.1] = np.inf
    r[rng.random((n, beams)) < 0.05] = np.nan
    return r


def _reference_voxel(points_xy, voxel_m):
    cells = np.floor(points_xy / voxel_m).astype(np.int64)
    _, first = np.unique(cells, axis=0, return_index=True)
    return points_xy[np.sort(first)]


def test_scan_projector_is_bit_identical_to_scan_points():
    rng = np.random.default_rng(0)
    angles = np.linspace(-2.3, 2.3, 91)
    ranges = _ranges(rng, 20, 91)
    project = ScanProjector(angles, 0.1, 10.0)
    for r in ranges:
        expected = scan_points(r, angles, 0.1, 10.0)
        got = project(r)
        assert got.shape == expected.shape and np.array_equal(got, expected)
    xy, row = project.planar_points(ranges)
    expected = [scan_points(r, angles, 0.1, 10.0) for r in ranges]
    assert np.array_equal(xy, np.concatenate([p[:, :2] for p in expected]))
    assert np.array_equal(row, np.repeat(np.arange(20), [len(p) for p in expected]))


def test_scan_projector_drops_the_maximum_range_and_keeps_the_minimum():
    project = ScanProjector(np.array([0.0, np.pi / 2, np.pi]), 0.5, 10.0)
    pts = project(np.array([0.5, 10.0, 2.0], dtype=np.float32))
    np.testing.assert_allclose(pts, [[0.5, 0.0, 0.0], [-2.0, 0.0, 0.0]], atol=1e-12)


@pytest.mark.parametrize("voxel", [0.05, 0.3, 2.0])
def test_voxel_downsample_keeps_the_first_point_of_each_cell(voxel):
    rng = np.random.default_rng(1)
    pts = rng.normal(0.0, 5.0, size=(5000, 2)) - [3.0, -40.0]
    assert np.array_equal(voxel_downsample(pts, voxel), _reference_voxel(pts, voxel))
    small = np.array([[0.01, 0.01], [0.02, 0.02], [-0.01, 0.01], [0.5, 0.5]])
    assert np.array_equal(voxel_downsample(small, 0.1), small[[0, 2, 3]])


def _keyframes_with_map(rng, n_scans=30, beams=61):
    angles = np.linspace(-1.5, 1.5, beams)
    scans = Scans(t=np.arange(n_scans) * 0.1, ranges=_ranges(rng, n_scans, beams), angles=angles,
                  range_min=0.1, range_max=11.0)
    rec = Recording(name="synthetic", t0=0.0, scans=scans)
    idx = np.arange(0, n_scans, 3)
    pose = rng.normal(0.0, 2.0, size=(len(idx), 3))
    traj = Trajectory(t=scans.t[idx], x=pose[:, 0], y=pose[:, 1], yaw=pose[:, 2])
    return rec, idx, traj


def test_map_points_equal_the_per_keyframe_loop_for_any_chunk_size():
    rec, index, traj = _keyframes_with_map(np.random.default_rng(2))
    config = PipelineConfig()
    fe = config.frontend
    chunks = []
    for k, i in enumerate(index):
        p = scan_points(rec.scans.ranges[i], rec.scans.angles, fe.min_range_m, min(fe.max_range_m, rec.scans.range_max))
        c, s = np.cos(traj.yaw[k]), np.sin(traj.yaw[k])
        chunks.append(np.column_stack([traj.x[k] + c * p[:, 0] - s * p[:, 1], traj.y[k] + s * p[:, 0] + c * p[:, 1]]))
    expected = _reference_voxel(np.concatenate(chunks), config.output.map_voxel_m)
    for chunk in (1, 3, 4, 2048):
        assert np.array_equal(map_points(rec, index, traj, fe, config.output.map_voxel_m, chunk=chunk), expected)


def _odometry_chain(n):
    delta = np.tile([0.5, 0.0, 0.05], (n, 1))
    delta[0] = 0.0
    valid = np.r_[False, np.ones(n - 1, bool)]
    odometry = BetweenMeasurement(delta=delta, sigma=np.tile([0.05, 0.05, 0.01], (n, 1)), valid=valid)
    return Measurements(t=np.arange(n, dtype=float), scan_index=None, odometry=odometry)


def test_isam2_records_one_update_latency_per_keyframe():
    meas = _odometry_chain(40)
    res = optimise(meas, np.zeros(3), BackendConfig(optimizer="isam2"))
    lat = res.update_latencies_s
    assert lat.shape == (40,) and np.all(lat > 0) and np.all(lat < 1.0)
    assert lat.sum() <= res.build_time_s + res.optimise_time_s + 1e-9
    assert optimise(meas, np.zeros(3), BackendConfig()).update_latencies_s is None


def test_isam2_relinearisation_settings_reach_the_same_chain():
    meas = _odometry_chain(30)
    default = optimise(meas, np.zeros(3), BackendConfig(optimizer="isam2")).trajectory
    params = gtsam.ISAM2Params()
    params.setRelinearizeThreshold(0.01)
    params.relinearizeSkip = 1
    every = optimise(meas, np.zeros(3), BackendConfig(optimizer="isam2"), isam2_params=params).trajectory
    np.testing.assert_allclose(every.xy(), default.xy(), atol=1e-6)
    # A chain of identical steps: the end of an arc of 29 x 0.05 rad.
    assert every.yaw[-1] == pytest.approx(29 * 0.05, abs=1e-9)


# --- bulk CDR decoding (slam.readers.cdr) and the reader's two paths ----------------


def _header(types, sec, frame):
    return types["std_msgs/msg/Header"](stamp=types["builtin_interfaces/msg/Time"](sec=sec, nanosec=7), frame_id=frame)


def _imu(types, k, frame="imu"):
    v3, q = types["geometry_msgs/msg/Vector3"], types["geometry_msgs/msg/Quaternion"]
    cov = np.arange(9.0) + k
    return types["sensor_msgs/msg/Imu"](
        header=_header(types, 100 + k, frame), orientation=q(x=0.1 * k, y=0.2, z=0.3, w=0.9),
        orientation_covariance=cov, angular_velocity=v3(x=k, y=-k, z=0.5 * k), angular_velocity_covariance=cov,
        linear_acceleration=v3(x=1.0, y=2.0, z=9.8), linear_acceleration_covariance=cov,
    )


def _fix(types, k, frame="gps"):
    status = types["sensor_msgs/msg/NavSatStatus"](status=-1 if k == 1 else 0, service=1)
    return types["sensor_msgs/msg/NavSatFix"](
        header=_header(types, 100 + k, frame), status=status, latitude=49.0 + k, longitude=8.0 - k, altitude=1.5,
        position_covariance=np.arange(9.0) * k, position_covariance_type=2,
    )


def _scan(types, k, frame="laser", beams=5):
    return types["sensor_msgs/msg/LaserScan"](
        header=_header(types, 100 + k, frame), angle_min=-1.0, angle_max=1.0, angle_increment=0.5, time_increment=0.0,
        scan_time=0.1, range_min=0.1, range_max=30.0, ranges=np.arange(beams, dtype=np.float32) + k,
        intensities=np.zeros(0, dtype=np.float32),
    )


@pytest.mark.parametrize("frame", ["", "a", "abc", "abcdefg"])  # every alignment after the frame id
def test_bulk_decoding_equals_message_by_message(frame):
    from rosbags.typesys import Stores, get_typestore

    from slam.readers import cdr

    store = get_typestore(Stores.LATEST)
    types = store.types
    imus = [_imu(types, k, frame) for k in range(4)]
    cols = cdr.decode_columns("sensor_msgs/msg/Imu", [store.serialize_cdr(m, m.__msgtype__) for m in imus],
                              ["angular_velocity", "orientation", "orientation_covariance"])
    np.testing.assert_array_equal(cols["stamp_ns"], [(100 + k) * 10**9 + 7 for k in range(4)])
    np.testing.assert_array_equal(cols["angular_velocity"], [[k, -k, 0.5 * k] for k in range(4)])
    np.testing.assert_array_equal(cols["orientation"][:, 0], [0.1 * k for k in range(4)])
    np.testing.assert_array_equal(cols["orientation_covariance"][3], np.arange(9.0) + 3)
    fixes = [_fix(types, k, frame) for k in range(3)]
    cols = cdr.decode_columns("sensor_msgs/msg/NavSatFix", [store.serialize_cdr(m, m.__msgtype__) for m in fixes],
                              ["status", "latitude", "longitude", "position_covariance", "position_covariance_type"])
    np.testing.assert_array_equal(cols["status"], [0, -1, 0])
    np.testing.assert_array_equal(cols["longitude"], [8.0, 7.0, 6.0])
    np.testing.assert_array_equal(cols["position_covariance"][2], np.arange(9.0) * 2)
    np.testing.assert_array_equal(cols["position_covariance_type"], [2, 2, 2])
    scans = [_scan(types, k, frame) for k in range(3)]
    cols = cdr.decode_columns("sensor_msgs/msg/LaserScan", [store.serialize_cdr(m, m.__msgtype__) for m in scans],
                              ["angle_min", "angle_increment", "range_max", "ranges"])
    np.testing.assert_array_equal(cols["ranges"], [np.arange(5.0) + k for k in range(3)])
    assert cols["angle_increment"][1] == 0.5 and cols["range_max"][2] == 30.0


def test_bulk_decoding_refuses_changing_layouts_and_other_encodings():
    from rosbags.typesys import Stores, get_typestore

    from slam.readers import cdr

    store = get_typestore(Stores.LATEST)
    types = store.types

    def raw(m):
        return store.serialize_cdr(m, m.__msgtype__)

    fields = ["angular_velocity"]
    two_frames = [raw(_imu(types, 0, "ab")), raw(_imu(types, 1, "abc"))]
    assert cdr.decode_columns("sensor_msgs/msg/Imu", two_frames, fields) is None
    # Same total length, different split between frame id and ranges.
    scans = [raw(_scan(types, 0, "abcd", beams=5)), raw(_scan(types, 1, "abcdefgh", beams=4))]
    assert len(scans[0]) == len(scans[1])
    assert cdr.decode_columns("sensor_msgs/msg/LaserScan", scans, ["ranges"]) is None
    big_endian = store.serialize_cdr(_imu(types, 0), "sensor_msgs/msg/Imu", little_endian=False)
    assert cdr.decode_columns("sensor_msgs/msg/Imu", [big_endian], fields) is None
    assert cdr.decode_columns("sensor_msgs/msg/Temperature", [raw(_imu(types, 0))], fields) is None


def test_reader_falls_back_when_a_frame_id_changes(tmp_path, monkeypatch, caplog):
    from bagfactory import BagBuilder

    from slam.config import InputConfig
    from slam.readers import rosbag

    def bag_with(frames):
        bag = BagBuilder(ros=2)
        for k, frame in enumerate(frames):
            bag.add("/imu/data", "sensor_msgs/msg/Imu", _imu(bag.types, k, frame), log_t=100.0 + k)
        return bag.write(tmp_path / f"run{len(frames)}{frames[-1]}")

    cfg = InputConfig.model_validate({"topics": {"scan": None, "compass": None, "odometry": None, "gps": None,
                                                 "groundtruth": None, "gyro": "/imu/data"}})
    monkeypatch.setattr(rosbag, "BULK_CHUNK", 2)
    caplog.set_level("INFO", logger="slam.readers.rosbag")
    same = rosbag.read_rosbag(bag_with(["imu"] * 5), cfg).gyro
    assert "message by message" not in caplog.text
    changed = rosbag.read_rosbag(bag_with(["imu"] * 3 + ["imu_link"] * 2), cfg).gyro
    assert "/imu/data read message by message" in caplog.text
    np.testing.assert_array_equal(same.rate, 0.5 * np.arange(5))
    np.testing.assert_array_equal(changed.rate, same.rate)
    np.testing.assert_array_equal(changed.t, same.t)


def _error(fn, *args):
    from slam.errors import GslamError

    with pytest.raises(GslamError) as err:
        fn(*args)
    return str(err.value).split(": ", 1)[1]  # without the bag's path, which differs


@pytest.mark.parametrize("chunk", [2, 3, 8192])
def test_bulk_and_message_by_message_reading_fail_alike(tmp_path, monkeypatch, chunk):
    from bagfactory import BagBuilder

    from slam.config import InputConfig
    from slam.readers import rosbag

    monkeypatch.setattr(rosbag, "BULK_CHUNK", chunk)
    none = {"scan": None, "gyro": None, "compass": None, "odometry": None, "gps": None, "groundtruth": None}
    cases = [
        ("/beams", {"scan": "/beams"}, {}),
        ("/angles", {"scan": "/angles"}, {}),
        ("/imu", {"compass": "/imu"}, {"compass": {"source": "imu_orientation"}}),
        ("/imu", {"gyro": "/imu"}, {"gyro": {"axis": "world_z"}}),
    ]
    errors = {}
    for ros in (1, 2):  # ROS 1 is always read message by message
        bag = BagBuilder(ros)
        for k in range(6):
            bag.scan("/beams", 100.0 + k, [1.0, 2.0, 3.0] if k < 4 else [1.0, 2.0])
            bag.scan("/angles", 100.0 + k, [1.0, 2.0], angle_min=0.1 if k == 5 else 0.0)
            bag.imu("/imu", 100.0 + k, has_orientation=k != 4)
        (tmp_path / f"ros{ros}").mkdir()
        path = bag.write_in(tmp_path / f"ros{ros}")
        for topic, topics, sections in cases:
            cfg = InputConfig.model_validate({"topics": none | topics, **sections})
            errors.setdefault(str(topics), []).append(_error(rosbag.read_rosbag, path, cfg))
    assert errors["{'scan': '/beams'}"][1] == "scan topic '/beams': message 4 has 2 beams, the first had 3"
    assert "beam angles change at message 5" in errors["{'scan': '/angles'}"][1]
    assert "message 4 has no orientation" in errors["{'compass': '/imu'}"][1]
    for ros1, ros2 in errors.values():
        assert ros1 == ros2


def test_every_stream_of_a_ros2_bag_is_read_in_bulk_and_equals_ros1(tmp_path, caplog):
    import dataclasses

    from bagfactory import driving_bag

    from slam.config import InputConfig
    from slam.readers.rosbag import read_rosbag

    caplog.set_level("INFO", logger="slam.readers.rosbag")
    recs = []
    for ros in (1, 2):
        (tmp_path / f"ros{ros}").mkdir()
        recs.append(read_rosbag(driving_bag(ros).write_in(tmp_path / f"ros{ros}"), InputConfig()))
    assert "message by message" not in caplog.text
    for name in ("scans", "gyro", "compass", "odometry", "gps", "groundtruth"):
        a, b = getattr(recs[0], name), getattr(recs[1], name)
        for f in dataclasses.fields(a):
            u, v = getattr(a, f.name), getattr(b, f.name)
            if isinstance(u, np.ndarray):
                assert u.dtype == v.dtype and np.array_equal(u, v, equal_nan=True), (name, f.name)


def test_layout_cross_check_against_rosbags():
    from rosbags.typesys import Stores, get_typestore

    from slam.readers import cdr

    store = get_typestore(Stores.LATEST)
    fixes = [_fix(store.types, k, "gps") for k in range(3)]
    fields = ["status", "latitude", "position_covariance", "position_covariance_type"]
    raws = [store.serialize_cdr(m, m.__msgtype__) for m in fixes]
    cols = cdr.decode_columns("sensor_msgs/msg/NavSatFix", raws, fields)
    assert cdr.agrees(fixes[2], cols, -1) and cdr.agrees(fixes[0], cols, 0)
    assert not cdr.agrees(fixes[1], cols, 0)  # another stamp
    cols["latitude"][-1] += 1e-9
    assert not cdr.agrees(fixes[2], cols, -1)
