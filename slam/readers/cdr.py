"""Bulk decoding of fixed-layout ROS 2 messages (CDR) with numpy.

rosbags decodes one message at a time in Python, which is most of the time
spent reading a bag with 100 Hz topics. Within one topic the layout of a
message only changes with the lengths of its strings (frame ids) and
sequences (laser ranges); when every message of a topic has the layout of
the first, each field sits at the same byte offset in every message, and
the whole topic decodes as one numpy structured array.

:func:`decode_columns` does that for the message types the bag reader
needs. It returns ``None`` whenever the fast path does not apply (ROS 1
serialisation, big-endian CDR, an unknown type, messages whose string or
sequence lengths differ); the caller then decodes message by message.
:func:`agrees` compares a decoded row with the same message deserialised by
rosbags, so a bag written with another definition of a type is caught.
Alignment follows CDR (XCDR1): a primitive of n bytes starts at a multiple
of n counted from the end of the 4-byte encapsulation header.
"""

from __future__ import annotations

import struct
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

_ENCAPSULATION = 4
_CDR_LE = b"\x00\x01"  # plain CDR, little endian

# Fields after std_msgs/Header, per message type: (name, kind, count).
# kind is a numpy type code, "str" (uint32 length + bytes) or "seq:<code>"
# (uint32 count + elements).
_BODY: dict[str, tuple[tuple[str, str, int], ...]] = {
    "sensor_msgs/msg/Imu": (
        ("orientation", "f8", 4), ("orientation_covariance", "f8", 9),
        ("angular_velocity", "f8", 3), ("angular_velocity_covariance", "f8", 9),
        ("linear_acceleration", "f8", 3), ("linear_acceleration_covariance", "f8", 9),
    ),
    "sensor_msgs/msg/MagneticField": (("magnetic_field", "f8", 3), ("magnetic_field_covariance", "f8", 9)),
    "nav_msgs/msg/Odometry": (
        ("child_frame_id", "str", 1), ("position", "f8", 3), ("orientation", "f8", 4), ("pose_covariance", "f8", 36),
        ("twist", "f8", 6), ("twist_covariance", "f8", 36),
    ),
    "geometry_msgs/msg/PoseStamped": (("position", "f8", 3), ("orientation", "f8", 4)),
    "sensor_msgs/msg/NavSatFix": (
        ("status", "i1", 1), ("service", "u2", 1), ("latitude", "f8", 1), ("longitude", "f8", 1),
        ("altitude", "f8", 1), ("position_covariance", "f8", 9), ("position_covariance_type", "u1", 1),
    ),
    "sensor_msgs/msg/LaserScan": (
        ("angle_min", "f4", 1), ("angle_max", "f4", 1), ("angle_increment", "f4", 1), ("time_increment", "f4", 1),
        ("scan_time", "f4", 1), ("range_min", "f4", 1), ("range_max", "f4", 1),
        ("ranges", "seq:f4", 0), ("intensities", "seq:f4", 0),
    ),
}
_HEADER = (("sec", "i4", 1), ("nanosec", "u4", 1), ("frame_id", "str", 1))


def _xyz(v: Any) -> list[float]:
    return [v.x, v.y, v.z]


def _xyzw(q: Any) -> list[float]:
    return [q.x, q.y, q.z, q.w]


def _pose(msg: Any) -> Any:
    return msg.pose.pose if hasattr(msg, "child_frame_id") else msg.pose


# Each field as rosbags' deserialised message holds it: a cross-check of the layout.
_GETTERS: dict[str, Callable[[Any], Any]] = {
    "orientation": lambda m: _xyzw(_pose(m).orientation if hasattr(m, "pose") else m.orientation),
    "orientation_covariance": lambda m: m.orientation_covariance,
    "angular_velocity": lambda m: _xyz(m.angular_velocity),
    "magnetic_field": lambda m: _xyz(m.magnetic_field),
    "position": lambda m: _xyz(_pose(m).position),
    "status": lambda m: m.status.status,
    "latitude": lambda m: m.latitude,
    "longitude": lambda m: m.longitude,
    "position_covariance": lambda m: m.position_covariance,
    "position_covariance_type": lambda m: m.position_covariance_type,
    "angle_min": lambda m: m.angle_min,
    "angle_increment": lambda m: m.angle_increment,
    "range_min": lambda m: m.range_min,
    "range_max": lambda m: m.range_max,
    "ranges": lambda m: m.ranges,
}


