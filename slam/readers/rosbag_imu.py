"""The gyro and compass streams of the ROS bag reader (:mod:`slam.readers.rosbag`).

* gyro: sensor_msgs/Imu -> :class:`Gyro`, ``angular_velocity.z`` or the
  world-vertical component of the angular velocity (``input.gyro.axis``,
  :func:`world_yaw_rate`).
* compass: sensor_msgs/MagneticField (:class:`_CompassMagStream`) or the
  orientation of a sensor_msgs/Imu (:class:`_CompassImuStream`) ->
  :class:`Compass`; the sign conventions are in those classes.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from slam.config import CompassInputConfig, GyroInputConfig, StreamFrameConfig
from slam.errors import GslamError
from validation.base.geometry import heading_from_magnetometer, wrap_angle, yaw_from_quaternion
from slam.readers import frames
from slam.readers.rosbag_streams import IMU, MAGNETIC_FIELD, _Stream
from slam.recording import Compass, Gyro


class _GyroStream(_Stream):
    """Imu -> yaw rate (rad/s).

    ``axis: z`` takes ``angular_velocity.z`` (body z up). ``axis: world_z``
    rotates the body-frame angular velocity into the world frame with the
    message's orientation quaternion (body-to-world) and takes its z
    component, the yaw rate of an IMU mounted tilted or rolled. A message
    without orientation (``orientation_covariance[0]`` = -1) is then an error.
    """

    msgtypes = (IMU,)

    def __init__(
        self, name: str, topic: str, bag: Path, config: GyroInputConfig, frame: StreamFrameConfig = StreamFrameConfig()
    ) -> None:
        super().__init__(name, topic, bag)
        self.world = config.axis == "world_z"
        self.axis = "xyz".index(config.axis) if not self.world else 2
        self.frame = frame
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
            self.rates.append(((w.x, w.y, w.z)[self.axis],))
        self.add_stamp(msg)

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
            rows = cols["angular_velocity"][:, self.axis : self.axis + 1]
        self.blocks = []
        if self.world:
            self._finite("angular_velocity/orientation", rows)
            self._rotations("orientation", rows[:, 3:])
            self.rate = world_yaw_rate(rows[:, :3], rows[:, 3:])
        else:
            self.rate = rows[:, 0] if rows.size else np.zeros(0)
            self._finite(f"angular_velocity.{'xyz'[self.axis]}", self.rate)

    def build(self, t0_ns: int) -> Gyro:
        rate = frames.yaw_rate(self.rate, self.frame, "world" if self.world else "body")
        return Gyro(t=self.t(t0_ns), rate=rate)


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

    def __init__(
        self, name: str, topic: str, bag: Path, config: CompassInputConfig, frame: StreamFrameConfig = StreamFrameConfig()
    ) -> None:
        super().__init__(name, topic, bag)
        self.declination = np.radians(config.declination_deg)
        self.mounting = np.radians(config.mounting_yaw_deg)
        self.frame = frame
        self.fields: list[tuple[float, float, float]] = []

    def add(self, msg: Any) -> None:
        self.add_stamp(msg)
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
        field = frames.body_vector(self.field, self.frame)
        yaw = heading_from_magnetometer(field, self.declination)
        if self.frame.yaw_sign == -1:  # mirrored about east, as frames.heading does
            yaw = -yaw
        return Compass(t=self.t(t0_ns), yaw=wrap_angle(yaw - self.mounting), field=field)


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

    def __init__(
        self, name: str, topic: str, bag: Path, config: CompassInputConfig, frame: StreamFrameConfig = StreamFrameConfig()
    ) -> None:
        super().__init__(name, topic, bag)
        self.offset = np.radians(config.declination_deg + config.mounting_yaw_deg)
        self.frame = frame
        self.quats: list[tuple[float, float, float, float]] = []

    def add(self, msg: Any) -> None:
        if msg.orientation_covariance[0] == -1.0:
            raise GslamError(
                f"{self.where}: message {len(self.stamps)} has no orientation "
                "(orientation_covariance[0] = -1); use compass source magnetic_field"
            )
        self.add_stamp(msg)
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
        self._rotations("orientation", self.quat)

    def build(self, t0_ns: int) -> Compass:
        q = self.quat
        reported = frames.heading(yaw_from_quaternion(q[:, 0], q[:, 1], q[:, 2], q[:, 3]), self.frame)
        return Compass(t=self.t(t0_ns), yaw=wrap_angle(reported - self.offset), field=None)
