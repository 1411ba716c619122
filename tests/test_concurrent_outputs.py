"""The concurrent pipeline writes what the plain one writes.

``gslam map`` matches scans and draws figures in a second process
(slam.processes.background, slam.frontend.worker, slam.outputs.result_writer) and writes its large
files vectorised (map.ply with numpy, TUM files a block of lines at a
time). Each test compares against the plain path: the same run mapped with
``concurrent=False``, open3d's PLY writer, a TUM writer that formats one
pose at a time, the ROS bag read in one pass.
"""

from __future__ import annotations

import json
import os
import signal

import numpy as np
import pytest

from slam.processes.background import Forked, Inline, can_fork, start
from slam.config import load_config
from slam.errors import GslamError
from validation.base.geometry import quaternion_from_yaw
from slam.outputs.pointcloud import import_open3d, ply_bytes, write_ply
from slam.readers.read import read_recording
from slam.outputs.tum import read_tum, tum_text
from slam.pipeline.folder import run_map
from slam.recording import Trajectory
from tests.conftest import TELEMAX_CONFIG

pytestmark = pytest.mark.slow  # end to end: pytest -m 'not slow' leaves it out

TIMINGS = ("runtime_s", "realtime_factor", "timings_s", "validation_time_s")
needs_fork = pytest.mark.skipif(not can_fork(), reason="no fork on this platform: the pipeline runs in one process")


def result_files(folder):
    """Every file's bytes, metrics.json without its timings, the marker (a time) left out."""
    files = {}
    for p in sorted(folder.iterdir()):
        if p.name == ".gslam-result.json":
            continue
        if p.name == "metrics.json":
            m = json.loads(p.read_text())
            files[p.name] = json.dumps({k: v for k, v in m.items() if k not in TIMINGS}, sort_keys=True).encode()
        else:
            files[p.name] = p.read_bytes()
    return files


@needs_fork
@pytest.mark.parametrize("mode", ["on", "off"])
def test_concurrent_map_writes_the_same_bytes_as_the_plain_one(short_run, tmp_path, mode):
    config = load_config(TELEMAX_CONFIG, [f"validation.mode={mode}"])
    fast = run_map(short_run.run_dir, config, tmp_path / "fast")
    plain = run_map(short_run.run_dir, config, tmp_path / "plain", concurrent=False)
    a, b = result_files(fast.out_dir), result_files(plain.out_dir)
    assert {"trajectory.png", "map.png", "map.ply", "groundtruth.tum", "config.yaml"} <= set(a)
    assert set(a) == set(b)
    for name in a:
        assert a[name] == b[name], name
    timings = fast.metrics["timings_s"]
    assert timings["frontend"] > 0 and timings["frontend_wait"] <= fast.metrics["runtime_s"]


@needs_fork
def test_odometry_guesses_are_given_after_the_whole_run_is_read(short_run, tmp_path):
    config = load_config(TELEMAX_CONFIG, ["frontend.initial_guess=odometry", "output.plots=false"])
    fast = run_map(short_run.run_dir, config, tmp_path / "fast")
    plain = run_map(short_run.run_dir, config, tmp_path / "plain", concurrent=False)
    assert result_files(fast.out_dir) == result_files(plain.out_dir)


def test_scans_read_first_are_the_recordings_scans(short_run):
    config = load_config(TELEMAX_CONFIG).input
    early = []
    rec = read_recording(short_run.run_dir, config, on_scans=early.append)
    plain = read_recording(short_run.run_dir, config)
    assert len(early) == 1
    scans = early[0]
    assert scans.t[0] == 0.0 and np.allclose(scans.t + (rec.scans.t[0] - scans.t[0]), rec.scans.t, atol=1e-9)
    assert np.array_equal(scans.ranges, rec.scans.ranges) and np.array_equal(scans.angles, rec.scans.angles)
    for name in ("scans", "gyro", "compass", "odometry", "gps", "groundtruth"):
        a, b = getattr(rec, name), getattr(plain, name)
        assert (a is None) == (b is None), name
        if a is not None:
            assert np.array_equal(a.t, b.t), name
    assert rec.t0 == plain.t0 and np.array_equal(rec.scans.ranges, plain.scans.ranges)