def agrees(msg: Any, cols: dict[str, np.ndarray], row: int = 0) -> bool:
    """True if row ``row`` of ``cols`` holds the values of ``msg``, the same
    message deserialised by rosbags: a check that the layout assumed here is
    the one the bag was written with."""
    stamp = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
    if int(cols["stamp_ns"][row]) != stamp:
        return False
    for name, values in cols.items():
        if name in ("stamp_ns", "nanosec"):  # the stamp, compared above
            continue
        getter = _GETTERS.get(name)
        if getter is None:
            return False
        expected = np.asarray(getter(msg), dtype=values.dtype)
        if not np.array_equal(expected, values[row], equal_nan=expected.dtype.kind == "f"):
            return False
    return True


def supported(msgtype: str) -> bool:
    """True if :func:`decode_columns` knows the layout of ``msgtype``."""
    return msgtype in _BODY



def _layout(msgtype: str, first: bytes) -> tuple[np.dtype, list[tuple[int, int]]] | None:
    """The structured dtype of one message laid out like ``first``, and the
    (offset, value) of every length field, which must match in each message."""
    names, formats, offsets, lengths = [], [], [], []
    pos = 0  # in the payload, after the encapsulation header
    payload = len(first) - _ENCAPSULATION

    def read_u32(at: int) -> int:
        return struct.unpack_from("<I", first, _ENCAPSULATION + at)[0]

    for name, kind, count in _HEADER + _BODY[msgtype]:
        if kind == "str" or kind.startswith("seq:"):
            pos = -(-pos // 4) * 4
            if pos + 4 > payload:
                return None
            n = read_u32(pos)
            lengths.append((pos, n))
            pos += 4
            if kind == "str":
                pos += n
                continue
            kind, count = kind[4:], n
        size = np.dtype(kind).itemsize
        pos = -(-pos // size) * size
        names.append(name)
        formats.append((kind, (count,)) if count != 1 else kind)
        offsets.append(pos + _ENCAPSULATION)
        pos += size * count
    # CDR may pad the end to the alignment of the largest member.
    if pos > payload or payload - pos >= 8:
        return None
    dtype = np.dtype({"names": names, "formats": formats, "offsets": offsets, "itemsize": len(first)})
    return dtype, lengths


def decode_columns(msgtype: str, raws: Sequence[bytes], fields: Sequence[str]) -> dict[str, np.ndarray] | None:
    """The named ``fields`` of every message in ``raws`` (ROS 2 CDR bytes of
    one topic) as arrays, one row per message, plus ``stamp_ns`` (int64
    header stamp, ns); or ``None`` when the messages cannot be decoded in
    bulk (see the module docstring)."""
    if not raws or msgtype not in _BODY:
        return None
    first = raws[0]
    size = len(first)
    if first[:2] != _CDR_LE or any(len(r) != size for r in raws):
        return None
    layout = _layout(msgtype, first)
    if layout is None:
        return None
    dtype, lengths = layout
    buf = np.frombuffer(b"".join(raws), dtype=np.uint8).reshape(len(raws), size)
    if not (buf[:, :2] == buf[0, :2]).all():
        return None
    for pos, n in lengths:
        at = _ENCAPSULATION + pos
        if not (buf[:, at : at + 4].copy().view("<u4")[:, 0] == n).all():
            return None
    rows = buf.reshape(-1).view(dtype)
    cols = {name: np.array(rows[name]) for name in fields}
    cols["stamp_ns"] = rows["sec"].astype(np.int64) * 1_000_000_000 + rows["nanosec"].astype(np.int64)
    cols["nanosec"] = rows["nanosec"].astype(np.int64)
    return cols
