"""The CARMEN log reader: tiny logs written here with known poses and raw
odometry, and the real Radish / Freiburg logs when they are present."""

from __future__ import annotations

import gzip
import logging
from pathlib import Path

import numpy as np
import pytest

from conftest import real_data
from slam.errors import GslamError
from slam.readers.carmen import chain_steps, looks_like_carmen, read_carmen
from slam.recording import relative_poses

CORRECTED = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, np.pi / 2], [1.0, 1.0, np.pi]])
RAW_STEPS = np.array([[1.1, 0.05, 1.5], [0.9, -0.1, 1.6]])


def compose(a, b):
    c, s = np.cos(a[2]), np.sin(a[2])
    return np.array([a[0] + c * b[0] - s * b[1], a[1] + s * b[0] + c * b[1], a[2] + b[2]])


def flaser(ranges, pose, ts) -> str:
    r = " ".join(f"{v:.3f}" for v in ranges)
    p = " ".join(repr(float(v)) for v in pose)
    return f"FLASER {len(ranges)} {r} {p} {p} {ts} host {ts}"


def odom(pose, ts) -> str:
    return "ODOM " + " ".join(repr(float(v)) for v in pose) + f" 0 0 0 {ts} host {ts}"


def three_scan_log(stamps=(0.5, 0.7, 0.9), raw=True) -> list[str]:
    """Three scans at CORRECTED; after scan k the corrected pose is repeated,
    then raw odometry continues from it to CORRECTED[k] * RAW_STEPS[k]."""
    lines = ["# header", "PARAM robot_use_laser on host 0", odom([0, 0, 0], 0.4)]
    for k, pose in enumerate(CORRECTED):
        lines.append(flaser([1.0, 2.0, 3.0, 81.91], pose, stamps[k]))
        lines.append(odom(pose, 0))
        lines.append("NEFF 10")
        if raw and k < len(RAW_STEPS):
            half = compose(pose, RAW_STEPS[k] / 2)
            lines.append(odom(half, stamps[k] + 0.1))
            lines.append(odom(compose(pose, RAW_STEPS[k]), stamps[k] + 0.19))
    return lines


def write(path: Path, lines: list[str]) -> Path:
    text = "\n".join(lines) + "\n"
    if path.name.endswith(".gz"):
        with gzip.open(path, "wt") as f:
            f.write(text)
    else:
        path.write_text(text)
    return path


def error_of(path: Path) -> str:
    with pytest.raises(GslamError) as info:
        read_carmen(path)
    msg = str(info.value)
    assert msg and "\n" not in msg
    return msg


@pytest.mark.parametrize("name", ["run.log", "run.log.gz"])
def test_raw_odometry_is_recovered_exactly(tmp_path, name):
    rec = read_carmen(write(tmp_path / name, three_scan_log()))
    expected = chain_steps(CORRECTED[0], RAW_STEPS)
    assert np.allclose(expected[1], compose(CORRECTED[0], RAW_STEPS[0]))
    odo = rec.odometry
    got = np.column_stack([odo.x, odo.y, odo.yaw])
    np.testing.assert_allclose(got, expected, atol=1e-12)
    steps = relative_poses(got[:-1], got[1:])
    np.testing.assert_allclose(steps, RAW_STEPS, atol=1e-12)
    gt = rec.groundtruth
    np.testing.assert_allclose(np.column_stack([gt.x, gt.y, gt.yaw]), CORRECTED, atol=1e-12)
    assert rec.t0 == pytest.approx(0.5)
    np.testing.assert_allclose(rec.scans.t, [0.0, 0.2, 0.4], atol=1e-12)
    np.testing.assert_allclose(odo.t, rec.scans.t)
    assert rec.name == "run"
    assert rec.gyro is None and rec.compass is None and rec.gps is None


def test_flaser_angles_ranges_and_range_max(tmp_path):
    rec = read_carmen(write(tmp_path / "a.log", three_scan_log()))
    s = rec.scans
    assert s.ranges.shape == (3, 4)
    np.testing.assert_allclose(s.ranges[0], [1.0, 2.0, 3.0, 81.91], rtol=1e-6)
    # Even beam count: 180 deg / n steps from -90 deg.
    np.testing.assert_allclose(np.degrees(s.angles), [-90.0, -45.0, 0.0, 45.0])
    # No PARAM: just below the saturation value, so "no return" is dropped.
    assert 81.0 < s.range_max < 81.91

    lines = three_scan_log()
    lines.insert(1, "PARAM robot_front_laser_max 40.0 host 0")
    lines = [ln.replace("FLASER 4 1.000 2.000 3.000 81.910", "FLASER 5 1.000 2.000 3.000 4.000 81.910") for ln in lines]
    s = read_carmen(write(tmp_path / "b.log", lines)).scans
    assert s.range_max == 40.0
    np.testing.assert_allclose(np.degrees(s.angles), [-90.0, -45.0, 0.0, 45.0, 90.0])


