"""The physics of the faults ``gslam inject`` adds, on arrays in a
recording's own time base (s from its start) and frames.

* **Dipole.** A point dipole (:func:`slam.sim.magnetics.dipole_field`)
  placed beside the path: ``distance_m`` to one side of the robot's
  position at the interval's middle, in the frame of the path (ground
  truth, else odometry: only positions relative to the dipole matter). Its
  field in a level robot's body frame is added to a magnetometer; for a
  heading from an orientation estimate, the heading error it causes
  against the Earth's horizontal field is taken off the heading
  (:func:`heading_error`).
* **Laser cut.** Ranges beyond ``range_m`` become no return. Whether the
  cut scan still constrains a pose is judged from its own points
  (:func:`slam.frontend.scan_geometry.scan_geometry`): normals from a line through each return and its
  neighbours, then the point-to-line information matrix of
  :mod:`slam.sim.faults`.
* **Slip.** Odometry increments scaled over the interval and the poses
  chained again (:func:`reintegrate`): every pose after the interval moves
  with it, as a slipping robot's odometry does.
* **Multipath.** A position bias that rises and falls as a half sine.
"""

from __future__ import annotations

import numpy as np

from validation.base.geometry import wrap_angle
from slam.commands.inject.spec import DipoleFault, LaserCutFault, MultipathFault, SlipFault
from slam.recording import interpolate_poses
from slam.recording import Trajectory
from slam.frontend.scan_geometry import scan_geometry
from slam.sim.faults import SM_MODALITIES, sm_masks
from slam.sim.magnetics import dipole_field, world_to_body


def inside(t: np.ndarray, start: float, end: float) -> np.ndarray:
    return (np.asarray(t) >= start) & (np.asarray(t) <= end)


# --- dipole ------------------------------------------------------------------------


class Dipole:
    """A dipole placed beside ``path`` (:class:`DipoleFault`); positions in
    the path's frame, m, the sensor at height 0."""

    def __init__(self, fault: DipoleFault, path: Trajectory) -> None:
        self.fault = fault
        self.path = path
        mid = 0.5 * (fault.start_s + fault.end_s)
        x, y, yaw = interpolate_poses(path, np.array([mid]))[0]
        side = 1.0 if fault.side == "left" else -1.0
        self.position = np.array([x - side * fault.distance_m * np.sin(yaw),
                                  y + side * fault.distance_m * np.cos(yaw), -fault.height_m])
        azimuth = yaw + np.radians(fault.azimuth_deg)
        self.moment = fault.moment_A_m2 * np.array([np.cos(azimuth), np.sin(azimuth), 0.0])

    def field_path(self, t: np.ndarray, height: np.ndarray | None = None) -> np.ndarray:
        """Field (n, 3) T at the sensor at times ``t`` in the path's frame;
        zero outside the fault's interval."""
        pose = interpolate_poses(self.path, np.asarray(t, float))
        z = np.zeros(len(pose)) if height is None else height
        b = dipole_field(np.column_stack([pose[:, :2], z]), self.position, self.moment)
        return b * inside(t, self.fault.start_s, self.fault.end_s)[:, None]

    def field_body(self, t: np.ndarray) -> np.ndarray:
        """Field (n, 3) T in the REP-103 body frame of a level robot on the path."""
        yaw = interpolate_poses(self.path, np.asarray(t, float))[:, 2]
        return world_to_body(self.field_path(t), yaw)


def heading_change(field_body: np.ndarray, added: np.ndarray) -> np.ndarray:
    """How much (rad) a magnetometer heading changes when ``added`` joins
    the body field ``field_body`` (both (n, 3) T, level robot): the heading
    is minus the field's angle in the body, so it turns the other way."""
    before = np.arctan2(field_body[:, 1], field_body[:, 0])
    after = np.arctan2(field_body[:, 1] + added[:, 1], field_body[:, 0] + added[:, 0])
    return -np.asarray(wrap_angle(after - before))


def heading_error(heading: np.ndarray, added_body: np.ndarray, horizontal_T: float, declination_rad: float = 0.0) -> np.ndarray:
    """Heading change (rad) of a compass at true ``heading`` (n,) rad (ENU)
    whose Earth field is ``horizontal_T`` strong, when ``added_body`` (n, 3)
    T joins it: the Earth field points to magnetic north, in the body at
    ``pi/2 - declination - heading``."""
    angle = np.pi / 2.0 - declination_rad - np.asarray(heading, float)
    earth = horizontal_T * np.column_stack([np.cos(angle), np.sin(angle), np.zeros(len(angle))])
    return heading_change(earth, added_body)


