"""The stream base class of the ROS bag reader (:mod:`slam.readers.rosbag`).

The reader makes one stream per configured topic. A stream collects one
:mod:`slam.recording` object from the messages of its topic, either message
by message or a chunk at a time from the bulk CDR decoder
(:mod:`slam.readers.cdr`). The streams themselves are in
:mod:`slam.readers.rosbag_scans` (LaserScan), :mod:`slam.readers.rosbag_imu` (gyro and
compass) and :mod:`slam.readers.rosbag_poses` (odometry, ground truth and GPS).
The message type names they accept are here too.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from slam.errors import GslamError

LASER_SCAN = "sensor_msgs/msg/LaserScan"
IMU = "sensor_msgs/msg/Imu"
MAGNETIC_FIELD = "sensor_msgs/msg/MagneticField"
ODOMETRY = "nav_msgs/msg/Odometry"
POSE_STAMPED = "geometry_msgs/msg/PoseStamped"
NAV_SAT_FIX = "sensor_msgs/msg/NavSatFix"

_NS = 1_000_000_000


class _Stream:
    """Collects one stream from the messages of one topic.

    ``add`` takes a deserialised message, ``add_columns`` the same fields of
    a chunk of messages decoded in bulk (:func:`slam.readers.cdr.decode_columns`;
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
        self.nanosecs: list[int] = []  # of each stamp, to refuse one that is no ROS time
        self.blocks: list[dict[str, np.ndarray]] = []
        self.n_bulk = 0  # messages received through add_columns
        self.ns = np.zeros(0, dtype=np.int64)

    def add(self, msg: Any) -> None:
        raise NotImplementedError

    def add_stamp(self, msg: Any) -> None:
        """Keep the header stamp of ``msg`` (each ``add`` does)."""
        self.stamps.append(_stamp(msg))
        self.nanosecs.append(msg.header.stamp.nanosec)

    def bulk_fields(self) -> tuple[str, ...]:
        """Fields ``add_columns`` needs (names of :mod:`slam.readers.cdr`)."""
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
        """Check the stamps are ROS times, strictly increasing; subclasses check values."""
        cols = self.columns()
        self.ns = cols["stamp_ns"] if cols is not None else np.asarray(self.stamps, dtype=np.int64)
        nanosec = cols["nanosec"] if cols is not None else np.asarray(self.nanosecs, dtype=np.int64)
        beyond = np.flatnonzero(nanosec >= _NS)
        if beyond.size:  # sec + 3e9 ns would read as another, later second
            i = int(beyond[0])
            raise GslamError(f"{self.where}: header stamp at message {i} has nanosec {int(nanosec[i])}, beyond "
                             f"{_NS - 1}: not a ROS time (a stamp in other units?)")
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

    def _rotations(self, field: str, quats: np.ndarray) -> None:
        """Quaternions (n, 4) must be rotations: of norm 1 (within 10 %; an
        all-zero orientation is a publisher that sets none)."""
        if quats.size == 0:
            return
        norm = np.linalg.norm(quats, axis=1)
        bad = np.abs(norm - 1.0) > 0.1
        if bad.any():
            i = int(np.flatnonzero(bad)[0])
            raise GslamError(f"{self.where}: {field} at message {i} is not a rotation (quaternion of norm {norm[i]:.3g}, "
                             f"expected 1; {int(bad.sum())} of {len(norm)} messages): a publisher that sets no orientation?")

    def first_ns(self) -> int | None:
        return int(self.ns[0]) if len(self.ns) else None

    def t(self, t0_ns: int) -> np.ndarray:
        return (self.ns - t0_ns).astype(np.float64) / _NS

    def build(self, t0_ns: int) -> Any:
        raise NotImplementedError


def _stamp(msg: Any) -> int:
    stamp = msg.header.stamp
    return stamp.sec * _NS + stamp.nanosec
