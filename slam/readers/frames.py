"""Frame conventions of a recording's streams, turned into the project's.

The project works in an ENU world (x east, y north, z up; yaw
counter-clockwise from x) with REP-103 bodies (x forward, y left, z up);
see :mod:`slam.recording`. A bag may use others, per stream
(``input.frames``, :class:`slam.config.StreamFrameConfig`):

* ``world: ned``: x north, y east, z down, so a heading ``psi`` is measured
  clockwise from north. In the plane this is the reflection across the
  north-east diagonal: ``(x, y) -> (y, x)``, ``yaw -> pi/2 - psi``; a rate
  about the world's z (down) is minus the rate about up.
* ``body: frd``: x forward, y right, z down. The forward axis, and so the
  heading of a pose, is the same as REP-103's; a rate about the body z and
  a magnetometer's y and z change sign.
* ``yaw_sign: -1``: a further reflection across the world's x axis:
  ``y -> -y``, ``yaw -> -yaw``, a yaw rate negated.

Reflections keep a trajectory's shape: only its handedness and the meaning
of its axes change, so a path read in the wrong frame turns the wrong way
round, and one read in the right frame agrees with the other sensors.
"""

from __future__ import annotations

import numpy as np

from slam.config import StreamFrameConfig
from validation.base.geometry import wrap_angle


def planar_poses(x: np.ndarray, y: np.ndarray, yaw: np.ndarray, frame: StreamFrameConfig) -> tuple[np.ndarray, ...]:
    """Positions (m) and headings (rad) of a pose stream in the ENU world."""
    x, y, yaw = np.asarray(x, float), np.asarray(y, float), np.asarray(yaw, float)
    if frame.world == "ned":
        x, y, yaw = y, x, np.pi / 2.0 - yaw
    if frame.yaw_sign == -1:
        y, yaw = -y, -yaw
    return x.copy(), y.copy(), np.asarray(wrap_angle(yaw))


def heading(yaw: np.ndarray, frame: StreamFrameConfig) -> np.ndarray:
    """A heading stream (rad) in the ENU world (before declination and
    mounting are taken off, which are ENU angles)."""
    yaw = np.asarray(yaw, float)
    if frame.world == "ned":
        yaw = np.pi / 2.0 - yaw
    if frame.yaw_sign == -1:
        yaw = -yaw
    return np.asarray(wrap_angle(yaw))


def yaw_rate(rate: np.ndarray, frame: StreamFrameConfig, about: str = "body") -> np.ndarray:
    """A rate (rad/s) about the body's vertical axis (``about='body'``) or
    the world's (``'world'``), turned into the rate counter-clockwise about up."""
    sign = 1.0
    if (about == "body" and frame.body == "frd") or (about == "world" and frame.world == "ned"):
        sign = -sign
    if frame.yaw_sign == -1:
        sign = -sign
    return sign * np.asarray(rate, float)


def body_vector(v: np.ndarray, frame: StreamFrameConfig) -> np.ndarray:
    """Vectors (n, 3) measured in the stream's body frame, in REP-103's."""
    v = np.array(v, dtype=float, copy=True).reshape(-1, 3)
    if frame.body == "frd":
        v[:, 1:] = -v[:, 1:]
    return v
