"""Reader for recorded runs in ROS 1 bags and ROS 2 bags (sqlite3 or mcap).

Both are read through ``rosbags.highlevel.AnyReader``. Only the topics named
in :class:`slam.config.TopicsConfig` are read; each message is deserialised
once even when two streams share a topic (gyro and compass from one Imu).
In ROS 2 bags, topics whose messages share one layout are decoded in bulk,
a chunk of messages at a time (:mod:`slam.io.cdr`); other topics, and ROS 1
bags, message by message through rosbags. Both give the same streams.

Message -> stream mapping (all times are header stamps):

* ``scan``: sensor_msgs/LaserScan -> :class:`Scans`, ranges as published.
* ``gyro``: sensor_msgs/Imu -> :class:`Gyro`, ``angular_velocity.z`` or the
  world-vertical component of the angular velocity (``input.gyro.axis``).
* ``compass``: sensor_msgs/MagneticField or the orientation of a
  sensor_msgs/Imu -> :class:`Compass` (sign conventions in
  :class:`_CompassMagStream` and :class:`_CompassImuStream`).
* ``odometry``, ``groundtruth``: nav_msgs/Odometry (ground truth may also be
  geometry_msgs/PoseStamped) -> :class:`Trajectory` from the planar pose.
* ``gps``: sensor_msgs/NavSatFix -> :class:`Gps` in metres about a datum.

Bad input raises :class:`GslamError` with one line naming the bag and topic.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from slam.config import CompassInputConfig, GpsInputConfig, GyroInputConfig, InputConfig
from slam.errors import GslamError
from slam.geometry import (
    enu_from_geodetic,
    heading_from_magnetometer,
    wrap_angle,
    yaw_from_quaternion,
)
from slam.io import cdr
from slam.recording import Compass, Gps, Gyro, Recording, Scans, Trajectory

log = logging.getLogger(__name__)

BAG_SUFFIXES = (".bag", ".db3", ".mcap")

LASER_SCAN = "sensor_msgs/msg/LaserScan"
IMU = "sensor_msgs/msg/Imu"
MAGNETIC_FIELD = "sensor_msgs/msg/MagneticField"
ODOMETRY = "nav_msgs/msg/Odometry"
POSE_STAMPED = "geometry_msgs/msg/PoseStamped"
NAV_SAT_FIX = "sensor_msgs/msg/NavSatFix"

_NS = 1_000_000_000
BULK_CHUNK = 8192
"""Messages of one topic decoded together: bounds the raw bytes held."""


def _first_line(err: BaseException) -> str:
    text = str(err).strip().splitlines()
    return text[0] if text else type(err).__name__


# --- streams: one per configured topic ---------------------------------------


class _Stream:
    """Collects one stream from the messages of one topic.

    ``add`` takes a deserialised message, ``add_columns`` the same fields of
    a chunk of messages decoded in bulk (:func:`slam.io.cdr.decode_columns`;
    a stream gets one or the other, never both); ``finish`` turns them into
    arrays and checks them; ``build`` returns the :mod:`slam.recording`
    object with times relative to ``t0_ns``.
    """

    msgtypes: tuple[str, ...] = ()

    def __init__(self, name: str, topic: str, bag: Path) -> None:
        self.name = name
        self.topic = topic
        self.where = f"{bag}: {name} topic '{topic}'"
        self.msgtype = self.msgtypes[0]
        self.stamps: list[int] = []
        self.blocks: list[dict[str, np.ndarray]] = []
        self.n_bulk = 0  # messages received through add_columns
        self.ns = np.zeros(0, dtype=np.int64)

    def add(self, msg: Any) -> None:
        raise NotImplementedError

    def bulk_fields(self) -> tuple[str, ...]:
        """Fields ``add_columns`` needs (names of :mod:`slam.io.cdr`)."""
        raise NotImplementedError

    def add_columns(self, cols: dict[str, np.ndarray]) -> None:
        n = len(cols["stamp_ns"])
        self.check_columns(cols, self.n_bulk)
        self.blocks.append(cols)
        self.n_bulk += n

    def check_columns(self, cols: dict[str, np.ndarray], offset: int) -> None:
        """The checks :meth:`add` makes, for messages ``offset``, ``offset + 1``, ..."""

    def reset_columns(self) -> None:
        """Forget what ``add_columns`` got (the topic is read again one by one)."""
        self.blocks, self.n_bulk = [], 0

    def columns(self) -> dict[str, np.ndarray] | None:
        """The bulk-decoded fields of every message (merged into one block
        once), or None if the stream was read message by message."""
        if not self.blocks:
            return None
        if len(self.blocks) > 1:
            self.blocks = [{k: np.concatenate([b[k] for b in self.blocks]) for k in self.blocks[0]}]
        return self.blocks[0]

    def finish(self) -> None:
        """Check the stamps are strictly increasing; subclasses check values."""
        cols = self.columns()
        self.ns = cols["stamp_ns"] if cols is not None else np.asarray(self.stamps, dtype=np.int64)
        steps = np.diff(self.ns)
        bad = np.flatnonzero(steps <= 0)
        if bad.size:
            i = int(bad[0]) + 1
            kind = "duplicate" if steps[bad[0]] == 0 else "decreasing"
            raise GslamError(
                f"{self.where}: {kind} header stamp at message {i} "
                f"(t = {self.ns[i] / _NS:.9f} s, previous {self.ns[i - 1] / _NS:.9f} s)"
            )

    def _finite(self, field: str, values: np.ndarray) -> None:
        if values.size == 0:
            return
        ok = np.isfinite(values).reshape(len(values), -1).all(axis=1)
        if not ok.all():
            i = int(np.flatnonzero(~ok)[0])
            raise GslamError(f"{self.where}: non-finite {field} at message {i}")

    def first_ns(self) -> int | None:
        return int(self.ns[0]) if len(self.ns) else None

    def t(self, t0_ns: int) -> np.ndarray:
        return (self.ns - t0_ns).astype(np.float64) / _NS

    def build(self, t0_ns: int) -> Any:
        raise NotImplementedError


def _stamp(msg: Any) -> int:
    stamp = msg.header.stamp
    return stamp.sec * _NS + stamp.nanosec


class _ScanStream(_Stream):
    """LaserScan; beam count and angles must not change within the stream."""

    msgtypes = (LASER_SCAN,)

    def __init__(self, name: str, topic: str, bag: Path) -> None:
        super().__init__(name, topic, bag)
        self.ranges: list[np.ndarray] = []
        self.block: np.ndarray | None = None  # (n, beams) when decoded in bulk
        self.first: Any = None

    def add(self, msg: Any) -> None:
        if self.first is None:
            self.first = msg
        first = self.first
        if len(msg.ranges) != len(first.ranges):
            raise GslamError(
                f"{self.where}: message {len(self.stamps)} has {len(msg.ranges)} beams, "
                f"the first had {len(first.ranges)}"
            )
        elif (msg.angle_min, msg.angle_increment) != (first.angle_min, first.angle_increment):
            raise GslamError(f"{self.where}: beam angles change at message {len(self.stamps)}")
        self.stamps.append(_stamp(msg))
        self.ranges.append(msg.ranges)

    def bulk_fields(self) -> tuple[str, ...]:
        return ("angle_min", "angle_increment", "range_min", "range_max", "ranges")

    def reset_columns(self) -> None:
        super().reset_columns()
        self.first = None

    def check_columns(self, cols: dict[str, np.ndarray], offset: int) -> None:
        if self.first is None:
            head = (float(cols[k][0]) for k in ("angle_min", "angle_increment", "range_min", "range_max"))
            self.first = _ScanHead(*head, cols["ranges"].shape[1])
        first = self.first
        beams = cols["ranges"].shape[1]  # one per chunk: its messages share one layout
        if beams != first.beams:
            raise GslamError(f"{self.where}: message {offset} has {beams} beams, the first had {first.beams}")
        # As in add(): a NaN angle differs from everything, but message 0 is the reference.
        differs = (cols["angle_min"] != first.angle_min) | (cols["angle_increment"] != first.angle_increment)
        if offset == 0:
            differs[0] = False
        if differs.any():
            raise GslamError(f"{self.where}: beam angles change at message {offset + int(np.argmax(differs))}")

    def finish(self) -> None:
        super().finish()
        cols = self.columns()
        if cols is not None:
            self.block = cols["ranges"]
            self.blocks = []  # the block is the only copy kept
        first = self.first
        angles = np.array([[first.angle_min, first.angle_increment]])
        self._finite("angle_min/angle_increment", angles)

    def build(self, t0_ns: int) -> Scans:
        first = self.first
        beams = np.arange(len(first.ranges), dtype=np.float64)
        ranges = self.block if self.block is not None else np.stack(self.ranges)
        return Scans(
            t=self.t(t0_ns),
            ranges=np.asarray(ranges, dtype=np.float32),
            angles=float(first.angle_min) + beams * float(first.angle_increment),
            range_min=float(first.range_min),
            range_max=float(first.range_max),
        )


@dataclass(frozen=True)
class _ScanHead:
    """The fields of a first LaserScan that :class:`_ScanStream` keeps."""

    angle_min: float
    angle_increment: float
    range_min: float
    range_max: float
    beams: int

    @property
    def ranges(self) -> range:  # only its length is used
        return range(self.beams)


class _GyroStream(_Stream):
    """Imu -> yaw rate (rad/s).

    ``axis: z`` takes ``angular_velocity.z`` (body z up). ``axis: world_z``
    rotates the body-frame angular velocity into the world frame with the
    message's orientation quaternion (body-to-world) and takes its z
    component, the yaw rate of an IMU mounted tilted or rolled. A message
    without orientation (``orientation_covariance[0]`` = -1) is then an error.
    """

    msgtypes = (IMU,)

    def __init__(self, name: str, topic: str, bag: Path, config: GyroInputConfig) -> None:
        super().__init__(name, topic, bag)
        self.world = config.axis == "world_z"
        self.rates: list[tuple[float, ...]] = []

    def add(self, msg: Any) -> None:
        w = msg.angular_velocity
        if self.world:
            if msg.orientation_covariance[0] == -1.0:
                raise GslamError(
                    f"{self.where}: message {len(self.stamps)} has no orientation "
                    "(orientation_covariance[0] = -1); gyro axis world_z needs one, use axis z"
                )
            q = msg.orientation
            self.rates.append((w.x, w.y, w.z, q.x, q.y, q.z, q.w))
        else:
            self.rates.append((w.z,))
        self.stamps.append(_stamp(msg))

    def bulk_fields(self) -> tuple[str, ...]:
        return ("angular_velocity", "orientation", "orientation_covariance") if self.world else ("angular_velocity",)

    def check_columns(self, cols: dict[str, np.ndarray], offset: int) -> None:
        if self.world:
            _no_orientation(self.where, cols, offset, "gyro axis world_z needs one, use axis z")

    def finish(self) -> None:
        super().finish()
        cols = self.columns()
        if cols is None:
            rows = np.asarray(self.rates, dtype=np.float64).reshape(len(self.rates), -1)
        elif self.world:
            rows = np.column_stack([cols["angular_velocity"], cols["orientation"]])
        else:
            rows = cols["angular_velocity"][:, 2:3]
        self.blocks = []
        if self.world:
            self._finite("angular_velocity/orientation", rows)
            self.rate = world_yaw_rate(rows[:, :3], rows[:, 3:])
        else:
            self.rate = rows[:, 0] if rows.size else np.zeros(0)
            self._finite("angular_velocity.z", self.rate)

    def build(self, t0_ns: int) -> Gyro:
        return Gyro(t=self.t(t0_ns), rate=self.rate)


def _no_orientation(where: str, cols: dict[str, np.ndarray], offset: int, hint: str) -> None:
    """Raise for the first message without orientation (covariance[0] = -1);
    the chunk ``cols`` starts at message ``offset``."""
    missing = np.flatnonzero(cols["orientation_covariance"][:, 0] == -1.0)
    if missing.size:
        raise GslamError(
            f"{where}: message {offset + int(missing[0])} has no orientation "
            f"(orientation_covariance[0] = -1); {hint}"
        )


def world_yaw_rate(omega: np.ndarray, quat_xyzw: np.ndarray) -> np.ndarray:
    """The world-z component (rad/s) of body-frame angular velocities
    ``omega`` (n, 3) for body-to-world orientations ``quat_xyzw`` (n, 4,
    normalised here): the third row of the rotation matrix times omega."""
    q = quat_xyzw / np.linalg.norm(quat_xyzw, axis=1, keepdims=True)
    x, y, z, w = q.T
    row = np.column_stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)])
    return np.einsum("ij,ij->i", row, omega)


class _CompassMagStream(_Stream):
    """MagneticField -> heading of a level robot.

    The field is measured in the sensor frame, whose yaw in the robot frame
    is ``mounting_yaw_deg`` (CCW positive). The sensor's world yaw follows
    from :func:`heading_from_magnetometer` (declination east positive), and
    the robot's yaw is the sensor's minus the mounting yaw:
    ``yaw = wrap(heading_from_magnetometer(field, declination) - mounting)``.
    ``field`` is kept in the sensor frame, tesla.
    """

    msgtypes = (MAGNETIC_FIELD,)

    def __init__(self, name: str, topic: str, bag: Path, config: CompassInputConfig) -> None:
        super().__init__(name, topic, bag)
        self.declination = np.radians(config.declination_deg)
        self.mounting = np.radians(config.mounting_yaw_deg)
        self.fields: list[tuple[float, float, float]] = []

    def add(self, msg: Any) -> None:
        self.stamps.append(_stamp(msg))
        m = msg.magnetic_field
        self.fields.append((m.x, m.y, m.z))

    def bulk_fields(self) -> tuple[str, ...]:
        return ("magnetic_field",)

    def finish(self) -> None:
        super().finish()
        cols = self.columns()
        field = self.fields if cols is None else cols["magnetic_field"]
        self.field = np.asarray(field, dtype=np.float64).reshape(-1, 3)
        self.blocks = []
        self._finite("magnetic_field", self.field)

    def build(self, t0_ns: int) -> Compass:
        yaw = wrap_angle(heading_from_magnetometer(self.field, self.declination) - self.mounting)
        return Compass(t=self.t(t0_ns), yaw=yaw, field=self.field)


class _CompassImuStream(_Stream):
    """Imu orientation -> heading.

    The orientation is taken as the sensor frame's rotation from an ENU
    frame whose north is *magnetic* north (what a magnetometer-aided AHRS
    reports). Magnetic north lies ``declination`` east of true north, i.e.
    at world yaw ``pi/2 - declination``, so the true yaw of the sensor is its
    reported yaw minus the declination (the same sign as in
    :func:`heading_from_magnetometer`); the robot's yaw is the sensor's minus
    the mounting yaw: ``yaw = wrap(yaw(q) - declination - mounting)``. For an
    IMU that already reports true-north yaw, set the declination to 0.
    A message whose ``orientation_covariance[0]`` is -1 has no orientation
    (REP-145) and is an error.
    """

    msgtypes = (IMU,)

    def __init__(self, name: str, topic: str, bag: Path, config: CompassInputConfig) -> None:
        super().__init__(name, topic, bag)
        self.offset = np.radians(config.declination_deg + config.mounting_yaw_deg)
        self.quats: list[tuple[float, float, float, float]] = []

    def add(self, msg: Any) -> None:
        if msg.orientation_covariance[0] == -1.0:
            raise GslamError(
                f"{self.where}: message {len(self.stamps)} has no orientation "
                "(orientation_covariance[0] = -1); use compass source magnetic_field"
            )
        self.stamps.append(_stamp(msg))
        q = msg.orientation
        self.quats.append((q.x, q.y, q.z, q.w))

    def bulk_fields(self) -> tuple[str, ...]:
        return ("orientation", "orientation_covariance")

    def check_columns(self, cols: dict[str, np.ndarray], offset: int) -> None:
        _no_orientation(self.where, cols, offset, "use compass source magnetic_field")

    def finish(self) -> None:
        super().finish()
        cols = self.columns()
        self.quat = np.asarray(self.quats if cols is None else cols["orientation"], dtype=np.float64).reshape(-1, 4)
        self.blocks = []
        self._finite("orientation", self.quat)

    def build(self, t0_ns: int) -> Compass:
        q = self.quat
        yaw = wrap_angle(yaw_from_quaternion(q[:, 0], q[:, 1], q[:, 2], q[:, 3]) - self.offset)
        return Compass(t=self.t(t0_ns), yaw=yaw, field=None)


class _PoseStream(_Stream):
    """Odometry (or PoseStamped) -> planar pose x, y (m), yaw (rad)."""

    msgtypes = (ODOMETRY,)

    def __init__(
        self, name: str, topic: str, bag: Path, msgtypes: tuple[str, ...] = (ODOMETRY,)
    ) -> None:
        self.msgtypes = msgtypes
        super().__init__(name, topic, bag)
        self.poses: list[tuple[float, ...]] = []

    def add(self, msg: Any) -> None:
        self.stamps.append(_stamp(msg))
        pose = msg.pose.pose if self.msgtype == ODOMETRY else msg.pose
        p, q = pose.position, pose.orientation
        self.poses.append((p.x, p.y, q.x, q.y, q.z, q.w))

    def bulk_fields(self) -> tuple[str, ...]:
        return ("position", "orientation")

    def finish(self) -> None:
        super().finish()
        cols = self.columns()
        if cols is None:
            self.pose = np.asarray(self.poses, dtype=np.float64).reshape(-1, 6)
        else:
            self.pose = np.column_stack([cols["position"][:, :2], cols["orientation"]]).astype(np.float64)
        self.blocks = []
        self._finite("pose.position", self.pose[:, :2])
        self._finite("pose.orientation", self.pose[:, 2:])

    def build(self, t0_ns: int) -> Trajectory:
        p = self.pose
        yaw = wrap_angle(yaw_from_quaternion(p[:, 2], p[:, 3], p[:, 4], p[:, 5]))
        x, y = p[:, 0].copy(), p[:, 1].copy()
        return Trajectory(t=self.t(t0_ns), x=x, y=y, yaw=np.asarray(yaw))


class _GpsStream(_Stream):
    """NavSatFix -> east/north (m) about the datum, horizontal sigma (m).

    Fixes with status < 0 (NO_FIX) or a NaN latitude/longitude are dropped
    and counted. ``sigma = sqrt((cov[0] + cov[4]) / 2)``, the RMS of the east
    and north standard deviations; a fix whose covariance type is 0
    (unknown) gets sigma NaN, which the back-end replaces by its floor.
    The datum is the configured one, else the first kept fix.
    """

    msgtypes = (NAV_SAT_FIX,)

    def __init__(self, name: str, topic: str, bag: Path, config: GpsInputConfig) -> None:
        super().__init__(name, topic, bag)
        if (config.datum_lat_deg is None) != (config.datum_lon_deg is None):
            raise GslamError("input.gps: set both datum_lat_deg and datum_lon_deg, or neither")
        self.datum = config.datum_lat_deg, config.datum_lon_deg
        self.rows: list[tuple[float, ...]] = []
        self.dropped = 0

    def add(self, msg: Any) -> None:
        status = msg.status.status
        lat, lon = msg.latitude, msg.longitude
        if status < 0 or lat != lat or lon != lon:  # x != x only for NaN
            self.dropped += 1
            return
        self.stamps.append(_stamp(msg))
        cov = msg.position_covariance
        self.rows.append((lat, lon, cov[0], cov[4], msg.position_covariance_type, status))

    def bulk_fields(self) -> tuple[str, ...]:
        return ("status", "latitude", "longitude", "position_covariance", "position_covariance_type")

    def add_columns(self, cols: dict[str, np.ndarray]) -> None:
        """Fixes without a position are dropped here, as in :meth:`add`."""
        lat, lon = cols["latitude"], cols["longitude"]
        keep = (cols["status"] >= 0) & ~np.isnan(lat) & ~np.isnan(lon)
        cov = cols["position_covariance"][keep]
        rows = np.column_stack([lat[keep], lon[keep], cov[:, 0], cov[:, 4], cols["position_covariance_type"][keep],
                                cols["status"][keep]]).astype(np.float64)
        dropped = np.array([np.count_nonzero(~keep)])
        super().add_columns({"stamp_ns": cols["stamp_ns"][keep], "rows": rows, "dropped": dropped})

    def finish(self) -> None:
        super().finish()
        cols = self.columns()
        rows = np.asarray(self.rows if cols is None else cols["rows"], dtype=np.float64).reshape(-1, 6)
        if cols is not None:
            self.dropped = int(cols["dropped"].sum())
        self.blocks = []
        self._finite("latitude/longitude", rows[:, :2])
        known = rows[:, 4] != 0
        with np.errstate(invalid="ignore"):
            sigma = np.sqrt(0.5 * (rows[:, 2] + rows[:, 3]))
        self._finite("position_covariance (negative or non-finite variance)", sigma[known])
        sigma[~known] = np.nan
        self.rows, self.sigma = rows, sigma
        if self.dropped:
            log.info("%s: dropped %d fixes without a position", self.where, self.dropped)

    def build(self, t0_ns: int) -> Gps | None:
        rows = self.rows
        if not len(rows):
            log.warning("%s: no fix with a position; reading without GPS", self.where)
            return None
        lat0, lon0 = self.datum
        if lat0 is None:
            lat0, lon0 = float(rows[0, 0]), float(rows[0, 1])
        east, north = enu_from_geodetic(rows[:, 0], rows[:, 1], lat0, lon0)
        return Gps(
            t=self.t(t0_ns),
            x=np.asarray(east, dtype=np.float64),
            y=np.asarray(north, dtype=np.float64),
            sigma=self.sigma,
            status=rows[:, 5].astype(np.int64),
        )


# --- reading ----------------------------------------------------------------


def is_rosbag(path: Path) -> bool:
    """True for a ROS 1 ``.bag``, a ``.db3``/``.mcap`` file or a rosbag2
    directory (one holding ``metadata.yaml``)."""
    if path.is_dir():
        return (path / "metadata.yaml").is_file()
    return path.suffix in BAG_SUFFIXES


def resolve_bag_path(path: Path) -> Path:
    """The path to hand to rosbags: ``path`` itself, or the single bag file in
    a directory that is not a rosbag2 directory (as a run folder's ``bag/``
    may be)."""
    if not path.exists():
        raise GslamError(f"{path}: no such file or directory")
    if not path.is_dir() or (path / "metadata.yaml").is_file():
        return path
    inside = sorted(p for p in path.iterdir() if p.suffix in BAG_SUFFIXES)
    if len(inside) != 1:
        raise GslamError(
            f"{path}: expected a rosbag2 directory (metadata.yaml) or exactly one "
            f".bag/.db3/.mcap file, found {len(inside)}"
        )
    return inside[0]


def _make_streams(path: Path, config: InputConfig) -> list[_Stream]:
    topics, compass = config.topics, config.compass
    streams: list[_Stream] = []
    if topics.scan is not None:
        streams.append(_ScanStream("scan", topics.scan, path))
    if topics.gyro is not None:
        streams.append(_GyroStream("gyro", topics.gyro, path, config.gyro))
    if topics.compass is not None:
        cls = _CompassMagStream if compass.source == "magnetic_field" else _CompassImuStream
        streams.append(cls("compass", topics.compass, path, compass))
    if topics.odometry is not None:
        streams.append(_PoseStream("odometry", topics.odometry, path))
    if topics.gps is not None:
        streams.append(_GpsStream("gps", topics.gps, path, config.gps))
    if topics.groundtruth is not None:
        gt_types = (ODOMETRY, POSE_STAMPED)
        streams.append(_PoseStream("groundtruth", topics.groundtruth, path, gt_types))
    return streams


def _open_reader(path: Path) -> Any:
    try:
        from rosbags.highlevel import AnyReader
        from rosbags.typesys import Stores, get_typestore
    except ImportError:
        raise GslamError("reading ROS bags needs 'rosbags': pip install rosbags") from None
    # Bags without embedded definitions (old rosbag2 sqlite files) need one.
    store = get_typestore(Stores.ROS1_NOETIC if path.suffix == ".bag" else Stores.LATEST)
    try:
        reader = AnyReader([path], default_typestore=store)
        reader.open()
    except Exception as err:  # rosbags raises many types for foreign or broken files
        raise GslamError(f"{path}: not a readable ROS bag ({_first_line(err)})") from None
    return reader


def _connections(reader: Any, path: Path, streams: list[_Stream]) -> dict[str, list[Any]]:
    """The bag's connections per needed topic; drops absent optional streams."""
    by_topic: dict[str, list[Any]] = {}
    for conn in reader.connections:
        by_topic.setdefault(conn.topic, []).append(conn)
    wanted: dict[str, list[Any]] = {}
    for stream in list(streams):
        conns = by_topic.get(stream.topic)
        if not conns:
            if stream.name == "groundtruth":
                log.warning("%s: not in the bag; reading without ground truth", stream.where)
                streams.remove(stream)
                continue
            existing = ", ".join(sorted(by_topic)) or "none"
            raise GslamError(f"{stream.where}: not in the bag (topics: {existing})")
        found = sorted({c.msgtype for c in conns})
        if len(found) > 1 or found[0] not in stream.msgtypes:
            raise GslamError(
                f"{stream.where}: type is {' and '.join(found)}, "
                f"expected {' or '.join(stream.msgtypes)}"
            )
        stream.msgtype = found[0]
        wanted[stream.topic] = conns
    return wanted