# --- large outputs ---------------------------------------------------------------


def test_ply_is_byte_for_byte_what_open3d_writes(tmp_path):
    o3d = import_open3d()
    rng = np.random.default_rng(3)
    pts = rng.normal(0.0, 20.0, (1000, 2))
    pts[0] = [-0.0, 0.0]
    cloud = o3d.geometry.PointCloud()
    cloud.points = o3d.utility.Vector3dVector(np.column_stack([pts, np.zeros(len(pts))]))
    assert o3d.io.write_point_cloud(str(tmp_path / "o3d.ply"), cloud)
    write_ply(tmp_path / "ours.ply", pts)
    assert (tmp_path / "ours.ply").read_bytes() == (tmp_path / "o3d.ply").read_bytes()
    back = np.asarray(o3d.io.read_point_cloud(str(tmp_path / "ours.ply")).points)
    assert np.array_equal(back[:, :2], pts)


def test_an_empty_map_is_a_ply_without_points():
    # open3d refuses to write an empty cloud; the map of a run without returns is one.
    head, _, body = ply_bytes(np.zeros((0, 2))).partition(b"end_header\n")
    assert b"element vertex 0\n" in head and body == b""


def reference_tum(traj: Trajectory, t0: float) -> str:
    """One pose at a time, as the TUM writer formatted it before."""
    lines = ["# timestamp x y z qx qy qz qw"]
    for t, x, y, yaw in zip(traj.t, traj.x, traj.y, traj.yaw):
        qx, qy, qz, qw = quaternion_from_yaw(float(yaw))
        lines.append(f"{t0 + float(t):.9f} {float(x):.6f} {float(y):.6f} {0.0:.6f} {qx:.9f} {qy:.9f} {qz:.9f} {qw:.9f}")
    return "\n".join(lines) + "\n"


def test_tum_text_equals_formatting_one_pose_at_a_time(tmp_path):
    rng = np.random.default_rng(7)
    n = 5000
    traj = Trajectory(t=np.sort(rng.uniform(0, 7200, n)), x=rng.normal(0, 300, n), y=rng.normal(0, 3, n),
                      yaw=rng.uniform(-7, 7, n))
    traj.yaw[:6] = [0.0, -0.0, np.pi, -np.pi, 2 * np.pi, 1e-12]
    traj.x[:3] = [-0.0, 5e-7, -5e-7]
    for chunk in (1, 7, 65536):
        assert tum_text(traj, 1.7e9, chunk=chunk) == reference_tum(traj, 1.7e9)
    (tmp_path / "a.tum").write_text(tum_text(traj, 1.7e9))
    back, _ = read_tum(tmp_path / "a.tum", 1.7e9)
    assert np.allclose(back.x, traj.x, atol=1e-6)
    assert tum_text(Trajectory(t=np.zeros(0), x=np.zeros(0), y=np.zeros(0), yaw=np.zeros(0)), 0.0) == reference_tum(
        Trajectory(t=np.zeros(0), x=np.zeros(0), y=np.zeros(0), yaw=np.zeros(0)), 0.0)


# --- the second process ------------------------------------------------------------


def _echo(inbox, offset):
    return [inbox() + offset, inbox() + offset]


def _fail(inbox):
    raise GslamError("bad scan 3")


def _die(inbox):
    os.kill(os.getpid(), signal.SIGKILL)


@pytest.mark.parametrize("concurrent", [True, False])
def test_background_work_returns_what_inline_work_returns(concurrent):
    job = start("echo", _echo, 10, concurrent=concurrent)
    assert isinstance(job, Forked if concurrent and can_fork() else Inline)
    job.send(1)
    job.send(2)
    assert job.result() == [11, 12]


@pytest.mark.parametrize("concurrent", [True, False])
def test_an_error_in_background_work_is_raised_in_the_caller(concurrent):
    job = start("failing", _fail, concurrent=concurrent)
    with pytest.raises(GslamError, match="bad scan 3"):
        job.result()


