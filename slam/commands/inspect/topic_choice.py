"""Which topic of a bag feeds which stream, as ``gslam inspect`` guesses it.

From the topics' message types and names, and a few decoded messages:

* one topic per stream (the busiest of its type): a laser, an IMU's gyro,
  a heading (a magnetometer, else the IMU's orientation when it has one),
  the odometry, GPS fixes, and a reference (a topic named like
  ``ground_truth``);
* further ``nav_msgs/Odometry`` topics become further odometry sources
  (``input.extra_odometry``), each named after its topic, unless their name
  says they are an estimate fused from other sensors (``odometry/filtered``,
  ``ekf``, ``gps``...), which is no independent witness;
* how the IMU is mounted, from its first messages: an orientation
  estimate (``orientation_covariance[0]`` not -1) whose z axis is more than
  :data:`TILTED_DEG` off the vertical makes the yaw rate the world-vertical
  one (``gyro.axis: world_z``); without an orientation, the axis the
  accelerometer reads gravity on (REP-145: +9.81 on the axis pointing up)
  is the yaw axis, and a down-pointing one flips its sign.
"""

from __future__ import annotations

import itertools
import logging
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from slam.errors import GslamError
from slam.readers.rosbag import open_bag
from slam.readers.rosbag_streams import IMU, LASER_SCAN, MAGNETIC_FIELD, NAV_SAT_FIX, ODOMETRY, POSE_STAMPED

log = logging.getLogger(__name__)

GROUNDTRUTH_HINTS = ("ground_truth", "groundtruth", "gt", "vicon", "mocap", "optitrack")
FUSED_HINTS = ("filtered", "ekf", "ukf", "fused", "fusion", "global", "map", "amcl", "localization", "slam", "gps",
               "navsat", "estimate")
"""Odometry topics named like these are estimates fused from other sensors."""
PERCEPTION_HINTS = ("visual", "vo", "vio", "camera", "cam", "zed", "t265", "realsense", "orb", "stereo", "lidar",
                    "loam", "icp", "laser")
"""Odometry topics named like these come from perception, not from wheels or tracks."""
_GENERIC = {"odom", "odometry", "data", "sample", "out", "raw", "nav", "msg", "topic", "pose", "state", "base"}
TILTED_DEG = 30.0
SAMPLES = 50


@dataclass(frozen=True)
class TopicInfo:
    """A topic's name, message type and message count."""

    name: str
    msgtype: str
    count: int


@dataclass(frozen=True)
class ImuFacts:
    """What the first messages of an Imu topic show.

    ``orientation``: they carry an orientation estimate; ``tilt_deg``: the
    median angle of its body z axis from the vertical; ``up``: the body
    axis the accelerometer reads gravity's reaction on (``x``, ``y``,
    ``z``) and its sign, None when no axis holds most of it."""

    orientation: bool
    tilt_deg: float | None
    up: tuple[str, int] | None


@dataclass
class TopicChoice:
    """The guessed topics and what was left aside, with reasons."""

    scan: str | None = None
    gyro: str | None = None
    compass: str | None = None
    compass_source: str = "magnetic_field"
    odometry: str | None = None
    gps: str | None = None
    groundtruth: str | None = None
    extra_odometry: dict[str, str] = field(default_factory=dict)
    gyro_axis: str = "z"
    gyro_frame: dict[str, Any] = field(default_factory=dict)
    max_range_m: float | None = None
    notes: list[str] = field(default_factory=list)
    """One line per decision a user may want to check."""
    others: dict[str, list[str]] = field(default_factory=dict)
    """Per stream, the other topics of its type."""


def _words(topic: str) -> list[str]:
    return [w for w in re.split(r"[^a-z0-9]+", topic.lower()) if w]


def _hinted(topic: str, hints: tuple[str, ...]) -> bool:
    words = _words(topic)
    return any(h in words or (len(h) > 3 and h in topic.lower()) for h in hints)


def _busiest(topics: list[TopicInfo], types: tuple[str, ...]) -> list[TopicInfo]:
    return sorted((t for t in topics if t.msgtype in types), key=lambda t: -t.count)


def source_name(topic: str, taken: set[str]) -> str:
    """A further odometry source's name from its topic: its first word that
    is not generic (``/vo/odom`` -> ``vo``), lower-case letters and digits,
    not a name taken already or reserved."""
    from validation.streams.names import RESERVED_SOURCE_NAMES

    words = [w for w in _words(topic) if w not in _GENERIC]
    base = words[0] if words else "odo"
    if base[0].isdigit():
        base = f"o{base}"
    name = base
    for k in itertools.count(2):
        if name not in taken and name not in RESERVED_SOURCE_NAMES:
            return name
        name = f"{base}{k}"
    raise AssertionError("unreachable")


def sample_messages(bag: Path, topic: str, count: int = SAMPLES) -> list[Any]:
    """The first ``count`` messages of ``topic``, decoded."""
    reader = open_bag(bag)
    try:
        conns = [c for c in reader.connections if c.topic == topic]
        out = []
        try:
            for conn, _, raw in itertools.islice(reader.messages(connections=conns), count):
                out.append(reader.deserialize(raw, conn.msgtype))
        except Exception as err:  # rosbags, sqlite3, lz4...: all mean a broken file
            text = str(err).strip().splitlines()
            raise GslamError(f"{bag}: corrupt bag ({text[0] if text else type(err).__name__})") from None
        return out
    finally:
        reader.close()


