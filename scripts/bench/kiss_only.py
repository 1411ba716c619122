"""KISS-ICP alone on a bag's LaserScan topic: the floor of what mapping a
recorded run costs, as a process a user would write.

    python -m scripts.bench.kiss_only BAG [--topic /scan] [--poses OUT.txt] [--threads N]

It reads the topic with rosbags' ``AnyReader``, deserialising message by
message, turns each scan into planar points (finite ranges, z = 0) and
registers it with KissICP's default config, with ``max_range`` from the
scan's ``range_max`` and the voxel ``max_range / 100`` (KISS-ICP's own rule
when no voxel is given), on all cores unless ``--threads`` says otherwise
(``--threads 1``: the one thread gslam's front-end uses, for the same
poses on every run). No 2D scanner gives per-point stamps, so no point
is deskewed. After each scan the pose and velocity are made exactly planar
again, as gslam's front-end does: without it, round-off over a long blind
stretch makes KISS-ICP's Sophus abort the process (telemax_loop does this).
It prints the scans registered, the data span and the wall
time of the process so far (imports included). ``BAG`` is a ``.bag``, a
rosbag2 folder, or a simulated run folder (its ``bag/``), or a CARMEN log
(``.log``, ``.log.gz``): its ``FLASER`` lines, 180 deg from the right
(``laser_front_laser_fov`` when the log sets it), ``max_range`` 50 m (beyond
it the logs hold saturation values: ``configs/datasets/carmen.yaml``).

It imports nothing of gslam but the handler its exit shares with the other
scripts (slam.errors, 2 ms), so its cost is KISS-ICP's and rosbags' alone.
"""

from __future__ import annotations

import time

START = time.perf_counter()

import argparse  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
from kiss_icp.config import load_config  # noqa: E402
from kiss_icp.kiss_icp import KissICP  # noqa: E402
from rosbags.highlevel import AnyReader  # noqa: E402
from rosbags.typesys import Stores, get_typestore  # noqa: E402


def bag_path(path: Path) -> Path:
    """A rosbag2 folder or ROS 1 file; a simulated run folder's ``bag/``."""
    if (path / "bag").is_dir():
        return path / "bag"
    return path


def planar(transform: np.ndarray) -> np.ndarray:
    """The planar rigid transform closest in yaw to a 4x4 ``transform``."""
    yaw = np.arctan2(transform[1, 0], transform[0, 0])
    c, s = np.cos(yaw), np.sin(yaw)
    out = np.eye(4)
    out[:2, :2] = [[c, -s], [s, c]]
    out[:2, 3] = transform[:2, 3]
    return out


