"""Faults written into a ROS 1 or ROS 2 bag: every message is copied, those
of the faulty sensors' topics changed as :mod:`slam.commands.inject.physics` says.

Messages are matched to the recording as the reader made it by their
header stamps (recording time = stamp - ``Recording.t0``). A change made in
the project's frames (ENU, REP-103) is turned back into the topic's own
(``input.frames``) before it is written, so the bag stays in its own
conventions. ROS 1 bags are written as ROS 1 (the connections' message
definitions kept), ROS 2 bags as ROS 2 (same storage: sqlite3 or mcap).
"""

from __future__ import annotations

import logging
from collections import defaultdict
from pathlib import Path
from typing import Any

import numpy as np

from slam.config import InputConfig, StreamFrameConfig
from slam.errors import GslamError
from validation.base.geometry import enu_from_geodetic, geodetic_from_enu, wrap_angle, yaw_from_quaternion
from slam.commands.inject import physics
from slam.commands.inject.labels import Labels
from slam.commands.inject.spec import (
    DipoleFault, Fault, GyroBiasFault, LaserCutFault, MultipathFault, SlipFault, no_sample,
)
from slam.readers import frames
from slam.readers.rosbag import open_bag, resolve_bag_path
from slam.readers.rosbag_mcap import foreign_channels
from slam.recording import Recording

log = logging.getLogger(__name__)

_NS = 1_000_000_000


def _heading_sign(frame: StreamFrameConfig) -> float:
    """The sign of an ENU heading change in the stream's own heading."""
    return (-1.0 if frame.world == "ned" else 1.0) * frame.yaw_sign


def _topic(config: InputConfig, fault: Fault) -> tuple[str, str]:
    """The topic a fault changes and the stream's name."""
    stream = {"dipole": "compass", "laser_cut": "scan", "gyro_bias": "gyro", "slip": "odometry",
              "multipath": "gps"}[fault.kind]
    topic = getattr(config.topics, stream)
    if topic is None:
        raise GslamError(f"--fault {fault.text()}: the recording has no {stream} (input.topics.{stream} is null)")
    return topic, stream


class _Edits:
    """The messages of one topic, deserialised, with their recording times."""

    def __init__(self, msgs: list[Any], t0: float) -> None:
        self.msgs = msgs
        self.t = np.array([m.header.stamp.sec + 1e-9 * m.header.stamp.nanosec for m in msgs]) - t0


def _dipole(e: _Edits, fault: DipoleFault, rec: Recording, config: InputConfig, labels: Labels) -> None:
    path = rec.groundtruth if rec.groundtruth is not None else rec.odometry
    if path is None:
        raise GslamError(f"--fault {fault.text()}: placing a dipole beside the path needs ground truth or odometry")
    dipole = physics.Dipole(fault, path)
    added = dipole.field_body(e.t)
    frame = config.frames.compass
    magnetometer = config.compass.source == "magnetic_field"
    if fault.target == "magnetometer" and not magnetometer or fault.target == "heading" and magnetometer:
        raise GslamError(f"--fault {fault.text()}: the compass is a {config.compass.source}, not a {fault.target}")
    if magnetometer:
        field = np.array([[m.magnetic_field.x, m.magnetic_field.y, m.magnetic_field.z] for m in e.msgs])
        change = physics.heading_change(frames.body_vector(field, frame), added)
        raw = frames.body_vector(added, frame)  # FRD is its own inverse
        for m, b in zip(e.msgs, raw):
            m.magnetic_field.x += b[0]
            m.magnetic_field.y += b[1]
            m.magnetic_field.z += b[2]
    else:
        heading = np.interp(e.t, rec.compass.t, np.unwrap(rec.compass.yaw))
        change = physics.heading_error(heading, added, fault.earth_horizontal_uT * 1e-6)
        turn = _heading_sign(frame) * change
        for m, a in zip(e.msgs, turn):
            q = m.orientation  # about the world's vertical: z * q
            c, s = np.cos(0.5 * a), np.sin(0.5 * a)
            q.x, q.y, q.z, q.w = c * q.x - s * q.y, c * q.y + s * q.x, c * q.z + s * q.w, c * q.w - s * q.z
    labels.add("IMU_YAW", e.t, np.abs(change) > np.radians(fault.label_deg))


