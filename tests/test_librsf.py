"""The libRSF data-set reader: small files written here with known motion,
and the real Corridor data set when it is present."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from conftest import real_data
from slam.errors import GslamError
from validation.base.geometry import wrap_angle
from slam.readers.librsf import dataset_files, looks_like_librsf, read_librsf

V, W, DT, N = 0.5, 0.1, 0.1, 301  # m/s, rad/s, s: a circle of radius 5 m


def write_set(folder: Path, name="Test", input_lines=None, gt_lines=None) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    if input_lines is None:
        input_lines = [f"odom2 {k * DT:.10g} {V if k else 0} 0 {W if k else 0} 0.0025 0.0025 0.0001" for k in range(N)]
        input_lines.insert(5, "loop 0.4 0.1 1")
    inp = folder / f"{name}_Input.txt"
    inp.write_text("\n".join(input_lines) + "\n")
    if gt_lines is not None:
        (folder / f"{name}_GT.txt").write_text("\n".join(gt_lines) + "\n")
    return inp


def circle_gt(with_angle: bool) -> list[str]:
    lines = []
    for k in range(0, N, 3):
        t = k * DT
        th = W * t
        x, y = float(V / W * np.sin(th)), float(V / W * (1 - np.cos(th)))
        lines.append(f"point2 {t:.10g} {x!r} {y!r} 0 0 0 0")
        if with_angle:
            lines.append(f"angle {t:.10g} {float(th)!r} 0")
    return lines


def test_constant_velocity_integrates_to_a_circle(tmp_path):
    rec = read_librsf(write_set(tmp_path))
    o = rec.odometry
    assert len(o) == N and rec.t0 == 0.0 and rec.name == "Test"
    th = W * o.t
    np.testing.assert_allclose(o.x, V / W * np.sin(th), atol=1e-9)
    np.testing.assert_allclose(o.y, V / W * (1 - np.cos(th)), atol=1e-9)
    np.testing.assert_allclose(wrap_angle(o.yaw - th), 0.0, atol=1e-12)
    # 30 s at 0.1 rad/s: 3 rad around a circle of radius 5 m.
    assert np.hypot(o.x[-1], o.y[-1]) == pytest.approx(2 * 5.0 * np.sin(1.5))
    np.testing.assert_allclose(rec.gyro.rate[1:], W)
    np.testing.assert_allclose(rec.gyro.t, o.t)
    assert rec.groundtruth is None


def test_lateral_velocity_is_in_the_body_frame(tmp_path):
    lines = ["odom2 0 0 0 0 1 1 1", "odom2 1 0 0 1.5707963267948966 1 1 1", "odom2 2 0 0.3 0 1 1 1"]
    o = read_librsf(write_set(tmp_path, input_lines=lines)).odometry
    # After a quarter turn, +y in the body is -x in the world.
    np.testing.assert_allclose([o.x[-1], o.y[-1], o.yaw[-1]], [-0.3, 0.0, np.pi / 2], atol=1e-12)


@pytest.mark.parametrize("with_angle", [True, False])
def test_groundtruth_yaw_from_angle_lines_or_motion(tmp_path, with_angle):
    inp = write_set(tmp_path, gt_lines=circle_gt(with_angle))
    g = read_librsf(inp).groundtruth
    assert len(g) == (N + 2) // 3
    expected = W * g.t
    if with_angle:
        np.testing.assert_allclose(wrap_angle(g.yaw - expected), 0.0, atol=1e-12)
    else:
        # Direction of motion over the next 0.2 m of path: two 0.15 m chords
        # (0.6 s of arc), i.e. the heading half-way along it, W * (t + 0.3 s);
        # the last two samples hold the last heading.
        np.testing.assert_allclose(wrap_angle(g.yaw[:-2] - (expected[:-2] + W * 0.3)), 0.0, atol=1e-9)
        assert g.yaw[-1] == g.yaw[-3]


def test_file_pairing(tmp_path):
    inp = write_set(tmp_path / "set", gt_lines=circle_gt(True))
    gt = tmp_path / "set" / "Test_GT.txt"
    assert dataset_files(inp) == (inp, gt)
    assert dataset_files(gt) == (inp, gt)
    assert dataset_files(tmp_path / "set") == (inp, gt)
    assert looks_like_librsf(tmp_path / "set") and looks_like_librsf(inp) and looks_like_librsf(gt)
    assert not looks_like_librsf(tmp_path / "set" / "other.txt")
    write_set(tmp_path / "set", name="Other")
    with pytest.raises(GslamError, match="expected exactly one \\*_Input.txt in the folder, found Other_Input.txt, Test_Input.txt"):
        dataset_files(tmp_path / "set")


def error_of(path) -> str:
    with pytest.raises(GslamError) as info:
        read_librsf(path)
    msg = str(info.value)
    assert msg and "\n" not in msg
    return msg


def test_bad_inputs_give_one_line_errors(tmp_path):
    assert "no such file or directory" in error_of(tmp_path / "absent_Input.txt")
    inp = write_set(tmp_path / "a", input_lines=["odom2 0 0 0 0 1 1 1", "odom2 0.1 0.5 zero 0 1 1 1"])
    assert error_of(inp) == f"{inp}:2: expected odom2 t vx vy wz var_vx var_vy var_wz"
    inp = write_set(tmp_path / "b", input_lines=["odom2 0 0 0 0 1 1 1", "odom2 0.1 0.5"])
    assert error_of(inp).startswith(f"{inp}:2: expected odom2")
    inp = write_set(tmp_path / "c", input_lines=["loop 1 2 3"])
    assert "expected at least 2 'odom2" in error_of(inp)
    inp = write_set(tmp_path / "d", input_lines=["odom2 1 0 0 0 1 1 1", "odom2 0.5 0 0 0 1 1 1"])
    assert "expected increasing times" in error_of(inp)
    inp = write_set(tmp_path / "e", gt_lines=["point2 0 1.0 2.0 0 0 0 0", "point2 0.2 x 2.0 0 0 0 0"])
    assert error_of(inp) == f"{tmp_path / 'e' / 'Test_GT.txt'}:2: expected point2 t x y c_xx c_xy c_yx c_yy"
    binary = tmp_path / "f" / "Bin_Input.txt"
    binary.parent.mkdir()
    binary.write_bytes(bytes(range(256)))
    assert "binary content" in error_of(binary)
    other = tmp_path / "notes.txt"
    other.write_text("odom2 0 0 0 0 1 1 1\n")
    assert "expected a libRSF *_Input.txt or *_GT.txt file" in error_of(other)


# --- real data ------------------------------------------------------------


def test_real_corridor():
    folder = real_data("librsf/Corridor_Input.txt").parent
    rec = read_librsf(folder)
    assert rec.name == "Corridor"
    assert rec.duration == pytest.approx(2269.0, abs=1.0)
    assert len(rec.odometry) == 22692
    assert np.median(np.diff(rec.odometry.t)) == pytest.approx(0.1, abs=1e-3)
    g = rec.groundtruth
    assert len(g) == 11346
    # A corridor about 167 m long and 2 m wide; odometry path close to the truth's.
    assert 150.0 < np.ptp(g.x) < 180.0 and np.ptp(g.y) < 5.0
    path_gt = np.sum(np.hypot(np.diff(g.x), np.diff(g.y)))
    o = rec.odometry
    path_odo = np.sum(np.hypot(np.diff(o.x), np.diff(o.y)))
    assert abs(path_odo - path_gt) / path_gt < 0.05
