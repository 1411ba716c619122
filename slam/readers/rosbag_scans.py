"""The LaserScan stream of the ROS bag reader (:mod:`slam.readers.rosbag`).

sensor_msgs/LaserScan -> :class:`Scans`, ranges as published; the beam count
and angles must not change within the stream.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from slam.errors import GslamError
from slam.readers.rosbag_streams import LASER_SCAN, _Stream
from slam.recording import Scans


class _ScanStream(_Stream):
    """LaserScan; beam count and angles must not change within the stream."""

    msgtypes = (LASER_SCAN,)

    def __init__(self, name: str, topic: str, bag: Path) -> None:
        super().__init__(name, topic, bag)
        self.ranges: list[np.ndarray] = []
        self.block: np.ndarray | None = None  # (n, beams) when decoded in bulk
        self.first: Any = None

    def add(self, msg: Any) -> None:
        self._finite_angles(np.array([[msg.angle_min, msg.angle_increment]]), len(self.stamps))
        self._finite_limits(np.array([msg.range_min]), np.array([msg.range_max]), len(self.stamps))
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
        self.add_stamp(msg)
        self.ranges.append(msg.ranges)

    def bulk_fields(self) -> tuple[str, ...]:
        return ("angle_min", "angle_increment", "range_min", "range_max", "ranges")

    def reset_columns(self) -> None:
        super().reset_columns()
        self.first = None

    def check_columns(self, cols: dict[str, np.ndarray], offset: int) -> None:
        self._finite_angles(np.column_stack([cols["angle_min"], cols["angle_increment"]]), offset)
        self._finite_limits(cols["range_min"], cols["range_max"], offset)
        if self.first is None:
            head = (float(cols[k][0]) for k in ("angle_min", "angle_increment", "range_min", "range_max"))
            self.first = _ScanHead(*head, cols["ranges"].shape[1])
        first = self.first
        beams = cols["ranges"].shape[1]  # one per chunk: its messages share one layout
        if beams != first.beams:
            raise GslamError(f"{self.where}: message {offset} has {beams} beams, the first had {first.beams}")
        differs = (cols["angle_min"] != first.angle_min) | (cols["angle_increment"] != first.angle_increment)
        if differs.any():
            raise GslamError(f"{self.where}: beam angles change at message {offset + int(np.argmax(differs))}")

    def finish(self) -> None:
        super().finish()
        cols = self.columns()
        if cols is not None:
            self.block = cols["ranges"]
            self.blocks = []  # the block is the only copy kept

    def _finite_angles(self, angles: np.ndarray, offset: int) -> None:
        """Rows of (angle_min, angle_increment) from message ``offset`` on
        are finite: a NaN angle is no layout (and differs from every other,
        which would read as angles that change)."""
        bad = ~np.isfinite(angles).all(axis=1)
        if bad.any():
            raise GslamError(f"{self.where}: non-finite angle_min/angle_increment at message {offset + int(np.argmax(bad))}")

    def _finite_limits(self, range_min: np.ndarray, range_max: np.ndarray, offset: int) -> None:
        """range_min finite and range_max a number or +inf (no limit, as
        REP-117 allows) from message ``offset`` on: a NaN limit is a corrupt
        field, as a NaN angle is, not a laser that returns nothing."""
        with np.errstate(invalid="ignore"):
            bad = ~np.isfinite(range_min) | np.isnan(range_max) | (range_max == -np.inf)
        if bad.any():
            k = int(np.argmax(bad))
            raise GslamError(f"{self.where}: non-finite range_min/range_max at message {offset + k} "
                             f"({float(range_min[k]):g}, {float(range_max[k]):g}); expected the laser's range limits in m")

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
