"""Write the simulated streams as a ROS 2 bag (rosbags, Humble message types).

Topics, types and frames:

=================  ===============================  ==========================
``/scan``          sensor_msgs/msg/LaserScan        ``laser`` (robot centre)
``/imu/data``      sensor_msgs/msg/Imu              ``base_link``
``/imu/mag``       sensor_msgs/msg/MagneticField    ``base_link`` (tesla)
``/odom``          nav_msgs/msg/Odometry            ``odom`` -> ``base_link``
``/gps/fix``       sensor_msgs/msg/NavSatFix        ``gps``
``/ground_truth``  nav_msgs/msg/Odometry            ``map`` -> ``base_link``
=================  ===============================  ==========================

Header stamps equal the bag timestamps: ``t0`` plus the sample time, in
nanoseconds. Messages are written in time order.
"""

from __future__ import annotations

import heapq
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterator

import numpy as np
from rosbags.rosbag2 import Writer
from rosbags.typesys import Stores, get_typestore

from validation.base.geometry import quaternion_from_yaw
from slam.sim.robot import Motion
from slam.sim.sensors import GpsData, GyroData, LaserData, MagData, OdomData

TOPICS: dict[str, str] = {
    "/scan": "sensor_msgs/msg/LaserScan",
    "/imu/data": "sensor_msgs/msg/Imu",
    "/imu/mag": "sensor_msgs/msg/MagneticField",
    "/odom": "nav_msgs/msg/Odometry",
    "/gps/fix": "sensor_msgs/msg/NavSatFix",
    "/ground_truth": "nav_msgs/msg/Odometry",
}

GRAVITY_M_S2 = 9.81


@dataclass
class Streams:
    """Everything that goes into the bag."""

    truth: Motion
    laser: LaserData
    gyro: GyroData
    mag: MagData
    odom: OdomData
    gps: GpsData


