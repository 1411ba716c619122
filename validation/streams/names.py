"""The names of the validation streams and the components they speak for.

Most streams have fixed names (:data:`StreamName`, the table of
:mod:`validation.streams`). A source of planar poses, the *odometry-like*
sources, gives one stream per quantity, named ``{source}_{quantity}``:

============ ================================================================
quantity     values
============ ================================================================
yaw          the source's yaw, rad (angular)
distance     path length of its x/y, m
forward      forward travel: the sum of the steps along its heading, m
lateral      sideways travel: the sum of the body-frame lateral steps, m
speed        derivative of the distance, m/s
fix_speed    its speed derived as ``gps_speed`` is (the regression slope of
             its x and y over the GPS speed window), m/s
============ ================================================================

The built-in sources are ``odo`` (the odometry, components ``ODO_DIST`` and
``ODO_YAW``), ``sm`` (scan matching: ``SM_DIST``, ``SM_LAT`` for its
sideways travel, ``SM_YAW``) and ``sub`` (local SLAM's scan-to-submap
match, :func:`slam.submaps.build.local_witness`: ``SUB_YAW``, ``SUB_DIST``;
a witness that does not start where the odometry says, made only when an
observer compares one of its streams). A further odometry source named ``vo`` (a
visual odometry, a second wheel odometry: ``input.extra_odometry``) gives
``vo_yaw`` ... ``vo_fix_speed``, components ``VO_YAW`` and ``VO_DIST``, as
the odometry's do.
"""

from __future__ import annotations

import re
from typing import Literal, get_args

StreamName = Literal[
    "compass_yaw", "gyro_yaw", "sm_yaw", "odo_yaw", "odo_distance", "sm_distance",
    "odo_forward", "sm_forward", "odo_lateral", "sm_lateral", "odo_speed", "sm_speed", "gps_speed", "odo_fix_speed",
    "sm_fix_speed", "gps_course",
]
QualityStreamName = Literal[
    "mag_strength", "mag_dip", "mag_field_change", "gps_sigma",
    "scan_degenerate_dist", "scan_degenerate_lat", "scan_degenerate_yaw", "scan_ceiling",
]

ODOMETRY_QUANTITIES: tuple[str, ...] = ("yaw", "distance", "forward", "lateral", "speed", "fix_speed")
"""The streams of every odometry-like source, ``{source}_{quantity}``."""
INTEGRATED_QUANTITIES: frozenset[str] = frozenset({"yaw", "distance", "forward", "lateral"})
BUILTIN_SOURCES: dict[str, str] = {"odo": "ODO", "sm": "SM", "sub": "SUB"}
"""The odometry-like sources every run may have, and their sensor's component prefix."""
RESERVED_SOURCE_NAMES: frozenset[str] = frozenset({*BUILTIN_SOURCES, "gyro", "compass", "gps", "mag", "scan", "imu",
                                                    "loop"})
"""Names a further odometry source cannot take: the other streams' and components' prefixes."""

STREAM_COMPONENT: dict[str, str] = {
    "compass_yaw": "IMU_YAW",
    "gyro_yaw": "IMU_GYRO",
    "sm_yaw": "SM_YAW",
    "odo_yaw": "ODO_YAW",
    "odo_distance": "ODO_DIST",
    "sm_distance": "SM_DIST",
    "odo_forward": "ODO_DIST",
    "sm_forward": "SM_DIST",
    "odo_lateral": "ODO_DIST",
    "sm_lateral": "SM_LAT",
    "odo_speed": "ODO_DIST",
    "sm_speed": "SM_DIST",
    "gps_speed": "GPS",
    "odo_fix_speed": "ODO_DIST",
    "sm_fix_speed": "SM_DIST",
    "gps_course": "GPS",
    "mag_strength": "IMU_YAW",
    "mag_dip": "IMU_YAW",
    "mag_field_change": "IMU_YAW",
    "gps_sigma": "GPS",
    "scan_degenerate_dist": "SM_DIST",
    "scan_degenerate_lat": "SM_LAT",
    "scan_degenerate_yaw": "SM_YAW",
    "scan_ceiling": "SM",
}
STREAM_NAMES: tuple[str, ...] = get_args(StreamName) + get_args(QualityStreamName)
"""The fixed stream names (the further odometry sources' come on top)."""
ANGULAR_STREAMS: frozenset[str] = frozenset({"compass_yaw", "sm_yaw", "odo_yaw", "gps_course"})
INTEGRATED_STREAMS: frozenset[str] = frozenset({
    "gyro_yaw", "sm_yaw", "odo_yaw", "odo_distance", "sm_distance", "odo_forward", "sm_forward", "odo_lateral",
    "sm_lateral",
})
"""Streams that sum their sensor's increments: a fault of the sensor stays in
them for good (an offset relation forgets it once the fault is over)."""

_SOURCE_NAME = re.compile(r"[a-z][a-z0-9]*")
_SOURCE_STREAM = re.compile(rf"([a-z][a-z0-9]*)_({'|'.join(ODOMETRY_QUANTITIES)})")


def check_source_name(name: str) -> str:
    """``name`` if it can name a further odometry source, else ValueError."""
    if not _SOURCE_NAME.fullmatch(name):
        raise ValueError(f"odometry source name {name!r}: expected lower-case letters and digits, e.g. vo")
    if name in RESERVED_SOURCE_NAMES:
        raise ValueError(f"odometry source name {name!r} is taken; not one of {', '.join(sorted(RESERVED_SOURCE_NAMES))}")
    return name


def source_stream(source: str, quantity: str) -> str:
    """The stream of ``quantity`` of an odometry-like ``source``."""
    return f"{source}_{quantity}"


def split_source_stream(name: str) -> tuple[str, str] | None:
    """``(source, quantity)`` of an odometry-like source's stream, else None."""
    m = _SOURCE_STREAM.fullmatch(name)
    if m is None or m.group(1) in RESERVED_SOURCE_NAMES - set(BUILTIN_SOURCES):
        return None
    return m.group(1), m.group(2)


def is_stream_name(name: str) -> bool:
    """A fixed stream name, or a stream of some odometry-like source."""
    return name in STREAM_NAMES or split_source_stream(name) is not None


def source_component(source: str) -> str:
    """The sensor component of an odometry-like source: ``ODO``, ``SM``, ``VO``."""
    return BUILTIN_SOURCES.get(source, source.upper())


def stream_component(name: str) -> str:
    """The component ``name`` speaks for (the module docstring)."""
    if name in STREAM_COMPONENT:
        return STREAM_COMPONENT[name]
    split = split_source_stream(name)
    if split is None:
        raise KeyError(name)
    source, quantity = split
    return f"{source_component(source)}_{'YAW' if quantity == 'yaw' else 'DIST'}"


def is_angular(name: str) -> bool:
    """Whether the stream is an angle (unwrapped before it is interpolated)."""
    if name in ANGULAR_STREAMS:
        return True
    split = split_source_stream(name)
    return split is not None and split[1] == "yaw"


def is_integrated(name: str) -> bool:
    """Whether the stream sums its sensor's increments (:data:`INTEGRATED_STREAMS`)."""
    if name in INTEGRATED_STREAMS:
        return True
    split = split_source_stream(name)
    return split is not None and name not in STREAM_NAMES and split[1] in INTEGRATED_QUANTITIES
