"""The BROAD trial reader: tiny .mat trials written here from a known
orientation and Earth field, and the real trials when they are present."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.io import savemat
from scipy.spatial.transform import Rotation

from conftest import real_data
from slam.errors import GslamError
from validation.base.geometry import heading_from_magnetometer, wrap_angle
from slam.readers.broad import MAG_LAG_S, gyro_heading, level_field, looks_like_broad, read_broad

FS = 100.0
STRENGTH_UT = 50.0
DIP_DEG = 60.0
RATE = np.radians(20.0)  # rad/s about the vertical between 6 s and 10 s


def earth_field_ut() -> np.ndarray:
    """ENU field with 60 deg dip, no declination: north and down."""
    dip = np.radians(DIP_DEG)
    return STRENGTH_UT * np.array([0.0, np.cos(dip), -np.sin(dip)])


def orientation(t: np.ndarray, roll_deg=20.0, pitch_deg=-10.0, yaw0_deg=30.0) -> Rotation:
    """IMU-to-ENU rotations: constant tilt, yaw 30 deg, turning at RATE
    about the vertical between 6 s and 10 s."""
    yaw = np.radians(yaw0_deg) + RATE * np.clip(t - 6.0, 0.0, 4.0)
    n = len(t)
    return Rotation.from_euler("ZYX", np.column_stack([yaw, np.full(n, np.radians(pitch_deg)), np.full(n, np.radians(roll_deg))]))


def write_trial(path: Path, duration_s=20.0, disturb=(12.0, 14.0), lost=(3.0, 3.5), **overrides) -> Path:
    """A trial as the real sensor records it: the magnetometer's samples
    are ``MAG_LAG_S`` late."""
    t = np.arange(int(duration_s * FS)) / FS
    rot = orientation(t)
    measured = t - MAG_LAG_S
    field_w = np.tile(earth_field_ut(), (len(t), 1))
    if disturb is not None:
        inside = (measured >= disturb[0]) & (measured < disturb[1])
        field_w[inside] += [40.0, 0.0, 0.0]  # a magnet to the east
    inv = rot.inv()
    w_world = np.zeros((len(t), 3))
    w_world[(t >= 6.0) & (t < 10.0), 2] = RATE
    quat = rot.as_quat()[:, [3, 0, 1, 2]]  # w, x, y, z
    quat[(t >= lost[0]) & (t < lost[1])] = np.nan
    data = {
        "imu_gyr": inv.apply(w_world),
        "imu_acc": inv.apply(np.tile([0.0, 0.0, 9.81], (len(t), 1))),
        "imu_mag": orientation(measured).inv().apply(field_w),
        "opt_quat": quat,
        "opt_pos": np.column_stack([0.01 * t, -0.02 * t, np.ones_like(t)]),
        "sampling_rate": np.array([[FS]]),
        "movement": np.ones((len(t), 1), dtype=np.uint8),
    }
    data.update(overrides)
    data = {k: v for k, v in data.items() if v is not None}
    savemat(str(path), data)
    return path


def test_level_field_gives_the_known_heading():
    rot = orientation(np.array([0.0]), roll_deg=25.0, pitch_deg=-35.0, yaw0_deg=-120.0)
    mag = rot.inv().apply(earth_field_ut())
    up = rot.inv().apply([0.0, 0.0, 1.0])
    level, pitch = level_field(mag, up)
    assert np.degrees(pitch[0]) == pytest.approx(-35.0)
    assert np.degrees(heading_from_magnetometer(level)[0]) == pytest.approx(-120.0)
    # The level field is the Earth field turned by the heading only: same dip.
    np.testing.assert_allclose(np.linalg.norm(level), STRENGTH_UT)
    assert np.degrees(np.arctan2(-level[0, 2], np.hypot(level[0, 0], level[0, 1]))) == pytest.approx(DIP_DEG)


def _body_rates(rot: Rotation, fs: float) -> np.ndarray:
    """Body-frame rates (n, 3) rad/s that carry ``rot[k]`` to ``rot[k + 1]``."""
    steps = (rot[:-1].inv() * rot[1:]).as_rotvec() * fs
    return np.vstack([steps, steps[-1:]])


def _zyx_yaw(rot: Rotation) -> np.ndarray:
    return rot.as_euler("ZYX")[:, 0]


@pytest.mark.parametrize("motion", ["roll_while_pitched", "through_pitch_90"])
def test_gyro_heading_is_the_zyx_yaw(motion):
    """The gyro heading must follow the ZYX yaw the compass and the truth
    use, where the rate about the vertical does not: rolling while pitched
    40 deg (the yaw stays put; gyr . up swings by roll_rate * sin(pitch)),
    and pitching through 90 deg and on to 120 deg (the ZYX yaw jumps by
    180 deg)."""
    fs = 400.0
    t = np.arange(int(6.0 * fs)) / fs
    ramp = np.clip(t - 1.0, 0.0, 4.0) / 4.0
    if motion == "roll_while_pitched":
        euler = np.column_stack([np.full_like(t, 0.5), np.full_like(t, np.radians(40.0)), np.radians(60.0) * np.sin(np.pi * ramp)])
    else:
        euler = None
    if euler is not None:
        rot = Rotation.from_euler("ZYX", euler)
    else:  # about the body y axis from level to 121 deg (no sample at 90), heading 0.5 rad
        rot = Rotation.from_euler("Z", 0.5) * Rotation.from_rotvec(np.outer(np.radians(121.0) * ramp, [0.0, 1.0, 0.0]))
    gyr = _body_rates(rot, fs)
    up = rot.inv().apply([0.0, 0.0, 1.0])
    heading = gyro_heading(gyr, up, 1.0 / fs) + _zyx_yaw(rot[:1])[0]
    # First-order quaternion steps: within 0.2 deg over 6 s.
    np.testing.assert_allclose(wrap_angle(heading - _zyx_yaw(rot)), 0.0, atol=3e-3)
    if motion == "roll_while_pitched":
        vertical_rate = np.einsum("ij,ij->i", gyr, up)
        assert np.max(np.abs(vertical_rate)) > 0.3  # what the old stream integrated
    else:
        assert abs(wrap_angle(_zyx_yaw(rot)[-1] - 0.5)) == pytest.approx(np.pi, abs=1e-6)


def test_gyro_bias_at_rest_is_removed(tmp_path):
    t = np.arange(int(20.0 * FS)) / FS
    inv = orientation(t).inv()
    w_world = np.zeros((len(t), 3))
    w_world[(t >= 6.0) & (t < 10.0), 2] = RATE
    bias = np.radians([0.3, -0.2, 0.5])  # deg/s, as on the real boards
    rec = read_broad(write_trial(tmp_path / "biased.mat", imu_gyr=inv.apply(w_world) + bias))
    turning = (rec.gyro.t >= 6.5) & (rec.gyro.t < 9.5)
    np.testing.assert_allclose(rec.gyro.rate[turning], RATE, atol=1e-4)
    np.testing.assert_allclose(rec.gyro.rate[rec.gyro.t > 10.5], 0.0, atol=1e-4)


def test_synthetic_trial_headings_reference_and_faults(tmp_path):
    rec = read_broad(write_trial(tmp_path / "trial.mat"), fault_threshold_deg=10.0)
    assert rec.name == "trial" and rec.t0 == 0.0
    assert len(rec.gyro.t) == 2000
    np.testing.assert_allclose(np.diff(rec.gyro.t), 1.0 / FS)
    # Rate about the vertical: RATE while turning, 0 otherwise.
    turning = (rec.gyro.t >= 6.5) & (rec.gyro.t < 9.5)
    np.testing.assert_allclose(rec.gyro.rate[turning], RATE, atol=1e-6)
    np.testing.assert_allclose(rec.gyro.rate[rec.gyro.t < 5.5], 0.0, atol=1e-9)
    # Compass follows the true heading (30 deg, +80 deg over the turn) outside the magnet.
    c = rec.compass
    expected = np.radians(30.0) + RATE * np.clip(c.t - 6.0, 0.0, 4.0)
    clean = (c.t < 11.9) | (c.t > 14.1)
    np.testing.assert_allclose(wrap_angle(c.yaw[clean] - expected[clean]), 0.0, atol=1e-3)
    assert np.degrees(np.max(np.abs(wrap_angle(c.yaw[~clean] - expected[~clean])))) > 10.0
    # Field in tesla, levelled: strength and dip of the Earth field.
    assert np.linalg.norm(c.field[0]) == pytest.approx(STRENGTH_UT * 1e-6)
    ref = rec.magnetic_reference
    assert ref.strength_T == pytest.approx(STRENGTH_UT * 1e-6)
    assert np.degrees(ref.dip_rad) == pytest.approx(DIP_DEG)
    # Truth: tracking lost between 3 s and 3.5 s is dropped.
    g = rec.groundtruth
    assert len(g.t) == 2000 - 50
    assert not np.any((g.t >= 3.0) & (g.t < 3.5))
    np.testing.assert_allclose(wrap_angle(g.yaw - (np.radians(30.0) + RATE * np.clip(g.t - 6.0, 0.0, 4.0))), 0.0, atol=1e-9)
    np.testing.assert_allclose(g.x, 0.01 * g.t)
    # The magnet is the only fault.
    (start, end), = rec.faults["IMU_YAW"]
    assert start == pytest.approx(12.0, abs=0.02) and end == pytest.approx(14.0, abs=0.02)


def test_constant_heading_offset_is_removed(tmp_path):
    """An optical frame turned 15 deg from ENU: the truth says yaw - 15 deg
    and the compass, aligned over the first seconds, must follow it."""
    path = write_trial(tmp_path / "offset.mat", disturb=None)
    from scipy.io import loadmat

    d = loadmat(str(path))
    q = d["opt_quat"]
    ok = np.isfinite(q).all(axis=1)
    turned = Rotation.from_euler("z", -15.0, degrees=True) * Rotation.from_quat(q[ok][:, [1, 2, 3, 0]])
    q[ok] = turned.as_quat()[:, [3, 0, 1, 2]]
    d["opt_quat"] = q
    savemat(str(path), {k: v for k, v in d.items() if not k.startswith("__")})
    rec = read_broad(path)
    g = rec.groundtruth
    yaw_truth = np.interp(rec.compass.t, g.t, np.unwrap(g.yaw))
    np.testing.assert_allclose(wrap_angle(rec.compass.yaw - yaw_truth), 0.0, atol=1e-3)
    assert rec.faults["IMU_YAW"] == []


def test_bad_files_give_one_line_errors(tmp_path):
    def error_of(path):
        with pytest.raises(GslamError) as info:
            read_broad(path)
        msg = str(info.value)
        assert msg and "\n" not in msg
        return msg

    assert "no such file" in error_of(tmp_path / "absent.mat")
    garbage = tmp_path / "garbage.mat"
    garbage.write_bytes(b"not a matlab file" * 10)
    assert "cannot read as a MATLAB v5 file" in error_of(garbage)
    assert "expected a BROAD trial with 'imu_mag'" in error_of(write_trial(tmp_path / "nomag.mat", imu_mag=None))
    msg = error_of(write_trial(tmp_path / "shape.mat", imu_acc=np.zeros((5, 3))))
    assert "imu_acc: expected shape (2000, 3)" in msg
    assert "no tracked sample" in error_of(write_trial(tmp_path / "lost.mat", lost=(0.0, 100.0)))
    tiny = write_trial(tmp_path / "tiny.mat", duration_s=0.01)
    assert "no samples" in error_of(tiny)


def test_looks_like_broad(tmp_path):
    assert looks_like_broad(write_trial(tmp_path / "a.mat", duration_s=1.0))
    assert not looks_like_broad(tmp_path / "a.txt")


# --- real trials ----------------------------------------------------------


def real_trial(name: str) -> Path:
    return real_data(f"broad/{name}.mat")


@pytest.mark.slow
def test_real_undisturbed_and_attached_magnet():
    clean = read_broad(real_trial("10_undisturbed_slow_translation_A"))
    assert 190.0 < clean.duration < 200.0
    assert clean.faults["IMU_YAW"] == []
    ref = clean.magnetic_reference
    assert 38e-6 < ref.strength_T < 46e-6 and 65.0 < np.degrees(ref.dip_rad) < 75.0  # Berlin
    g, c = clean.groundtruth, clean.compass
    err = np.degrees(wrap_angle(c.yaw - np.interp(c.t, g.t, np.unwrap(g.yaw))))
    assert np.median(np.abs(err)) < 5.0

    magnet = read_broad(real_trial("32_disturbed_attached_magnet_1cm"))
    labelled = sum(b - a for a, b in magnet.faults["IMU_YAW"])
    assert 30.0 < labelled < 120.0


@pytest.mark.slow
def test_real_magnetometer_lag_alone_turns_the_heading_past_the_label():
    # Undisturbed fast rotation: with the magnetometer's 12 ms lag left in,
    # its heading is more than 20 deg off the optical one for seconds.
    path = real_trial("08_undisturbed_fast_rotation_with_breaks_A")
    assert read_broad(path).faults["IMU_YAW"] == []
    late = read_broad(path, mag_lag_s=0.0).faults["IMU_YAW"]
    assert sum(b - a for a, b in late) > 5.0
