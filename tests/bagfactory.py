"""Build small ROS 1 / ROS 2 bags with known contents for tests.

Usage::

    bag = BagBuilder(ros=1)
    bag.imu("/imu/data", t=100.0, rate_z=0.1, yaw=0.3)
    bag.scan("/scan", t=100.05, ranges=[1.0, 2.0, 3.0])
    path = bag.write(tmp_path / "run.bag")          # ROS 1 (.bag)
    path = BagBuilder(ros=2)...write(tmp_path / "run")  # rosbag2 directory

Times are absolute seconds; each message's header stamp is ``t`` and its
bag (log) time is ``log_t`` (default ``t``). Messages are written sorted by
log time, so header stamps can be made out of order on purpose.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from rosbags.typesys import Stores, get_typestore

from validation.base.geometry import quaternion_from_yaw

from slam.readers.rosbag import IMU, LASER_SCAN, MAGNETIC_FIELD, NAV_SAT_FIX, ODOMETRY, POSE_STAMPED


def _ns(t: float) -> int:
    return int(round(t * 1e9))


class BagBuilder:
    """Collects messages per topic and writes them as one bag."""

    def __init__(self, ros: int = 2) -> None:
        if ros not in (1, 2):
            raise ValueError("ros must be 1 or 2")
        self.ros = ros
        self.typestore = get_typestore(Stores.ROS1_NOETIC if ros == 1 else Stores.ROS2_HUMBLE)
        self.types = self.typestore.types
        # (log_ns, insertion order, topic, msgtype, message)
        self._messages: list[tuple[int, int, str, str, Any]] = []
        self._topics: dict[str, str] = {}

    # -- generic --------------------------------------------------------

    def add(self, topic: str, msgtype: str, msg: Any, log_t: float) -> None:
        """Add any message of ``msgtype`` logged at ``log_t`` (s)."""
        known = self._topics.setdefault(topic, msgtype)
        if known != msgtype:
            raise ValueError(f"{topic} already carries {known}")
        self._messages.append((_ns(log_t), len(self._messages), topic, msgtype, msg))

    def topic(self, topic: str, msgtype: str) -> None:
        """Declare a topic without messages (an empty stream)."""
        self._topics.setdefault(topic, msgtype)

    def header(self, t: float, frame_id: str = "base_link") -> Any:
        ns = _ns(t)
        stamp = self.types["builtin_interfaces/msg/Time"](sec=ns // 10**9, nanosec=ns % 10**9)
        if self.ros == 1:
            return self.types["std_msgs/msg/Header"](seq=0, stamp=stamp, frame_id=frame_id)
        return self.types["std_msgs/msg/Header"](stamp=stamp, frame_id=frame_id)

    def _vec(self, x: float, y: float, z: float) -> Any:
        return self.types["geometry_msgs/msg/Vector3"](x=float(x), y=float(y), z=float(z))

    def _quat(self, yaw: float) -> Any:
        qx, qy, qz, qw = quaternion_from_yaw(yaw)
        return self.types["geometry_msgs/msg/Quaternion"](x=qx, y=qy, z=qz, w=qw)

    def _pose(self, x: float, y: float, yaw: float) -> Any:
        point = self.types["geometry_msgs/msg/Point"](x=float(x), y=float(y), z=0.0)
        return self.types["geometry_msgs/msg/Pose"](position=point, orientation=self._quat(yaw))

    # -- typed messages -------------------------------------------------

    def scan(
        self,
        topic: str,
        t: float,
        ranges: Sequence[float],
        angle_min: float = -np.pi / 2,
        angle_increment: float = np.pi / 180,
        range_min: float = 0.1,
        range_max: float = 30.0,
        log_t: float | None = None,
    ) -> None:
        """sensor_msgs/LaserScan."""
        r = np.asarray(ranges, dtype=np.float32)
        msg = self.types[LASER_SCAN](
            header=self.header(t, "laser"),
            angle_min=float(angle_min),
            angle_max=float(angle_min + (len(r) - 1) * angle_increment),
            angle_increment=float(angle_increment),
            time_increment=0.0,
            scan_time=0.1,
            range_min=float(range_min),
            range_max=float(range_max),
            ranges=r,
            intensities=np.zeros(0, dtype=np.float32),
        )
        self.add(topic, LASER_SCAN, msg, t if log_t is None else log_t)

    def imu(
        self,
        topic: str,
        t: float,
        rate_z: float = 0.0,
        yaw: float = 0.0,
        has_orientation: bool = True,
        log_t: float | None = None,
        gravity: Sequence[float] = (0.0, 0.0, 9.81),
    ) -> None:
        """sensor_msgs/Imu with yaw rate ``rate_z`` (rad/s) and orientation
        yaw ``yaw`` (rad); ``has_orientation=False`` marks the orientation
        as absent (covariance[0] = -1, REP-145); ``gravity``: what the
        accelerometer reads at rest (m/s^2, +9.81 on the axis pointing up)."""
        cov = np.zeros(9)
        ocov = cov.copy()
        if not has_orientation:
            ocov[0] = -1.0
        msg = self.types[IMU](
            header=self.header(t, "imu"),
            orientation=self._quat(yaw),
            orientation_covariance=ocov,
            angular_velocity=self._vec(0.0, 0.0, rate_z),
            angular_velocity_covariance=cov.copy(),
            linear_acceleration=self._vec(*gravity),
            linear_acceleration_covariance=cov.copy(),
        )
        self.add(topic, IMU, msg, t if log_t is None else log_t)

    def mag(self, topic: str, t: float, field: Sequence[float], log_t: float | None = None) -> None:
        """sensor_msgs/MagneticField, ``field`` (3,) tesla in the sensor frame."""
        msg = self.types[MAGNETIC_FIELD](
            header=self.header(t, "mag"),
            magnetic_field=self._vec(*field),
            magnetic_field_covariance=np.zeros(9),
        )
        self.add(topic, MAGNETIC_FIELD, msg, t if log_t is None else log_t)

    def odom(
        self, topic: str, t: float, x: float, y: float, yaw: float, log_t: float | None = None
    ) -> None:
        """nav_msgs/Odometry with a planar pose."""
        pwc = self.types["geometry_msgs/msg/PoseWithCovariance"](
            pose=self._pose(x, y, yaw), covariance=np.zeros(36)
        )
        twist = self.types["geometry_msgs/msg/Twist"](
            linear=self._vec(0, 0, 0), angular=self._vec(0, 0, 0)
        )
        twc = self.types["geometry_msgs/msg/TwistWithCovariance"](twist=twist, covariance=np.zeros(36))
        msg = self.types[ODOMETRY](
            header=self.header(t, "odom"), child_frame_id="base_link", pose=pwc, twist=twc
        )
        self.add(topic, ODOMETRY, msg, t if log_t is None else log_t)

    def pose(
        self, topic: str, t: float, x: float, y: float, yaw: float, log_t: float | None = None
    ) -> None:
        """geometry_msgs/PoseStamped with a planar pose."""
        msg = self.types[POSE_STAMPED](header=self.header(t, "map"), pose=self._pose(x, y, yaw))
        self.add(topic, POSE_STAMPED, msg, t if log_t is None else log_t)

    def fix(
        self,
        topic: str,
        t: float,
        lat: float,
        lon: float,
        status: int = 0,
        variance_m2: tuple[float, float] = (1.0, 1.0),
        covariance_type: int = 2,
        log_t: float | None = None,
    ) -> None:
        """sensor_msgs/NavSatFix; ``variance_m2`` is the (east, north)
        diagonal of the position covariance."""
        cov = np.zeros(9)
        cov[0], cov[4], cov[8] = variance_m2[0], variance_m2[1], 4.0
        msg = self.types[NAV_SAT_FIX](
            header=self.header(t, "gps"),
            status=self.types["sensor_msgs/msg/NavSatStatus"](status=int(status), service=1),
            latitude=float(lat),
            longitude=float(lon),
            altitude=100.0,
            position_covariance=cov,
            position_covariance_type=int(covariance_type),
        )
        self.add(topic, NAV_SAT_FIX, msg, t if log_t is None else log_t)

    # -- output ---------------------------------------------------------

    def write_in(self, folder: str | Path, name: str = "run", storage: str = "sqlite3") -> Path:
        """Write to ``folder/name.bag`` (ROS 1) or ``folder/name/`` (ROS 2)."""
        folder = Path(folder)
        return self.write(folder / (f"{name}.bag" if self.ros == 1 else name), storage)

    def write(self, path: str | Path, storage: str = "sqlite3") -> Path:
        """Write the bag and return its path.

        ROS 1 writes one ``.bag`` file (``path`` must end in ``.bag``);
        ROS 2 writes a rosbag2 directory ``path`` with ``storage``
        ``sqlite3`` or ``mcap``.
        """
        path = Path(path)
        ordered = sorted(self._messages, key=lambda m: (m[0], m[1]))
        if self.ros == 1:
            from rosbags.rosbag1 import Writer as Writer1

            if path.suffix != ".bag":
                raise ValueError("a ROS 1 bag path must end in .bag")
            with Writer1(path) as writer:
                conns = {
                    topic: writer.add_connection(topic, msgtype, typestore=self.typestore)
                    for topic, msgtype in self._topics.items()
                }
                for log_ns, _, topic, msgtype, msg in ordered:
                    writer.write(conns[topic], log_ns, self.typestore.serialize_ros1(msg, msgtype))
            return path

        from rosbags.rosbag2 import StoragePlugin
        from rosbags.rosbag2 import Writer as Writer2

        plugin = {"sqlite3": StoragePlugin.SQLITE3, "mcap": StoragePlugin.MCAP}[storage]
        with Writer2(path, version=9, storage_plugin=plugin) as writer:
            conns = {
                topic: writer.add_connection(topic, msgtype, typestore=self.typestore)
                for topic, msgtype in self._topics.items()
            }
            for log_ns, _, topic, msgtype, msg in ordered:
                writer.write(conns[topic], log_ns, self.typestore.serialize_cdr(msg, msgtype))
        return path


def with_foreign_channel(source: Path, dest: Path, topic: str, encoding: str = "json",
                         schema_encoding: str = "jsonschema") -> Path:
    """A copy of the MCAP file ``source`` (a ROS 2 bag's) into ``dest`` with a
    channel of another encoding on ``topic``, as a tool other than rosbag2
    adds one: a new channel, a message beside each of the first channel's;
    or, if ``source`` has ``topic``, that channel's messages re-encoded
    (``schema_encoding`` "": no schema at all)."""
    import json

    from mcap.reader import make_reader
    from mcap.writer import Writer

    with open(source, "rb") as f, open(dest, "wb") as g:
        reader = make_reader(f)
        summary = reader.get_summary()
        writer = Writer(g)
        writer.start(profile="ros2", library="tests.bagfactory")
        schemas = {s.id: writer.register_schema(s.name, s.encoding, s.data) for s in summary.schemas.values()}
        foreign = (writer.register_schema("Diagnostics", schema_encoding, b'{"type": "object"}') if schema_encoding
                   else 0)
        replaced = {c.id for c in summary.channels.values() if c.topic == topic}
        channels = {c.id: writer.register_channel(c.topic, encoding if c.id in replaced else c.message_encoding,
                                                  foreign if c.id in replaced else schemas[c.schema_id], c.metadata)
                    for c in summary.channels.values()}
        added = writer.register_channel(topic, encoding, foreign) if not replaced else None
        beside = min(summary.channels)
        for _, channel, message in reader.iter_messages(log_time_order=True):
            data = json.dumps({"ok": True}).encode() if channel.id in replaced else message.data
            writer.add_message(channels[channel.id], message.log_time, data, message.publish_time, message.sequence)
            if added is not None and channel.id == beside:
                writer.add_message(added, message.log_time, json.dumps({"ok": True}).encode(), message.publish_time)
        writer.finish()
    return dest


def split_mcap(source: Path, dest: Path, parts: int = 2, foreign: dict[int, tuple[str, str, str]] | None = None) -> Path:
    """The one-file MCAP rosbag2 folder ``source`` split by log time into
    ``parts`` files of a rosbag2 folder ``dest`` (as ``ros2 bag record
    --max-bag-duration`` splits), its metadata listing them; ``foreign``:
    part -> (topic, encoding, schema encoding) of a channel that another
    tool added to that part, a message beside each message of its first
    channel there (schema encoding "": no schema)."""
    import json

    import yaml
    from mcap.reader import make_reader
    from mcap.writer import Writer

    dest.mkdir(parents=True)
    (mcap,) = source.glob("*.mcap")
    with open(mcap, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        messages = list(reader.iter_messages(log_time_order=True))
    size = -(-len(messages) // parts)
    names = [f"{dest.name}_{k}.mcap" for k in range(parts)]
    for k, name in enumerate(names):
        with open(dest / name, "wb") as g:
            writer = Writer(g)
            writer.start(profile="ros2", library="tests.bagfactory")
            schemas = {s.id: writer.register_schema(s.name, s.encoding, s.data) for s in summary.schemas.values()}
            channels = {c.id: writer.register_channel(c.topic, c.message_encoding, schemas[c.schema_id], c.metadata)
                        for c in summary.channels.values()}
            added = None
            if foreign is not None and k in foreign:
                topic, encoding, schema_encoding = foreign[k]
                schema = (writer.register_schema("Diagnostics", schema_encoding, b'{"type": "object"}')
                          if schema_encoding else 0)
                added = writer.register_channel(topic, encoding, schema)
            chunk = messages[k * size:(k + 1) * size]
            beside = chunk[0][1].id if chunk else None
            for _, channel, message in chunk:
                writer.add_message(channels[channel.id], message.log_time, message.data, message.publish_time,
                                   message.sequence)
                if added is not None and channel.id == beside:
                    writer.add_message(added, message.log_time, json.dumps({"ok": True}).encode(),
                                       message.publish_time)
            writer.finish()
    meta = yaml.safe_load((source / "metadata.yaml").read_text())
    info = meta["rosbag2_bagfile_information"]
    info["relative_file_paths"] = names
    info["files"] = [{"path": name, "starting_time": {"nanoseconds_since_epoch": messages[k * size][2].log_time},
                      "duration": {"nanoseconds": messages[min((k + 1) * size, len(messages)) - 1][2].log_time
                                   - messages[k * size][2].log_time},
                      "message_count": len(messages[k * size:(k + 1) * size])} for k, name in enumerate(names)]
    (dest / "metadata.yaml").write_text(yaml.safe_dump(meta, sort_keys=False))
    return dest


def driving_bag(
    ros: int = 2,
    t0: float = 1_700_000_000.0,
    duration_s: float = 2.0,
    speed_m_s: float = 1.0,
    yaw: float = 0.5,
    datum: tuple[float, float] = (48.0, 11.0),
) -> BagBuilder:
    """A robot driving straight at ``speed_m_s`` along world yaw ``yaw`` on
    the default topics of :class:`slam.config.TopicsConfig`: scans 10 Hz
    (5 beams at 2 m), Imu 100 Hz (rate 0, orientation ``yaw``), magnetometer
    20 Hz (level, no declination), odometry 20 Hz, GPS 5 Hz about ``datum``,
    ground truth 100 Hz."""
    from validation.base.geometry import geodetic_from_enu

    bag = BagBuilder(ros)
    c, s = np.cos(yaw), np.sin(yaw)
    # Level field of 20 uT north, 40 uT down, seen from a body at ``yaw``.
    field = (20e-6 * np.cos(np.pi / 2 - yaw), 20e-6 * np.sin(np.pi / 2 - yaw), -40e-6)

    def ticks(rate_hz: float) -> np.ndarray:
        return t0 + np.arange(int(round(duration_s * rate_hz))) / rate_hz

    for t in ticks(10):
        bag.scan("/scan", t, [2.0] * 5)
    for t in ticks(100):
        bag.imu("/imu/data", t, rate_z=0.0, yaw=yaw)
        d = speed_m_s * (t - t0)
        bag.odom("/ground_truth", t, d * c, d * s, yaw)
    for t in ticks(20):
        bag.mag("/imu/mag", t, field)
        d = speed_m_s * (t - t0)
        bag.odom("/odom", t, d, 0.0, 0.0)
    for t in ticks(5):
        d = speed_m_s * (t - t0)
        lat, lon = geodetic_from_enu(d * c, d * s, *datum)
        bag.fix("/gps/fix", t, float(lat), float(lon))
    return bag


def ned_driving_bag(
    t0: float = 1_700_000_000.0,
    duration_s: float = 90.0,
    datum: tuple[float, float] = (48.0, 11.0),
    seed: int = 0,
) -> tuple[BagBuilder, dict[str, np.ndarray]]:
    """A ROS 1 bag of a robot driving left and right turns, recorded with
    aerospace conventions: the Imu's rates in an x-forward, y-right, z-down
    body (a left turn is a negative ``angular_velocity.z``) and its
    orientation's yaw a heading clockwise from north (NED), odometry and
    ground truth with x north and y east (NED). GPS fixes are geodetic.
    Topics: ``/imu/data`` 50 Hz, ``/odom`` 10 Hz, ``/fix`` 2 Hz,
    ``/ground_truth`` 50 Hz. Sensor noise is seeded: gyro 0.2 deg/s, heading
    1 deg, odometry 2 % of distance and turn. Returns the bag and the true
    ENU path (``t`` s from ``t0``, ``x``, ``y``, ``yaw``)."""
    from validation.base.geometry import geodetic_from_enu

    rng = np.random.default_rng(seed)
    dt = 0.02
    t = np.arange(0.0, duration_s, dt)
    # Left and right turns between straight legs, at 1 m/s.
    rate = np.zeros_like(t)
    for start, end, r in ((10, 16, 0.26), (30, 40, -0.31), (52, 58, 0.52), (70, 80, -0.16)):
        rate[(t >= start) & (t < end)] = r
    yaw = 0.4 + np.concatenate([[0.0], np.cumsum(rate[:-1] * dt)])
    x = np.concatenate([[0.0], np.cumsum(np.cos(yaw[:-1]) * dt)])
    y = np.concatenate([[0.0], np.cumsum(np.sin(yaw[:-1]) * dt)])
    # Odometry: integrated with its own errors.
    odo_yaw = 0.4 + np.concatenate([[0.0], np.cumsum(1.02 * rate[:-1] * dt)])
    odo_x = np.concatenate([[0.0], np.cumsum(0.98 * np.cos(odo_yaw[:-1]) * dt)])
    odo_y = np.concatenate([[0.0], np.cumsum(0.98 * np.sin(odo_yaw[:-1]) * dt)])
    bag = BagBuilder(ros=1)
    gyro_noise = np.radians(0.2) * rng.standard_normal(len(t))
    heading_noise = np.radians(1.0) * rng.standard_normal(len(t))
    for k, tk in enumerate(t):
        stamp = t0 + tk
        # NED heading of an FRD body: clockwise from north.
        bag.imu("/imu/data", stamp, rate_z=-(rate[k] + gyro_noise[k]), yaw=np.pi / 2 - (yaw[k] + heading_noise[k]))
        bag.odom("/ground_truth", stamp, y[k], x[k], np.pi / 2 - yaw[k])
        if k % 5 == 0:
            bag.odom("/odom", stamp, odo_y[k], odo_x[k], np.pi / 2 - odo_yaw[k])
        if k % 25 == 0:
            lat, lon = geodetic_from_enu(x[k] + rng.normal(0, 0.5), y[k] + rng.normal(0, 0.5), *datum)
            bag.fix("/fix", stamp, float(lat), float(lon), variance_m2=(0.25, 0.25))
    return bag, {"t": t, "x": x, "y": y, "yaw": yaw}


SENSOR_TOPICS = {
    "imu": "/imu/data", "mag": "/imu/mag", "odom": "/odom", "vo": "/vo/odom", "odom2": "/wheels2/odom",
    "gps": "/fix", "filtered": "/odometry/filtered",
}
"""The topic each sensor of :func:`sensor_bag` is written on."""


def sensor_bag(
    sensors: Sequence[str],
    duration_s: float = 150.0,
    seed: int = 0,
    faults: dict[str, tuple[float, float]] | None = None,
    unrelated: Sequence[str] = (),
    ros: int = 1,
    t0: float = 1_700_000_000.0,
    datum: tuple[float, float] = (48.0, 11.0),
    heading_offset: float = 0.0,
) -> BagBuilder:
    """A robot driving 1 m/s with left and right turns and changes of speed,
    recorded by the ``sensors`` of :data:`SENSOR_TOPICS`:

    * ``imu``: sensor_msgs/Imu at 50 Hz, yaw rate with 0.2 deg/s noise and a
      0.05 deg/s bias, its orientation a heading with 1 deg noise;
      ``imu_no_orientation``: the same without an orientation (REP-145);
      ``imu_down``: that one mounted upside down (z down: the yaw rate and
      gravity read negative);
    * ``mag``: sensor_msgs/MagneticField at 20 Hz, a level field of 20 uT
      north and 40 uT down with 0.3 uT noise;
    * ``odom``: wheel odometry at 20 Hz with 2 % errors of distance and turn;
    * ``vo``: a visual odometry at 15 Hz, 1 % errors, in its own frame
      (turned 0.7 rad, started 3 m off); ``odom2``: a second wheel odometry,
      10 Hz, 3 % errors;
    * ``gps``: NavSatFix at 2 Hz, 0.5 m noise;
    * ``filtered``: an odometry/filtered topic (a fused estimate).

    ``faults``: per sensor (``vo``, ``odom``, ``odom2``, ``imu``, ``mag``), an
    interval (s from the start) over which it goes wrong: an odometry's
    heading drifts 0.15 rad/s off (a visual odometry losing track), the
    gyro gains a 2 deg/s bias, the magnetometer's field is bent by 40 deg.
    ``unrelated``: sensors whose streams come from another robot's path
    (the same speeds, other turns). ``heading_offset`` (rad) turns the
    IMU's orientation heading and the magnetometer's (a sensor mounted
    turned). ``t`` starts at ``t0``."""
    from validation.base.geometry import geodetic_from_enu

    rng = np.random.default_rng(seed)
    faults = faults or {}
    dt = 0.01
    t = np.arange(0.0, duration_s, dt)

    def path(turns) -> tuple[np.ndarray, ...]:
        rate = np.zeros_like(t)
        for start, end, r in turns:
            rate[(t >= start) & (t < end)] = r
        speed = 1.0 + 0.4 * np.sin(2 * np.pi * t / 37.0)
        speed[t < 3.0] = t[t < 3.0] / 3.0
        yaw = np.concatenate([[0.3], 0.3 + np.cumsum(rate[:-1] * dt)])
        x = np.concatenate([[0.0], np.cumsum(speed[:-1] * np.cos(yaw[:-1]) * dt)])
        y = np.concatenate([[0.0], np.cumsum(speed[:-1] * np.sin(yaw[:-1]) * dt)])
        return rate, speed, yaw, x, y

    turns = [(s, s + 6, r) for s, r in zip(np.arange(8.0, duration_s - 8, 14.0), (0.3, -0.4, 0.5, -0.25, 0.35, -0.5))]
    own = path(turns)
    other = path([(s + 5, e + 5, -r) for s, e, r in turns])

    def truth(sensor: str):
        return other if sensor in unrelated else own

    def inside(sensor: str) -> np.ndarray:
        a, b = faults.get(sensor, (np.inf, np.inf))
        return (t >= a) & (t < b)

    def odometry(sensor: str, err: float, frame_yaw: float = 0.0, start: tuple[float, float] = (0.0, 0.0)):
        rate, speed, _, _, _ = truth(sensor)
        drift = np.where(inside(sensor), 0.15, 0.0)
        # A scale error of its own (a wheel's radius), and noise on every step.
        w = (1.0 + err) * rate + drift + err * rng.standard_normal(len(t))
        yaw = frame_yaw + np.concatenate([[0.0], np.cumsum(w[:-1] * dt)])
        v = (1.0 - err) * speed * (1.0 + 2.0 * err * rng.standard_normal(len(t)))
        x = start[0] + np.concatenate([[0.0], np.cumsum(v[:-1] * np.cos(yaw[:-1]) * dt)])
        y = start[1] + np.concatenate([[0.0], np.cumsum(v[:-1] * np.sin(yaw[:-1]) * dt)])
        return x, y, yaw

    bag = BagBuilder(ros)
    for sensor in sensors:
        every = {"imu": 2, "imu_no_orientation": 2, "imu_down": 2, "mag": 5, "odom": 5, "vo": 7, "odom2": 10, "gps": 50,
                 "filtered": 5}[sensor]
        idx = np.arange(0, len(t), every)
        rate, _, yaw, x, y = truth(sensor)
        if sensor in ("imu", "imu_no_orientation", "imu_down"):
            bias = np.radians(0.05) + np.where(inside("imu"), np.radians(2.0), 0.0)
            heading = yaw + heading_offset + np.radians(1.0) * rng.standard_normal(len(t))
            # Mounted upside down: z points down, the yaw rate reads negative, gravity on -z.
            sign = -1.0 if sensor == "imu_down" else 1.0
            for k in idx:
                w = rate[k] + bias[k] + np.radians(0.2) * rng.standard_normal()
                bag.imu(SENSOR_TOPICS["imu"], t0 + t[k], rate_z=sign * w, yaw=heading[k],
                        has_orientation=sensor == "imu", gravity=(0.0, 0.0, sign * 9.81))
        elif sensor == "mag":
            bent = yaw + heading_offset + np.where(inside("mag"), np.radians(40.0), 0.0)
            for k in idx:
                north = np.pi / 2 - bent[k]
                noise = 0.3e-6 * rng.standard_normal(3)
                bag.mag(SENSOR_TOPICS["mag"], t0 + t[k], (20e-6 * np.cos(north) + noise[0],
                                                        20e-6 * np.sin(north) + noise[1], -40e-6 + noise[2]))
        elif sensor in ("odom", "vo", "odom2", "filtered"):
            err = {"odom": 0.02, "vo": 0.01, "odom2": 0.03, "filtered": 0.005}[sensor]
            frame = (0.7, (3.0, -1.0)) if sensor == "vo" else (0.3, (0.0, 0.0))
            ox, oy, oyaw = odometry(sensor, err, *frame)
            for k in idx:
                bag.odom(SENSOR_TOPICS[sensor], t0 + t[k], ox[k], oy[k], oyaw[k])
        elif sensor == "gps":
            for k in idx:
                lat, lon = geodetic_from_enu(x[k] + rng.normal(0, 0.5), y[k] + rng.normal(0, 0.5), *datum)
                bag.fix(SENSOR_TOPICS["gps"], t0 + t[k], float(lat), float(lon), variance_m2=(0.25, 0.25))
        else:
            raise ValueError(f"unknown sensor {sensor!r}")
    return bag
