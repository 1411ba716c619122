"""The magnetic field seen by a level robot: Earth's field plus steel.

The undisturbed Earth field (strength F, dip I positive downward,
declination D east positive) in the ENU world frame is
``F * (cos I sin D, cos I cos D, -sin I)``. Each steel structure is a point
dipole of moment m (A m^2) whose field at offset r from it is

    B = mu0 / (4 pi) * (3 r_hat (r_hat . m) - m) / |r|^3        (tesla),

evaluated in 3D with the sensor at its mounting height and the dipole at
its own height. The body frame (REP-103) of a level robot with yaw psi is the
world frame rotated by psi about z, so ``B_body = R_z(-psi) B_world``.
Near steel the heading from :func:`validation.base.geometry.heading_from_magnetometer`,
the field strength and the dip all move away from the reference by physics.
"""

from __future__ import annotations

import numpy as np

from slam.recording import MagneticReference
from slam.sim.scenario import Disturber, EnvironmentConfig

MU0_OVER_4PI = 1e-7  # T m / A


def reference(env: EnvironmentConfig) -> MagneticReference:
    """The undisturbed field of a scenario in SI units."""
    return MagneticReference(
        strength_T=env.field_strength_T,
        dip_rad=float(np.radians(env.dip_deg)),
        declination_rad=float(np.radians(env.declination_deg)),
    )


def earth_field_world(ref: MagneticReference) -> np.ndarray:
    """Earth's field (3,) in the ENU world frame, T."""
    h = ref.strength_T * np.cos(ref.dip_rad)
    east, north = h * np.sin(ref.declination_rad), h * np.cos(ref.declination_rad)
    return np.array([east, north, -ref.strength_T * np.sin(ref.dip_rad)])


def dipole_field(points: np.ndarray, position: np.ndarray, moment: np.ndarray) -> np.ndarray:
    """Field (n, 3) T of a dipole of ``moment`` (3,) A m^2 at ``position``
    (3,) m, at ``points`` (n, 3) m (world frame)."""
    r = points - position
    dist = np.linalg.norm(r, axis=1)
    dist = np.maximum(dist, 1e-3)  # the dipole law diverges at the source
    r_hat = r / dist[:, None]
    dot = r_hat @ moment
    return MU0_OVER_4PI * (3.0 * r_hat * dot[:, None] - moment[None]) / dist[:, None] ** 3


def field_world(
    xy: np.ndarray, height_m: float, ref: MagneticReference, disturbers: list[Disturber]
) -> np.ndarray:
    """Total field (n, 3) T in the world frame at planar positions ``xy``
    (n, 2) m with the sensor ``height_m`` above the floor."""
    pts = np.column_stack([xy, np.full(len(xy), height_m)])
    b = np.tile(earth_field_world(ref), (len(xy), 1))
    for d in disturbers:
        axis = np.asarray(d.direction, dtype=float)
        moment = d.moment_A_m2 * axis / np.linalg.norm(axis)
        b += dipole_field(pts, np.asarray(d.position, dtype=float), moment)
    return b


def world_to_body(b_world: np.ndarray, yaw: np.ndarray) -> np.ndarray:
    """Rotate world-frame vectors (n, 3) into the body frame of a level robot
    with heading ``yaw`` (n,) rad."""
    c, s = np.cos(yaw), np.sin(yaw)
    return np.column_stack(
        [c * b_world[:, 0] + s * b_world[:, 1], -s * b_world[:, 0] + c * b_world[:, 1], b_world[:, 2]]
    )


def dip_angle(b: np.ndarray) -> np.ndarray:
    """Dip (n,) rad of field vectors (n, 3), positive when pointing down."""
    return np.arctan2(-b[:, 2], np.hypot(b[:, 0], b[:, 1]))


def body_field(
    xy: np.ndarray, yaw: np.ndarray, height_m: float, ref: MagneticReference, disturbers: list[Disturber]
) -> np.ndarray:
    """Noise-free body-frame field (n, 3) T of a level robot at poses
    (``xy`` (n, 2) m, ``yaw`` (n,) rad)."""
    return world_to_body(field_world(xy, height_m, ref, disturbers), yaw)