def _read_messages(
    reader: Any, path: Path, streams: list[_Stream], wanted: dict[str, list[Any]]
) -> dict[str, int]:
    """Feed every message of the wanted connections to its streams; return
    the number of messages per topic.

    In a ROS 2 bag, the raw messages of a topic whose type :mod:`slam.io.cdr`
    knows are held back and decoded in bulk, ``BULK_CHUNK`` at a time. If a
    chunk does not decode in bulk (the layout changes), that topic is read
    again message by message after the others.
    """
    by_topic: dict[str, list[_Stream]] = {}
    for stream in streams:
        by_topic.setdefault(stream.topic, []).append(stream)
    counts = dict.fromkeys(by_topic, 0)
    conns = [c for cs in wanted.values() for c in cs]
    if not conns:  # rosbags reads every connection when given none
        return counts
    ros2 = getattr(reader, "is2", False)  # ROS 1 messages are not CDR
    bulk = {topic: [] for topic, group in by_topic.items() if ros2 and cdr.supported(group[0].msgtype)}
    fallback: set[str] = set()

    def decode(topic: str) -> None:
        pending = bulk[topic]
        group = by_topic[topic]
        fields = sorted({f for s in group for f in s.bulk_fields()})
        msgtype = group[0].msgtype
        cols = cdr.decode_columns(msgtype, pending, fields) if topic not in fallback else None
        # One message per chunk through rosbags: the layout must be the bag's.
        if cols is not None and not cdr.agrees(_deserialize(reader, path, pending[-1], msgtype), cols, -1):
            cols = None
        if cols is None:
            fallback.add(topic)
            for s in group:
                s.reset_columns()
        else:
            for s in group:
                s.add_columns(cols)
        pending.clear()

    for topic, conn, raw in _raw_messages(reader, path, conns):
        counts[topic] += 1
        pending = bulk.get(topic)
        if pending is None:
            msg = _deserialize(reader, path, raw, conn.msgtype)
            for stream in by_topic[topic]:
                stream.add(msg)
        elif topic not in fallback:
            pending.append(raw)
            if len(pending) >= BULK_CHUNK:
                decode(topic)
    for topic, pending in bulk.items():
        if pending and topic not in fallback:
            decode(topic)
    if fallback:
        log.info("%s: topics %s read message by message", path, ", ".join(sorted(fallback)))
        again = [c for t in fallback for c in wanted[t]]
        for topic, conn, raw in _raw_messages(reader, path, again):
            msg = _deserialize(reader, path, raw, conn.msgtype)
            for stream in by_topic[topic]:
                stream.add(msg)
    return counts