# --- laser ---------------------------------------------------------------------------


def cut_ranges(ranges: np.ndarray, range_m: float, no_return: float) -> np.ndarray:
    """``ranges`` with every value beyond ``range_m`` set to ``no_return``."""
    r = np.array(ranges, dtype=np.float64, copy=True)
    with np.errstate(invalid="ignore"):
        r[r > range_m] = no_return
    return r


def laser_labels(ranges: np.ndarray, angles: np.ndarray, range_min: float, range_max: float,
                 fault: LaserCutFault) -> dict[str, np.ndarray]:
    """Per scan-matching modality, the cut scans that cannot constrain it."""
    count, min_eig, weak = scan_geometry(ranges, angles, range_min, range_max)
    return sm_masks(count, min_eig, weak, np.zeros(len(count)), fault.label_min_returns, fault.label_min_eigenvalue)


# --- odometry and GPS --------------------------------------------------------------------


def reintegrate(t: np.ndarray, x: np.ndarray, y: np.ndarray, yaw: np.ndarray, fault: SlipFault) -> tuple[np.ndarray, ...]:
    """Poses chained again from their increments, those that start inside
    the fault's interval scaled (distance by ``scale``, turn by
    ``yaw_scale``). Any planar frame whose headings are measured from its x
    towards its y axis (ENU, and NED's x north towards y east)."""
    x, y, yaw = (np.asarray(a, dtype=np.float64) for a in (x, y, yaw))
    c, s = np.cos(yaw[:-1]), np.sin(yaw[:-1])
    dx, dy = np.diff(x), np.diff(y)
    fwd, left = c * dx + s * dy, -s * dx + c * dy
    turn = np.asarray(wrap_angle(np.diff(yaw)))
    slip = inside(t[:-1], fault.start_s, fault.end_s)
    fwd, left = np.where(slip, fault.scale * fwd, fwd), np.where(slip, fault.scale * left, left)
    turn = np.where(slip, fault.yaw_scale * turn, turn)
    new_yaw = yaw[0] + np.concatenate([[0.0], np.cumsum(turn)])
    c, s = np.cos(new_yaw[:-1]), np.sin(new_yaw[:-1])
    new_x = x[0] + np.concatenate([[0.0], np.cumsum(c * fwd - s * left)])
    new_y = y[0] + np.concatenate([[0.0], np.cumsum(s * fwd + c * left)])
    return new_x, new_y, np.asarray(wrap_angle(new_yaw))


def slip_labels(t: np.ndarray, x: np.ndarray, y: np.ndarray, yaw: np.ndarray, fault: SlipFault) -> dict[str, np.ndarray]:
    """Samples (the start of each increment) where the slip's error exceeds
    ``label_slip`` of a motion that is happening (driving: > 1 cm/s;
    turning: > 1 deg/s), for each modality the fault scales."""
    dt = np.maximum(np.diff(t), 1e-9)
    speed = np.hypot(np.diff(x), np.diff(y)) / dt
    turn_rate = np.abs(np.asarray(wrap_angle(np.diff(yaw)))) / dt
    slip = inside(t[:-1], fault.start_s, fault.end_s)
    out = {}
    if fault.scale != 1.0:
        out["ODO_DIST"] = np.append(slip & (abs(fault.scale - 1.0) > fault.label_slip) & (speed > 0.01), False)
    if fault.yaw_scale != 1.0:
        turning = slip & (abs(fault.yaw_scale - 1.0) > fault.label_slip) & (turn_rate > np.radians(1.0))
        out["ODO_YAW"] = np.append(turning, False)
    return out


def multipath_bias(t: np.ndarray, fault: MultipathFault) -> np.ndarray:
    """Bias (n, 2) m east/north at times ``t``: a half sine over the interval."""
    phase = (np.asarray(t, float) - fault.start_s) / (fault.end_s - fault.start_s)
    size = np.where((phase >= 0.0) & (phase <= 1.0), fault.bias_m * np.sin(np.pi * np.clip(phase, 0.0, 1.0)), 0.0)
    a = np.radians(fault.azimuth_deg)
    return np.column_stack([size * np.cos(a), size * np.sin(a)])


__all__ = [
    "Dipole", "SM_MODALITIES", "cut_ranges", "heading_change", "heading_error", "inside", "laser_labels",
    "multipath_bias", "reintegrate", "scan_geometry", "slip_labels",
]