def imu_facts(messages: list[Any]) -> ImuFacts:
    """:class:`ImuFacts` of decoded sensor_msgs/Imu messages."""
    if not messages:
        return ImuFacts(False, None, None)
    quats = np.array([[m.orientation.x, m.orientation.y, m.orientation.z, m.orientation.w] for m in messages])
    norms = np.linalg.norm(quats, axis=1)
    has = all(m.orientation_covariance[0] != -1.0 for m in messages) and bool(np.all(np.abs(norms - 1.0) < 0.1))
    tilt = None
    if has:
        x, y, _, w = (quats / norms[:, None]).T
        tilt = float(np.degrees(np.median(np.arccos(np.clip(1.0 - 2.0 * (x * x + y * y), -1.0, 1.0)))))
    acc = np.median([[m.linear_acceleration.x, m.linear_acceleration.y, m.linear_acceleration.z] for m in messages],
                    axis=0)
    up = None
    norm = float(np.linalg.norm(acc))
    if norm > 5.0:  # a reading of gravity, not zeros
        axis = int(np.argmax(np.abs(acc)))
        if abs(acc[axis]) > 0.8 * norm:
            up = ("xyz"[axis], 1 if acc[axis] > 0 else -1)
    return ImuFacts(has, tilt, up)


def choose_topics(bag: Path, topics: list[TopicInfo]) -> TopicChoice:
    """The guess of the module docstring."""
    choice = TopicChoice()
    gts = [t for t in _busiest(topics, (ODOMETRY, POSE_STAMPED)) if _hinted(t.name, GROUNDTRUTH_HINTS)]
    if gts:
        choice.groundtruth = gts[0].name
        choice.others["groundtruth"] = [t.name for t in gts[1:]]
    rest = [t for t in topics if t.name != choice.groundtruth and t not in gts]
    scans = _busiest(rest, (LASER_SCAN,))
    if scans:
        choice.scan = scans[0].name
        choice.others["scan"] = [t.name for t in scans[1:]]
        first = sample_messages(bag, choice.scan, 1)
        if first and np.isfinite(first[0].range_max) and first[0].range_max > 0:
            choice.max_range_m = float(first[0].range_max)
    _choose_imu(bag, rest, choice)
    gps = _busiest(rest, (NAV_SAT_FIX,))
    if gps:
        choice.gps = gps[0].name
        choice.others["gps"] = [t.name for t in gps[1:]]
    _choose_odometry(rest, choice)
    return choice


def _choose_imu(bag: Path, topics: list[TopicInfo], choice: TopicChoice) -> None:
    imus = _busiest(topics, (IMU,))
    mags = _busiest(topics, (MAGNETIC_FIELD,))
    facts = None
    if imus:
        choice.gyro = imus[0].name
        choice.others["gyro"] = [t.name for t in imus[1:]]
        facts = imu_facts(sample_messages(bag, choice.gyro))
        _gyro_axis(facts, choice)
    if mags:
        choice.compass, choice.compass_source = mags[0].name, "magnetic_field"
        choice.others["compass"] = [t.name for t in mags[1:]]
        choice.notes.append(f"heading: the magnetometer {mags[0].name} (a level robot)")
    elif facts is not None and facts.orientation:
        choice.compass, choice.compass_source = choice.gyro, "imu_orientation"
        choice.notes.append(f"heading: the orientation estimate of {choice.gyro} (no magnetometer topic)")
    elif imus:
        choice.notes.append(f"heading: none ({choice.gyro} carries no orientation, and no magnetometer topic)")


def _gyro_axis(facts: ImuFacts, choice: TopicChoice) -> None:
    if facts.orientation and facts.tilt_deg is not None and facts.tilt_deg > TILTED_DEG:
        choice.gyro_axis = "world_z"
        choice.notes.append(f"gyro: {choice.gyro}'s z axis is {facts.tilt_deg:.0f} deg off the vertical: the yaw "
                            "rate is the world-vertical part of its rates (gyro.axis world_z)")
        return
    if facts.orientation or facts.up is None:
        return
    axis, sign = facts.up
    choice.gyro_axis = axis
    if sign < 0:
        # frd flips the body y and z rates; x needs the stream mirrored.
        choice.gyro_frame = {"body": "frd"} if axis in "yz" else {"yaw_sign": -1}
    if axis != "z" or sign < 0:
        choice.notes.append(f"gyro: {choice.gyro} reads gravity on its {'-' if sign < 0 else '+'}{axis} axis: "
                            f"that axis is the yaw axis (gyro.axis {axis}"
                            + (f", frames.gyro {choice.gyro_frame}" if choice.gyro_frame else "") + ")")


def _choose_odometry(topics: list[TopicInfo], choice: TopicChoice) -> None:
    odoms = _busiest(topics, (ODOMETRY,))
    fused = [t for t in odoms if _hinted(t.name, FUSED_HINTS)]
    own = [t for t in odoms if t not in fused]
    for t in fused:
        choice.notes.append(f"not used: {t.name}, by its name an estimate fused from other sensors (no witness "
                            "of its own)")
    if not own:
        return
    wheels = [t for t in own if not _hinted(t.name, PERCEPTION_HINTS)]
    main = (wheels or own)[0]
    choice.odometry = main.name
    taken: set[str] = set()
    for t in own:
        if t is main:
            continue
        name = source_name(t.name, taken)
        taken.add(name)
        choice.extra_odometry[name] = t.name
        choice.notes.append(f"further odometry source '{name}': {t.name} (components {name.upper()}_DIST, "
                            f"{name.upper()}_YAW; validated, not a factor)")
    poses = [t.name for t in topics if t.msgtype == POSE_STAMPED]
    if poses:
        choice.notes.append(f"not used: {', '.join(poses)} (geometry_msgs/PoseStamped, not a reference by its name)")