@pytest.mark.parametrize("concurrent", [True, False])
def test_an_error_in_background_work_fed_as_it_goes_is_raised_in_the_caller(concurrent):
    job = start("failing", _fail, concurrent=concurrent)
    with pytest.raises(GslamError, match="bad scan 3"):
        for k in range(100_000):  # the child ends while it is still fed
            job.send(np.zeros(16) + k)
        job.result()


@needs_fork
def test_a_background_process_that_dies_is_a_one_line_error():
    job = start("scan matching", _die)
    with pytest.raises(GslamError, match=r"scan matching: its process ended without a result \(signal 9\)"):
        job.result()


@needs_fork
def test_closing_unfinished_background_work_ends_its_process():
    job = start("echo", _echo, 0)  # waits for input that never comes
    job.close()
    assert not job.process.is_alive()


@needs_fork
def test_a_failing_figure_is_an_error_of_the_map_and_leaves_no_process(tmp_path, monkeypatch):
    import slam.outputs.result_writer as result_writer

    def broken(run, grid, points):
        raise ValueError("no room for the legend")

    monkeypatch.setattr(result_writer, "draw_map", broken)  # the forked drawers inherit it
    est = Trajectory(t=np.arange(3.0), x=np.zeros(3), y=np.arange(3.0), yaw=np.zeros(3))
    before = _children()
    writer = result_writer.ResultWriter(concurrent=True)
    writer.submit(result_writer.FinalEstimate(tmp_path, "run", est, None, {}))
    writer.submit_map(result_writer.MapInputs(points=np.zeros((4, 2))))
    with pytest.raises(ValueError, match="no room for the legend"):
        writer.wait()
    writer.close()
    assert not (tmp_path / "map.png").exists()
    assert _children() <= before


@needs_fork
@pytest.mark.parametrize("concurrent", [True, False])
def test_the_self_check_made_aside_is_the_one_made_here_and_its_error_reaches_the_caller(concurrent, monkeypatch):
    import slam.outputs.result_writer as result_writer
    import slam.outputs.self_check as self_check

    est = Trajectory(t=np.arange(3.0), x=np.zeros(3), y=np.arange(3.0), yaw=np.zeros(3))
    checker = result_writer.SelfChecker(concurrent)
    checker.submit({"trajectory": est, "blame_share": 0.25})
    made = checker.wait()
    checker.close()
    here = self_check.check_map(est, blame_share=0.25)
    assert made.as_dict() == here.as_dict() and made.as_dict()["blame_share"] == 0.25

    def broken(*args, **kwargs):
        raise ValueError("no neighbours")

    monkeypatch.setattr(self_check, "check_map", broken)  # the forked child inherits it
    before = _children()
    checker = result_writer.SelfChecker(concurrent)
    checker.submit({"trajectory": est})
    with pytest.raises(ValueError, match="no neighbours"):
        checker.wait()
    checker.close()
    assert _children() <= before


def _children() -> set[int]:
    return {int(p) for p in os.listdir("/proc") if p.isdigit() and _parent_of(int(p)) == os.getpid()}


def _parent_of(pid: int) -> int | None:
    try:
        with open(f"/proc/{pid}/stat") as f:
            return int(f.read().rsplit(")", 1)[1].split()[1])
    except (OSError, ValueError, IndexError):
        return None


@needs_fork
def test_an_error_preparing_the_scans_reaches_the_caller(short_run, monkeypatch):
    import slam.frontend.worker as scan_matching

    def broken(scans, config, guesses):
        yield from ()
        raise ValueError("voxel grid refused")

    monkeypatch.setattr(scan_matching, "prepared_chunks", broken)
    config = load_config(TELEMAX_CONFIG)
    rec = read_recording(short_run.run_dir, config.input)
    sm = scan_matching.BackgroundScanMatching(config.frontend, concurrent=True)
    sm.give(rec.scans)
    with pytest.raises(ValueError, match="voxel grid refused"):
        sm.result(rec.scans)
    sm.close()
    assert not sm.worker.process.is_alive()