@pytest.mark.parametrize("fov", ["100", "1.745329"])
def test_field_of_view_param_in_degrees_or_radians(tmp_path, fov):
    """CARMEN writes the field of view in degrees; csail writes 3.14159,
    radians. Either way a 100 deg scanner's beams span 100 deg."""
    lines = three_scan_log()
    lines.insert(1, f"PARAM laser_front_laser_fov {fov} host 0")
    lines = [ln.replace("FLASER 4 1.000 2.000 3.000 81.910", "FLASER 5 1.000 2.000 3.000 4.000 81.910") for ln in lines]
    s = read_carmen(write(tmp_path / "fov.log", lines)).scans
    np.testing.assert_allclose(np.degrees(s.angles), [-50.0, -25.0, 0.0, 25.0, 50.0], atol=1e-4)


def test_robotlaser1_has_its_own_angles(tmp_path):
    lines = []
    for k, pose in enumerate(CORRECTED):
        p = " ".join(repr(float(v)) for v in pose)
        lines.append(
            f"ROBOTLASER1 0 -1.5 3.0 0.5 30.0 0.01 0 3 1.0 2.0 3.0 0 {p} {p} 0 0 0.5 0.3 0.2 {1.0 + k} host {1.0 + k}"
        )
        lines.append(odom(pose, 0))
        lines.append(odom(compose(pose, [0.5, 0.0, 0.1]), 1.5 + k))
    rec = read_carmen(write(tmp_path / "rl.log", lines))
    np.testing.assert_allclose(rec.scans.angles, [-1.5, -1.0, -0.5])
    assert rec.scans.range_max == 30.0
    np.testing.assert_allclose(rec.scans.t, [0.0, 1.0, 2.0])
    np.testing.assert_allclose(rec.groundtruth.yaw, CORRECTED[:, 2])


def test_zero_timestamps_are_synthesised_with_a_warning(tmp_path, caplog):
    with caplog.at_level(logging.WARNING):
        rec = read_carmen(write(tmp_path / "z.log", three_scan_log(stamps=(0, 0, 0))))
    np.testing.assert_allclose(rec.scans.t, [0.0, 1.0, 2.0])
    assert rec.t0 == 0.0
    assert "synthesised" in caplog.text


def test_a_stamp_stepping_back_is_repaired(tmp_path, caplog):
    stamps = [10.0 * k for k in range(12)]
    stamps[5] = 39.5  # before its predecessor at 40
    lines = []
    for k, ts in enumerate(stamps):
        pose = [0.1 * k, 0.0, 0.0]
        lines += [flaser([1.0, 2.0], pose, ts), odom(pose, 0), odom([0.1 * k + 0.1, 0, 0], ts + 1)]
    with caplog.at_level(logging.WARNING):
        rec = read_carmen(write(tmp_path / "back.log", lines))
    assert np.all(np.diff(rec.scans.t) > 0)
    assert rec.scans.t[5] == pytest.approx(40.001)
    assert "step back" in caplog.text


def test_step_without_raw_odometry_is_a_gap(tmp_path, caplog):
    lines = three_scan_log()
    # Drop the raw readings after scan 1: only the repeat of its pose is left.
    first_raw_after_scan1 = [i for i, ln in enumerate(lines) if ln.startswith("FLASER")][1] + 3
    del lines[first_raw_after_scan1 : first_raw_after_scan1 + 2]
    with caplog.at_level(logging.WARNING):
        rec = read_carmen(write(tmp_path / "gap.log", lines))
    np.testing.assert_allclose(rec.odometry.t, rec.scans.t[:2])
    assert "no raw odometry" in caplog.text


def test_mostly_missing_odometry_is_left_out(tmp_path, caplog):
    with caplog.at_level(logging.WARNING):
        rec = read_carmen(write(tmp_path / "noodo.log", three_scan_log(raw=False)))
    assert rec.odometry is None
    assert rec.groundtruth is not None and len(rec.scans) == 3
    assert "odometry left out" in caplog.text