def _raw_messages(reader: Any, path: Path, conns: list[Any]):
    """(topic, connection, raw bytes) of every message on ``conns``."""
    messages = reader.messages(connections=conns)
    while True:
        # Corrupt chunks surface as assorted exception types from rosbags,
        # lz4, sqlite3 or struct while iterating; all mean "broken file".
        try:
            conn, _, raw = next(messages)
        except StopIteration:
            return
        except Exception as err:
            raise GslamError(f"{path}: corrupt bag ({_first_line(err)})") from None
        yield conn.topic, conn, raw


def _deserialize(reader: Any, path: Path, raw: bytes, msgtype: str) -> Any:
    try:
        return reader.deserialize(raw, msgtype)
    except Exception as err:
        raise GslamError(f"{path}: corrupt bag ({_first_line(err)})") from None


def read_rosbag(path: str | Path, config: InputConfig) -> Recording:
    """Read one recorded run from a ROS 1 or ROS 2 bag.

    ``path``: a ``.bag`` file, a rosbag2 directory, a ``.db3``/``.mcap``
    file, or a directory holding exactly one bag file. ``Recording.t0`` is
    the earliest first header stamp over the streams read (absolute s); each
    stream's ``t`` is relative to it. ``Recording.name`` is the file stem or
    directory name.
    """
    path = resolve_bag_path(Path(path))
    streams = _make_streams(path, config)
    reader = _open_reader(path)
    try:
        wanted = _connections(reader, path, streams)
        counts = _read_messages(reader, path, streams, wanted)
    finally:
        reader.close()

    for stream in streams:
        if counts[stream.topic] == 0:
            raise GslamError(f"{stream.where}: no messages")
        stream.finish()
    firsts = [s.first_ns() for s in streams if s.first_ns() is not None]
    t0_ns = min(firsts) if firsts else 0
    built = {s.name: s.build(t0_ns) for s in streams}
    rec = Recording(
        name=path.stem if path.is_file() else path.name,
        t0=t0_ns / _NS,
        scans=built.get("scan"),
        gyro=built.get("gyro"),
        compass=built.get("compass"),
        odometry=built.get("odometry"),
        gps=built.get("gps"),
        groundtruth=built.get("groundtruth"),
    )
    log.info(
        "%s: read %s over %.1f s",
        path,
        ", ".join(f"{len(s.ns)} {s.name}" for s in streams),
        rec.duration,
    )
    return rec


class RosbagReader:
    """The ``rosbag`` format of :mod:`slam.io.readers`."""

    def read(self, path: Path, config: InputConfig) -> Recording:
        """See :func:`read_rosbag`."""
        return read_rosbag(path, config)