def _laser_cut(e: _Edits, fault: LaserCutFault, labels: Labels) -> None:
    cut = physics.inside(e.t, fault.start_s, fault.end_s)
    rows = []
    for m, c in zip(e.msgs, cut):
        if c:
            m.ranges = physics.cut_ranges(m.ranges, fault.range_m, np.inf).astype(np.float32)
            rows.append(m)
    if rows:
        angles = rows[0].angle_min + rows[0].angle_increment * np.arange(len(rows[0].ranges))
        bad = physics.laser_labels(np.vstack([m.ranges for m in rows]), angles, rows[0].range_min, rows[0].range_max, fault)
        for modality, mask in bad.items():
            labels.add(modality, e.t[cut], mask)


def _gyro_bias(e: _Edits, fault: GyroBiasFault, config: InputConfig, labels: Labels) -> None:
    on = physics.inside(e.t, fault.start_s, fault.end_s)
    frame = config.frames.gyro
    world = config.gyro.axis == "world_z"
    # The raw rate that reads as +bias about up.
    bias = frames.yaw_rate(np.array([np.radians(fault.bias_deg_s)]), frame, "world" if world else "body")[0]
    for m, o in zip(e.msgs, on):
        if not o:
            continue
        w = m.angular_velocity
        if world:  # along the world's z seen from the body: the third row of R(q)
            q = m.orientation
            n = np.sqrt(q.x**2 + q.y**2 + q.z**2 + q.w**2)
            x, y, z, r = q.x / n, q.y / n, q.z / n, q.w / n
            up = (2 * (x * z - r * y), 2 * (y * z + r * x), 1 - 2 * (x * x + y * y))
            w.x, w.y, w.z = w.x + bias * up[0], w.y + bias * up[1], w.z + bias * up[2]
        else:
            setattr(w, config.gyro.axis, getattr(w, config.gyro.axis) + bias)
    labels.add("IMU_GYRO", e.t, on & (abs(fault.bias_deg_s) > fault.label_deg_s))


def _slip(e: _Edits, fault: SlipFault, labels: Labels) -> None:
    poses = [m.pose.pose for m in e.msgs]
    x = np.array([p.position.x for p in poses])
    y = np.array([p.position.y for p in poses])
    q = np.array([[p.orientation.x, p.orientation.y, p.orientation.z, p.orientation.w] for p in poses])
    yaw = yaw_from_quaternion(q[:, 0], q[:, 1], q[:, 2], q[:, 3])
    nx, ny, nyaw = physics.reintegrate(e.t, x, y, yaw, fault)
    for p, qq, a, b, c, old in zip(poses, q, nx, ny, nyaw, yaw):
        p.position.x, p.position.y = float(a), float(b)
        turn = float(wrap_angle(c - old))  # about the vertical, keeping any tilt
        cc, ss = np.cos(0.5 * turn), np.sin(0.5 * turn)
        p.orientation.x, p.orientation.y = cc * qq[0] - ss * qq[1], cc * qq[1] + ss * qq[0]
        p.orientation.z, p.orientation.w = cc * qq[2] + ss * qq[3], cc * qq[3] - ss * qq[2]
    for comp, mask in physics.slip_labels(e.t, x, y, yaw, fault).items():
        labels.add(comp, e.t, mask)


def _multipath(e: _Edits, fault: MultipathFault, datum: tuple[float, float], labels: Labels) -> None:
    fixed = np.array([m.status.status >= 0 and np.isfinite(m.latitude) for m in e.msgs], dtype=bool)
    if not (fixed & physics.inside(e.t, fault.start_s, fault.end_s)).any():  # a bag whose GPS topic has no fix
        raise GslamError(no_sample(fault, "GPS fix with a position"))
    bias = physics.multipath_bias(e.t, fault)
    sigma = np.array([np.sqrt(0.5 * (m.position_covariance[0] + m.position_covariance[4]))
                      if m.position_covariance_type != 0 else 1.0 for m in e.msgs])
    for m, ok, b in zip(e.msgs, fixed, bias):
        if ok and (b[0] or b[1]):
            east, north = enu_from_geodetic(m.latitude, m.longitude, *datum)
            m.latitude, m.longitude = (float(v) for v in geodetic_from_enu(east + b[0], north + b[1], *datum))
    labels.add("GPS", e.t, fixed & (np.hypot(bias[:, 0], bias[:, 1]) > fault.label_sigmas * sigma))