def kiss_only(path: Path, topic: str, threads: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Stamps (s, header) and KISS-ICP poses (n, 4, 4) of every scan on ``topic``."""
    store = get_typestore(Stores.ROS1_NOETIC if path.suffix == ".bag" else Stores.LATEST)
    stamps, poses = [], []
    if not path.exists():
        raise SystemExit(f"kiss_only: {path}: no such file or directory")
    try:
        reader = AnyReader([path], default_typestore=store)
        reader.open()
    except Exception as err:  # rosbags raises many types for what is no bag
        why = str(err).strip().splitlines()[0] if str(err).strip() else type(err).__name__
        raise SystemExit(f"kiss_only: {path}: not a readable ROS bag ({why})") from None
    try:
        conns = [c for c in reader.connections if c.topic == topic]
        if not conns:
            raise SystemExit(f"kiss_only: {path}: no topic {topic}")
        icp = None
        for conn, _, raw in reader.messages(connections=conns):
            msg = reader.deserialize(raw, conn.msgtype)
            if icp is None:
                config = load_config(None)  # KISS-ICP's defaults
                config.data.max_range = float(msg.range_max)
                config.mapping.voxel_size = config.data.max_range / 100.0
                config.registration.max_num_threads = threads  # 0: all cores (the default)
                icp = KissICP(config)
                beams = np.arange(len(msg.ranges))
                angles = msg.angle_min + beams * msg.angle_increment
                cos, sin = np.cos(angles), np.sin(angles)
            r = np.asarray(msg.ranges, dtype=np.float64)
            ok = np.isfinite(r)
            points = np.column_stack([r[ok] * cos[ok], r[ok] * sin[ok], np.zeros(int(ok.sum()))])
            icp.register_frame(points, np.zeros(0))
            # Over a long blind stretch (the yard: no returns, prediction only)
            # KISS-ICP's 4x4 float products drift off a rotation and Sophus
            # aborts the process; keep them planar, as slam/frontend/kiss.py does.
            icp.last_pose, icp.last_delta = planar(icp.last_pose), planar(icp.last_delta)
            stamps.append(msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec)
            poses.append(icp.last_pose.copy())
    finally:
        reader.close()
    return np.asarray(stamps), np.asarray(poses)


CARMEN_MAX_RANGE_M = 50.0


def is_carmen(path: Path) -> bool:
    return path.name.endswith((".log", ".log.gz"))


def carmen_scans(path: Path) -> tuple[np.ndarray, np.ndarray, list[np.ndarray]]:
    """Stamps, beam angles and ranges of a CARMEN log's ``FLASER`` lines."""
    import gzip

    opener = gzip.open if path.name.endswith(".gz") else open
    fov, stamps, ranges = np.pi, [], []
    with opener(path, "rt") as f:
        for line in f:
            parts = line.split()
            if parts[:2] == ["PARAM", "laser_front_laser_fov"]:
                value = float(parts[2])
                fov = value if value <= 2.0 * np.pi + 1e-6 else np.radians(value)  # degrees, or radians (csail)
            elif parts and parts[0] == "FLASER":
                n = int(parts[1])
                ranges.append(np.array(parts[2 : 2 + n], dtype=np.float64))
                stamps.append(float(parts[n + 8]))
    n = len(ranges[0]) if ranges else 0
    step = fov / (n - 1) if n % 2 == 1 and n > 1 else fov / max(n, 1)
    return np.asarray(stamps), -fov / 2.0 + step * np.arange(n), ranges


def kiss_only_carmen(path: Path, threads: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Stamps and KISS-ICP poses (n, 4, 4) of every scan of a CARMEN log."""
    stamps, angles, scans = carmen_scans(path)
    config = load_config(None)
    config.data.max_range = CARMEN_MAX_RANGE_M
    config.mapping.voxel_size = config.data.max_range / 100.0
    config.registration.max_num_threads = threads
    icp = KissICP(config)
    cos, sin = np.cos(angles), np.sin(angles)
    poses = []
    for r in scans:
        ok = np.isfinite(r) & (r < CARMEN_MAX_RANGE_M)
        icp.register_frame(np.column_stack([r[ok] * cos[ok], r[ok] * sin[ok], np.zeros(int(ok.sum()))]), np.zeros(0))
        icp.last_pose, icp.last_delta = planar(icp.last_pose), planar(icp.last_delta)
        poses.append(icp.last_pose.copy())
    return stamps, np.asarray(poses)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("bag", type=Path, help="a .bag file, a rosbag2 folder, a simulated run folder or a CARMEN log")
    p.add_argument("--topic", default="/scan", help="the LaserScan topic (default /scan)")
    p.add_argument("--poses", type=Path, default=None, help="write 't x y yaw' per scan to this file")
    p.add_argument("--threads", type=int, default=0, help="KISS-ICP's threads (default 0: all cores)")
    args = p.parse_args(argv)
    if is_carmen(args.bag):
        stamps, poses = kiss_only_carmen(args.bag, args.threads)
    else:
        stamps, poses = kiss_only(bag_path(args.bag), args.topic, args.threads)
    if args.poses is not None:
        yaw = np.arctan2(poses[:, 1, 0], poses[:, 0, 0])
        np.savetxt(args.poses, np.column_stack([stamps, poses[:, 0, 3], poses[:, 1, 3], yaw]), fmt="%.6f")
    span = stamps[-1] - stamps[0] if len(stamps) else 0.0
    print(f"kiss_only: {len(stamps)} scans, {span:.1f} s of data, {time.perf_counter() - START:.3f} s wall")
    return 0


if __name__ == "__main__":
    from slam.errors import run_script

    run_script("kiss_only", main)
