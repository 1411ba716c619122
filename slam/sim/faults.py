"""True fault intervals, derived from the simulated physics.

A component is faulty where its output is physically wrong beyond its
nominal noise. Nothing here is switched on by a flag; each definition looks
at the noise-free quantity the sensor model produced:

* ``IMU_YAW`` (compass): the heading computed by
  :func:`validation.base.geometry.heading_from_magnetometer` from the noise-free body
  field (Earth + steel dipoles) differs from the true yaw by more than
  ``faults.compass_error_deg``. Evaluated at the truth rate.
* ``SM_DIST``, ``SM_LAT``, ``SM_YAW`` (scan matching's motion along the
  heading, sideways and its turn): the noise-free scan cannot constrain
  that part of a 2D pose, either because it has fewer than
  ``faults.sm_min_returns`` returns (all three), or because its geometry is
  degenerate along a direction that involves it. For each return i with hit point p_i
  (relative to the laser, m) on a wall with unit normal n_i, point-to-line
  ICP has the Jacobian row J_i = (n_x, n_y, (p_i x n_i) / L), L being the
  mean range so all three columns are unitless; the scan is degenerate when
  the smallest eigenvalue of ``sum_i(J_i^T J_i) / B`` (B the number of
  beams, so a scan with few returns is weak too) is below
  ``faults.sm_min_eigenvalue``. A single straight wall (or a corridor) has
  an exact null direction along the wall and gives 0; a furnished room
  gives 0.1-0.3. The eigenvector of that smallest eigenvalue, in the body
  frame (forward, left, turn), says which modalities it involves: each
  whose share of the unit vector exceeds a quarter (|component| > 0.5). A
  corridor leaves the forward motion free (``SM_DIST``) and holds the
  sideways motion and the turn. At the laser times.
* ``GPS``: a fix is published and its multipath bias exceeds
  ``faults.gps_sigmas`` times the nominal sigma. At the GPS times (no fix
  means no output, which is not a fault).
* ``ODO_DIST``, ``ODO_YAW``: the track slip (terrain slip + turn-rate part)
  exceeds ``faults.odo_slip``, i.e. more than the nominal slip of a
  calibrated odometry, while the robot drives (``ODO_DIST``) or turns
  (``ODO_YAW``). At the truth rate.
* ``IMU_GYRO``: the true gyro bias exceeds ``faults.gyro_bias_rad_s``
  (normally never). At the gyro times.

Samples flagged faulty are joined into intervals ``[first, last]`` (s from
the start); intervals closer than ``faults.merge_gap_s`` are merged and
those shorter than ``faults.min_duration_s`` dropped.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from validation.base.geometry import heading_from_magnetometer, wrap_angle
from slam.recording import Interval
from slam.sim.magnetics import body_field, reference
from slam.sim.robot import Motion
from slam.recording import intervals_from_mask
from slam.sim.scenario import Scenario
from slam.sim.world import World

if TYPE_CHECKING:
    from slam.sim.sensors import GpsData, GyroData, LaserData


def compass_heading_error(
    true_body_field: np.ndarray, yaw: np.ndarray, declination_rad: float
) -> np.ndarray:
    """Heading error (n,) rad of a compass reading a noise-free field."""
    return np.asarray(wrap_angle(heading_from_magnetometer(true_body_field, declination_rad) - yaw))


SM_MODALITIES = ("SM_DIST", "SM_LAT", "SM_YAW")


def sm_masks(
    count: np.ndarray,
    min_eig: np.ndarray,
    weak: np.ndarray,
    yaw: np.ndarray,
    min_returns: int,
    min_eigenvalue: float,
) -> dict[str, np.ndarray]:
    """Per scan-matching modality, the scans that cannot constrain it
    (module docstring); ``weak`` (n, 3) is the weakest direction in the
    world frame, ``yaw`` (n,) the robot's heading, rad."""
    c, s = np.cos(yaw), np.sin(yaw)
    body = np.column_stack([c * weak[:, 0] + s * weak[:, 1], -s * weak[:, 0] + c * weak[:, 1], weak[:, 2]])
    few = count < min_returns
    degenerate = min_eig < min_eigenvalue
    return {m: few | (degenerate & (np.abs(body[:, i]) > 0.5)) for i, m in enumerate(SM_MODALITIES)}


def true_faults(
    scenario: Scenario,
    world: World,
    motion: Motion,
    laser: LaserData,
    gyro: GyroData,
    gps: GpsData,
) -> dict[str, list[Interval]]:
    """The fault intervals (s from the start) of every component."""
    cfg = scenario.faults
    ref = reference(scenario.environment)
    xy = motion.xy()

    def intervals(t: np.ndarray, mask: np.ndarray) -> list[Interval]:
        return intervals_from_mask(t, mask, cfg.merge_gap_s, cfg.min_duration_s)

    # 1. Compass: heading from the noise-free disturbed field vs the truth.
    height = scenario.sensors.magnetometer.mounting_height_m
    field = body_field(xy, motion.yaw, height, ref, scenario.world.disturbers)
    yaw_err = compass_heading_error(field, motion.yaw, ref.declination_rad)
    # 2. Track slip beyond nominal while driving or turning.
    slip = world.track_slip(xy, motion.w, scenario.sensors.odometry.turn_slip_per_rad_s) > cfg.odo_slip
    driving, turning = np.abs(motion.v) > 0.01, np.abs(motion.w) > np.radians(1.0)
    # 3. Scan geometry per modality, 4. gyro bias, 5. multipath.
    laser_yaw = np.interp(laser.t, motion.t, motion.yaw)
    sm = sm_masks(laser.returns, laser.min_eigenvalue, laser.weak_direction, laser_yaw,
                  cfg.sm_min_returns, cfg.sm_min_eigenvalue)
    gps_bad = (gps.status == 0) & (gps.multipath > cfg.gps_sigmas * gps.sigma)
    return {
        "ODO_DIST": intervals(motion.t, slip & driving),
        "ODO_YAW": intervals(motion.t, slip & turning),
        "IMU_GYRO": intervals(gyro.t, np.abs(gyro.bias) > cfg.gyro_bias_rad_s),
        "IMU_YAW": intervals(motion.t, np.abs(yaw_err) > np.radians(cfg.compass_error_deg)),
        **{m: intervals(laser.t, sm[m]) for m in SM_MODALITIES},
        "GPS": intervals(gps.t, gps_bad),
    }