def inject_rosbag(source: Path, dest: Path, rec: Recording, config: InputConfig, faults: list[Fault]) -> Labels:
    """Copy the bag at ``source`` into ``dest`` (a folder: a ROS 1 bag is
    written inside it under its own name, a ROS 2 bag becomes it) with
    ``faults`` added; their true intervals."""
    by_topic: dict[str, list[Fault]] = defaultdict(list)
    for fault in faults:
        by_topic[_topic(config, fault)[0]].append(fault)
    bag_path = resolve_bag_path(source)
    reader = open_bag(source)
    try:
        # A channel of another encoding (an MCAP file's JSON) has no ROS 2
        # definition to write it with: the copy is of the ROS 2 ones.
        foreign = foreign_channels(reader.connections)
        for topic, encoding in sorted(foreign.items()):
            log.warning("%s: topic '%s' not copied: its messages are %s, not ROS 2's CDR", bag_path, topic, encoding)
        conns = [c for c in reader.connections if c.topic not in foreign]
        present = {c.topic for c in conns}
        for topic, fs in by_topic.items():
            if topic not in present:
                raise GslamError(f"--fault {fs[0].text()}: topic '{topic}' is not in {bag_path}")
        messages = [(c, ts, raw) for c, ts, raw in reader.messages(connections=conns)]
        edits = {topic: _Edits([reader.deserialize(raw, c.msgtype) for c, _, raw in messages if c.topic == topic], rec.t0)
                 for topic in by_topic}
        labels = Labels()
        datum = _datum(config, edits, by_topic)
        for topic, fs in by_topic.items():
            for fault in fs:
                _apply(edits[topic], fault, rec, config, datum, labels)
        _write(reader, bag_path, dest, conns, messages, edits)
    finally:
        reader.close()
    return labels


def _datum(config: InputConfig, edits: dict[str, _Edits], by_topic: dict[str, list[Fault]]) -> tuple[float, float]:
    """The GPS datum the reader uses: the configured one, else the first
    fix with a position (before any bias is added)."""
    if config.gps.datum_lat_deg is not None:
        return config.gps.datum_lat_deg, config.gps.datum_lon_deg
    topic = config.topics.gps
    if topic in edits:
        for m in edits[topic].msgs:
            if m.status.status >= 0 and np.isfinite(m.latitude):
                return float(m.latitude), float(m.longitude)
    return 0.0, 0.0


def _apply(e: _Edits, fault: Fault, rec: Recording, config: InputConfig, datum, labels: Labels) -> None:
    if isinstance(fault, DipoleFault):
        _dipole(e, fault, rec, config, labels)
    elif isinstance(fault, LaserCutFault):
        _laser_cut(e, fault, labels)
    elif isinstance(fault, GyroBiasFault):
        _gyro_bias(e, fault, config, labels)
    elif isinstance(fault, SlipFault):
        _slip(e, fault, labels)
    elif isinstance(fault, MultipathFault):
        _multipath(e, fault, datum, labels)


def _write(reader: Any, source: Path, dest: Path, conns: list, messages: list, edits: dict[str, _Edits]) -> None:
    changed = {topic: iter(e.msgs) for topic, e in edits.items()}
    store = reader.typestore
    if source.suffix == ".bag":
        from rosbags.rosbag1 import Writer

        dest.mkdir(parents=True, exist_ok=True)
        with Writer(dest / source.name) as writer:
            out = {c.id: writer.add_connection(c.topic, c.msgtype, msgdef=c.msgdef.data, md5sum=c.digest,
                                               callerid=c.ext.callerid, latching=c.ext.latching)
                   for c in conns}
            for c, ts, raw in messages:
                if c.topic in changed:
                    raw = store.serialize_ros1(next(changed[c.topic]), c.msgtype)
                writer.write(out[c.id], ts, raw)
        return
    from rosbags.rosbag2 import StoragePlugin, Writer

    plugin = StoragePlugin.MCAP if any(p.suffix == ".mcap" for p in _files(source)) else StoragePlugin.SQLITE3
    with Writer(dest, version=9, storage_plugin=plugin) as writer:
        out = {c.id: writer.add_connection(c.topic, c.msgtype, typestore=store) for c in conns}
        for c, ts, raw in messages:
            if c.topic in changed:
                raw = store.serialize_cdr(next(changed[c.topic]), c.msgtype)
            writer.write(out[c.id], ts, raw)


def _files(source: Path) -> list[Path]:
    return [source] if source.is_file() else list(source.iterdir())
