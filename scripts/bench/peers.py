"""The peer a KISS-ICP user tries first for laser SLAM: kiss-slam
(PRBonn, ``pip install kiss-slam``), run as a process on the same scans.

kiss-slam reads point clouds from a folder (its ``generic`` dataloader);
each scan becomes one PLY file, written with open3d. kiss-slam brings
numpy and kiss-icp versions of its own, so it lives in its own virtual
environment: ``python3 -m venv ks && ks/bin/pip install kiss-slam pillow
matplotlib`` (open3d there needs libusb-1.0, Debian's ``libusb-1.0-0``),
then ``--kiss-slam ks/bin/kiss_slam_pipeline``.

Two settings: kiss-slam's defaults, and ``indoor``: voxels, local maps and
density maps at the scale of an indoor 2D scan (the sizes of
``configs/datasets/carmen.yaml``), which is what a user mapping these logs
would set first.
"""

from __future__ import annotations

import re
import shutil
import subprocess
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from slam.frontend.kiss import ScanProjector
from slam.outputs.pointcloud import import_open3d
from slam.recording import Scans, Trajectory

INDOOR = """\
odometry:
  preprocessing: {max_range: 50.0, min_range: 0.1, deskew: false}
  mapping: {voxel_size: 0.2, max_points_per_voxel: 20}
  adaptive_threshold: {initial_threshold: 1.0, min_motion_th: 0.05}
local_mapper: {voxel_size: 0.2, splitting_distance: 20.0}
occupancy_mapper: {resolution: 0.1, z_min: -0.5, z_max: 0.5}
loop_closer:
  detector: {density_map_resolution: 0.2}
"""
"""kiss-slam's keys for indoor 2D scans (the rest at its defaults)."""


BLIND_M = 1.0e4
"""Where a scan without returns gets its one point (open3d writes no empty cloud)."""


@dataclass
class PeerRun:
    """kiss-slam's trajectory (at the scan times), its loop closures and
    the process's wall time (s); ``error``: why there is none."""

    trajectory: Trajectory | None
    closures: int | None
    wall_s: float
    error: str = ""


def export_scans(scans: Scans, folder: Path, min_range: float, max_range: float) -> None:
    """One PLY file per scan (points in the laser frame, z = 0), in order."""
    o3d = import_open3d()
    folder.mkdir(parents=True, exist_ok=True)
    project = ScanProjector(scans.angles, min_range, min(max_range, scans.range_max))
    for i in range(len(scans)):
        points = project(scans.ranges[i])
        if len(points) == 0:  # one return beyond any range kiss-slam keeps: a blind scan, still in its place
            points = np.array([[BLIND_M, 0.0, 0.0]])
        cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
        o3d.io.write_point_cloud(str(folder / f"{i:06d}.ply"), cloud)


def _last_error(text: str) -> str:
    """The error a program ended with, from its (rich-formatted) output: the
    exception's name and the last plain line."""
    plain = re.sub(r"\x1b\[[0-9;]*m", "", text)
    lines = [ln.strip() for ln in plain.splitlines() if ln.strip() and ln.strip()[0] not in "│╭╰─"]
    if not lines:
        return "no output"
    names = [m.group(1) for ln in lines if (m := re.match(r"(\w+(?:Error|Exception)):", ln))]
    last = lines[-1]
    return (f"{names[-1]}: {last}" if names and not last.startswith(names[-1]) else last)[:160]


def kiss_slam(executable: str, scans_folder: Path, t: np.ndarray, work: Path, setting: str) -> PeerRun:
    """Run kiss-slam (``setting``: ``default`` or ``indoor``) on a folder of
    PLY scans taken at times ``t``, in ``work``."""
    if shutil.which(executable) is None:
        return PeerRun(None, None, 0.0, f"{executable} not found")
    work.mkdir(parents=True, exist_ok=True)
    cmd = [executable, str(scans_folder), "--dataloader", "generic"]
    if setting == "indoor":
        (work / "indoor.yaml").write_text(INDOOR)
        cmd += ["--config", str(work / "indoor.yaml")]
    start = time.perf_counter()
    done = subprocess.run(cmd, cwd=work, capture_output=True, text=True)
    wall = time.perf_counter() - start
    poses = sorted(work.glob("slam_output/*/*_poses_kitti.txt"))
    if not poses:
        return PeerRun(None, None, wall, f"exit {done.returncode}: {_last_error(done.stderr or done.stdout)}")
    rows = np.loadtxt(poses[-1]).reshape(-1, 3, 4)
    n = min(len(rows), len(t))
    yaw = np.arctan2(rows[:n, 1, 0], rows[:n, 0, 0])
    traj = Trajectory(t=t[:n].copy(), x=rows[:n, 0, 3], y=rows[:n, 1, 3], yaw=yaw)
    closures = None
    log = sorted(work.glob("slam_output/*/result_metrics.log"))
    if log:
        found = re.search(r"Number of closures found\s*\|\s*(\d+)", log[-1].read_text())
        closures = int(found.group(1)) if found else None
    return PeerRun(traj, closures, wall)
