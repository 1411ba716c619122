"""The pose and GPS streams of the ROS bag reader (:mod:`slam.readers.rosbag`).

* odometry, ground truth: nav_msgs/Odometry (ground truth may also be
  geometry_msgs/PoseStamped) -> :class:`Trajectory` from the planar pose.
* GPS: sensor_msgs/NavSatFix -> :class:`Gps` in metres about a datum.
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any

import numpy as np

from slam.config import GpsInputConfig, StreamFrameConfig
from slam.errors import GslamError
from validation.base.geometry import enu_from_geodetic, yaw_from_quaternion
from slam.readers import frames
from slam.readers.rosbag_streams import NAV_SAT_FIX, ODOMETRY, _Stream
from slam.recording import Gps, Trajectory

# The streams are part of the reader: they log under its name, so that one
# logger ("slam.readers.rosbag") shows or hides everything a bag read reports.
log = logging.getLogger("slam.readers.rosbag")


class _PoseStream(_Stream):
    """Odometry (or PoseStamped) -> planar pose x, y (m), yaw (rad)."""

    msgtypes = (ODOMETRY,)

    def __init__(
        self,
        name: str,
        topic: str,
        bag: Path,
        msgtypes: tuple[str, ...] = (ODOMETRY,),
        frame: StreamFrameConfig = StreamFrameConfig(),
    ) -> None:
        self.msgtypes = msgtypes
        super().__init__(name, topic, bag)
        self.frame = frame
        self.poses: list[tuple[float, ...]] = []

    def add(self, msg: Any) -> None:
        self.add_stamp(msg)
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
        self._rotations("pose.orientation", self.pose[:, 2:])

    def build(self, t0_ns: int) -> Trajectory:
        p = self.pose
        yaw = yaw_from_quaternion(p[:, 2], p[:, 3], p[:, 4], p[:, 5])
        x, y, yaw = frames.planar_poses(p[:, 0], p[:, 1], yaw, self.frame)
        return Trajectory(t=self.t(t0_ns), x=x, y=y, yaw=yaw)


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
        self.add_stamp(msg)
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
        super().add_columns({"stamp_ns": cols["stamp_ns"][keep], "nanosec": cols["nanosec"][keep], "rows": rows,
                             "dropped": dropped})

    def finish(self) -> None:
        super().finish()
        cols = self.columns()
        rows = np.asarray(self.rows if cols is None else cols["rows"], dtype=np.float64).reshape(-1, 6)
        if cols is not None:
            self.dropped = int(cols["dropped"].sum())
        self.blocks = []
        self._finite("latitude/longitude", rows[:, :2])
        outside = (np.abs(rows[:, 0]) > 90.0) | (np.abs(rows[:, 1]) > 180.0)
        if outside.any():
            i = int(np.flatnonzero(outside)[0])
            raise GslamError(f"{self.where}: fix {i} at latitude {rows[i, 0]:.9g}, longitude {rows[i, 1]:.9g}: "
                             "expected degrees within +-90 and +-180")
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