class _Messages:
    """Builds and serialises messages of the Humble type store."""

    def __init__(self, t0_ns: int) -> None:
        self.store = get_typestore(Stores.ROS2_HUMBLE)
        self.T = self.store.types
        self.t0_ns = t0_ns

    def stamp(self, t: float) -> int:
        return self.t0_ns + int(round(t * 1e9))

    def header(self, ns: int, frame: str):
        stamp = self.T["builtin_interfaces/msg/Time"](ns // 10**9, ns % 10**9)
        return self.T["std_msgs/msg/Header"](stamp, frame)

    def vec(self, x: float, y: float, z: float):
        return self.T["geometry_msgs/msg/Vector3"](float(x), float(y), float(z))

    def ser(self, msg, topic: str) -> bytes:
        return bytes(self.store.serialize_cdr(msg, TOPICS[topic]))

    def odometry(self, ns: int, frame: str, x: float, y: float, yaw: float, v: float, w: float):
        T = self.T
        pose = T["geometry_msgs/msg/Pose"](
            T["geometry_msgs/msg/Point"](float(x), float(y), 0.0),
            T["geometry_msgs/msg/Quaternion"](*quaternion_from_yaw(float(yaw))),
        )
        twist = T["geometry_msgs/msg/Twist"](self.vec(v, 0, 0), self.vec(0, 0, w))
        return T["nav_msgs/msg/Odometry"](
            self.header(ns, frame),
            "base_link",
            T["geometry_msgs/msg/PoseWithCovariance"](pose, np.zeros(36)),
            T["geometry_msgs/msg/TwistWithCovariance"](twist, np.zeros(36)),
        )


def _scan(m: _Messages, d: LaserData) -> Iterator[tuple[int, str, bytes]]:
    inc = float(d.angles[1] - d.angles[0])
    period = float(d.t[1] - d.t[0]) if len(d.t) > 1 else 0.0
    for k, t in enumerate(d.t):
        ns = m.stamp(t)
        msg = m.T["sensor_msgs/msg/LaserScan"](
            m.header(ns, "laser"), float(d.angles[0]), float(d.angles[-1]), inc, 0.0, period,
            float(d.range_min), float(d.range_max), d.ranges[k], np.zeros(0, dtype=np.float32),
        )  # fmt: skip
        yield ns, "/scan", m.ser(msg, "/scan")


def _imu(m: _Messages, d: GyroData) -> Iterator[tuple[int, str, bytes]]:
    no_orientation = np.zeros(9)
    no_orientation[0] = -1.0  # REP-145: orientation not provided
    quat = m.T["geometry_msgs/msg/Quaternion"](0.0, 0.0, 0.0, 1.0)
    for t, rate in zip(d.t, d.rate):
        ns = m.stamp(t)
        msg = m.T["sensor_msgs/msg/Imu"](
            m.header(ns, "base_link"), quat, no_orientation, m.vec(0, 0, rate), np.zeros(9),
            m.vec(0, 0, GRAVITY_M_S2), np.zeros(9),
        )  # fmt: skip
        yield ns, "/imu/data", m.ser(msg, "/imu/data")


def _mag(m: _Messages, d: MagData) -> Iterator[tuple[int, str, bytes]]:
    for t, b in zip(d.t, d.field):
        ns = m.stamp(t)
        msg = m.T["sensor_msgs/msg/MagneticField"](m.header(ns, "base_link"), m.vec(*b), np.zeros(9))
        yield ns, "/imu/mag", m.ser(msg, "/imu/mag")


def _odom(m: _Messages, d: OdomData) -> Iterator[tuple[int, str, bytes]]:
    for k, t in enumerate(d.t):
        ns = m.stamp(t)
        msg = m.odometry(ns, "odom", d.x[k], d.y[k], d.yaw[k], d.v[k], d.w[k])
        yield ns, "/odom", m.ser(msg, "/odom")


def _truth(m: _Messages, d: Motion) -> Iterator[tuple[int, str, bytes]]:
    for k, t in enumerate(d.t):
        ns = m.stamp(t)
        msg = m.odometry(ns, "map", d.x[k], d.y[k], d.yaw[k], d.v[k], d.w[k])
        yield ns, "/ground_truth", m.ser(msg, "/ground_truth")


def _gps(m: _Messages, d: GpsData) -> Iterator[tuple[int, str, bytes]]:
    cov = np.diag([d.sigma**2, d.sigma**2, (2.0 * d.sigma) ** 2]).ravel()
    for k, t in enumerate(d.t):
        ns = m.stamp(t)
        fix = d.status[k] == 0
        status = m.T["sensor_msgs/msg/NavSatStatus"](int(d.status[k]), 1)
        msg = m.T["sensor_msgs/msg/NavSatFix"](
            m.header(ns, "gps"), status, float(d.lat[k]), float(d.lon[k]),
            d.altitude if fix else float("nan"), cov, 2,
        )  # fmt: skip
        yield ns, "/gps/fix", m.ser(msg, "/gps/fix")


def write_bag(path: str | Path, streams: Streams, t0_s: float, progress: Any = None) -> dict[str, int]:
    """Write all streams into a new bag folder ``path``; returns the number
    of messages per topic. ``progress`` is an optional tqdm-like bar."""
    m = _Messages(int(round(t0_s * 1e9)))
    generators = [
        _scan(m, streams.laser), _imu(m, streams.gyro), _mag(m, streams.mag),
        _odom(m, streams.odom), _gps(m, streams.gps), _truth(m, streams.truth),
    ]  # fmt: skip
    counts = dict.fromkeys(TOPICS, 0)
    with Writer(Path(path), version=8) as writer:
        conns = {
            topic: writer.add_connection(topic, msgtype, typestore=m.store)
            for topic, msgtype in TOPICS.items()
        }
        # (stamp, topic) orders the merge; a topic never repeats a stamp.
        for ns, topic, data in heapq.merge(*generators, key=lambda item: (item[0], item[1])):
            writer.write(conns[topic], ns, data)
            counts[topic] += 1
            if progress is not None:
                progress.update(1)
    return counts