@pytest.mark.parametrize(
    "bad, lineno, expected",
    [
        ("FLASER 4 1.0 2.0 x 4.0 0 0 0 0 0 0 1.0 host 1.0", 4, "expected FLASER n r_1..r_n"),
        ("FLASER 4 1.0 2.0 3.0 4.0 0 0 0", 4, "expected FLASER n r_1..r_n"),
        ("FLASER four 1.0", 4, "expected FLASER n r_1..r_n"),
        ("ODOM 1.0 nan 0 0 0 0 1.0 host 1.0", 4, "expected finite numbers"),
        ("ODOM 1.0 2.0", 4, "expected ODOM x y theta"),
    ],
)
def test_malformed_line_names_file_and_line(tmp_path, bad, lineno, expected):
    lines = three_scan_log()
    lines.insert(lineno - 1, bad)
    path = write(tmp_path / "bad.log.gz", lines)
    msg = error_of(path)
    assert msg.startswith(f"{path}:{lineno}: ")
    assert expected in msg


def test_beam_count_change_is_an_error(tmp_path):
    lines = three_scan_log()
    lines.append(flaser([1.0, 2.0], [0, 0, 0], 5.0))
    path = write(tmp_path / "mixed.log", lines)
    assert f"{path}:{len(lines)}: expected 4 beams" in error_of(path)


def test_unreadable_inputs_give_one_line_errors(tmp_path):
    assert "no such file" in error_of(tmp_path / "missing.log")
    corrupt = tmp_path / "corrupt.log.gz"
    corrupt.write_bytes(b"this is not gzip data at all")
    assert "not a valid gzip file" in error_of(corrupt)
    truncated = tmp_path / "truncated.log.gz"
    truncated.write_bytes(gzip.compress(("\n".join(three_scan_log()) + "\n").encode())[:60])
    assert "truncated gzip file" in error_of(truncated)
    binary = tmp_path / "binary.log"
    binary.write_bytes(bytes(range(256)))
    assert "binary" in error_of(binary)
    empty = write(tmp_path / "empty.log", ["PARAM a b", odom([0, 0, 0], 1.0)])
    assert "no FLASER or ROBOTLASER1 scans" in error_of(empty)
    assert "directory" in error_of(tmp_path)


def test_looks_like_carmen(tmp_path):
    assert looks_like_carmen(write(tmp_path / "x.log.gz", three_scan_log()))
    assert looks_like_carmen(write(tmp_path / "x.log", three_scan_log()))
    assert not looks_like_carmen(write(tmp_path / "x.txt", three_scan_log()))
    assert not looks_like_carmen(tmp_path / "absent.log")


# --- real logs ------------------------------------------------------------


def real_log(name: str) -> Path:
    return real_data(f"carmen/{name}-corrected.log.gz")


def test_real_freiburg_079():
    rec = read_carmen(real_log("freiburg-079"))
    assert len(rec.scans) == 4791
    assert rec.scans.ranges.shape == (4791, 360)
    assert 1000.0 < rec.duration < 1100.0
    assert 4.0 < len(rec.scans) / rec.duration < 5.0  # about 4.5 Hz
    assert len(rec.odometry) == 4791
    o, g = rec.odometry, rec.groundtruth
    d_odo = relative_poses(np.column_stack([o.x, o.y, o.yaw])[:-1], np.column_stack([o.x, o.y, o.yaw])[1:])
    d_ref = relative_poses(np.column_stack([g.x, g.y, g.yaw])[:-1], np.column_stack([g.x, g.y, g.yaw])[1:])
    err = d_odo - d_ref
    # Raw odometry differs from the corrected steps by a few cm and degrees.
    assert 0.005 < np.median(np.hypot(err[:, 0], err[:, 1])) < 0.05
    assert 0.1 < np.degrees(np.median(np.abs(err[:, 2]))) < 2.0
    assert 350.0 < np.sum(np.hypot(d_ref[:, 0], d_ref[:, 1])) < 500.0


def test_real_logs_with_bad_stamps_or_odometry(caplog):
    with caplog.at_level(logging.WARNING):
        orebro = read_carmen(real_log("orebro"))
    assert orebro.odometry is None and len(orebro.scans) == 237
    np.testing.assert_allclose(np.diff(orebro.scans.t), 1.0)
    intel = read_carmen(real_log("intel"))
    assert len(intel.scans) == 910 and np.all(np.diff(intel.scans.t) > 0)
    assert 2600.0 < intel.duration < 2700.0
