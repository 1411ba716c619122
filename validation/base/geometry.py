"""Small planar-geometry helpers shared by the simulator, the readers and the
back-end. Frames and units as in :mod:`slam.recording`."""

from __future__ import annotations

import math

import numpy as np

EARTH_RADIUS_M = 6_378_137.0  # WGS-84 equatorial radius


def wrap_angle(a: np.ndarray | float) -> np.ndarray | float:
    """Wrap angles to (-pi, pi]."""
    w = np.mod(np.asarray(a, dtype=float) + np.pi, 2.0 * np.pi) - np.pi
    w = np.where(w == -np.pi, np.pi, w)
    return float(w) if np.ndim(w) == 0 else w


def yaw_from_quaternion(qx, qy, qz, qw):
    """Yaw (rotation about z) of a quaternion, rad; works on arrays."""
    return np.arctan2(2.0 * (qw * qz + qx * qy), 1.0 - 2.0 * (qy * qy + qz * qz))


def quaternion_from_yaw(yaw: float) -> tuple[float, float, float, float]:
    """(x, y, z, w) of a rotation by ``yaw`` about z."""
    return 0.0, 0.0, float(np.sin(yaw / 2.0)), float(np.cos(yaw / 2.0))


def heading_from_magnetometer(field_body: np.ndarray, declination_rad: float = 0.0) -> np.ndarray:
    """World yaw of a level robot from the magnetic field in its body frame.

    ``field_body`` is (n, 3) (or (3,)) in the REP-103 body frame (x forward,
    y left). The horizontal field points to magnetic north, which lies
    ``declination_rad`` east of true north; true north is +y of the ENU world
    frame, so yaw = pi/2 - declination - atan2(m_y, m_x).
    """
    m = np.atleast_2d(field_body)
    yaw = np.pi / 2.0 - declination_rad - np.arctan2(m[:, 1], m[:, 0])
    yaw = wrap_angle(yaw)
    return yaw if np.ndim(field_body) == 2 else float(yaw[0])


def enu_from_geodetic(lat_deg, lon_deg, lat0_deg: float, lon0_deg: float):
    """Local east/north metres of latitude/longitude about a datum.

    An equirectangular projection: exact enough (mm) over the few km a
    ground robot covers in one run.
    """
    lat0 = np.radians(lat0_deg)
    east = np.radians(np.asarray(lon_deg) - lon0_deg) * EARTH_RADIUS_M * np.cos(lat0)
    north = np.radians(np.asarray(lat_deg) - lat0_deg) * EARTH_RADIUS_M
    return east, north


def geodetic_from_enu(east, north, lat0_deg: float, lon0_deg: float):
    """Inverse of :func:`enu_from_geodetic`: (lat_deg, lon_deg)."""
    lat0 = np.radians(lat0_deg)
    lat = lat0_deg + np.degrees(np.asarray(north) / EARTH_RADIUS_M)
    lon = lon0_deg + np.degrees(np.asarray(east) / (EARTH_RADIUS_M * np.cos(lat0)))
    return lat, lon


def compose(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Planar poses (x, y, yaw) ``a * b``, row by row ((n, 3) or (3,))."""
    a2, b2 = np.atleast_2d(a), np.atleast_2d(b)
    c, s = np.cos(a2[:, 2]), np.sin(a2[:, 2])
    out = np.column_stack(
        [a2[:, 0] + c * b2[:, 0] - s * b2[:, 1], a2[:, 1] + s * b2[:, 0] + c * b2[:, 1], wrap_angle(a2[:, 2] + b2[:, 2])]
    )
    return out[0] if np.ndim(a) == 1 and np.ndim(b) == 1 else out


def between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Planar poses ``inverse(a) * b``, row by row ((n, 3) or (3,))."""
    a2, b2 = np.atleast_2d(a), np.atleast_2d(b)
    c, s = np.cos(a2[:, 2]), np.sin(a2[:, 2])
    dx, dy = b2[:, 0] - a2[:, 0], b2[:, 1] - a2[:, 1]
    out = np.column_stack([c * dx + s * dy, -s * dx + c * dy, wrap_angle(b2[:, 2] - a2[:, 2])])
    return out[0] if np.ndim(a) == 1 and np.ndim(b) == 1 else out


def rotation(yaw: float) -> np.ndarray:
    """The 2 x 2 rotation matrix of ``yaw`` (rad)."""
    c, s = np.cos(yaw), np.sin(yaw)
    return np.array([[c, -s], [s, c]])


def transform_points(pose: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Points (n, 2) given in the frame of ``pose`` (x, y, yaw), in its parent frame."""
    c, s = math.cos(pose[2]), math.sin(pose[2])
    return points @ np.array([[c, s], [-s, c]]) + np.asarray(pose[:2])
