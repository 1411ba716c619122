"""Faults written into a BROAD trial (``.mat``): the IMU arrays of the
faulty stretch changed, everything else copied.

* ``dipole``: the dipole sits beside the optical path (``opt_pos``, the
  true heading), at the IMU's height at the interval's middle minus
  ``height_m``; its field at the IMU's optical positions is rotated into
  the IMU frame with ``opt_quat`` and added to ``imu_mag`` (uT). Labelled
  where the heading the magnetometer gives with the true tilt moves by more
  than ``label_deg`` (the reader's own label uses the same tilt).
* ``gyro_bias``: the bias about the true vertical (``opt_quat``) added to
  ``imu_gyr``.

Untracked optical samples (NaN) take the nearest tracked pose.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from slam.errors import GslamError
from validation.base.geometry import heading_from_magnetometer, wrap_angle
from slam.commands.inject import physics
from slam.commands.inject.labels import Labels
from slam.commands.inject.spec import DipoleFault, Fault, GyroBiasFault
from slam.readers.broad import _load, _truth_up, level_field
from slam.sim.magnetics import dipole_field

SUPPORTED = ("dipole", "gyro_bias")


def _filled(values: np.ndarray, ok: np.ndarray) -> np.ndarray:
    """``values`` (n, k) with the rows where ``ok`` is False taken from the
    nearest row where it is True."""
    idx = np.arange(len(values))
    good = np.flatnonzero(ok)
    nearest = good[np.clip(np.searchsorted(good, idx), 0, len(good) - 1)]
    before = good[np.clip(np.searchsorted(good, idx) - 1, 0, len(good) - 1)]
    nearest = np.where(np.abs(before - idx) < np.abs(nearest - idx), before, nearest)
    return values[nearest]


def _rotate_to_imu(quat_wxyz: np.ndarray, v: np.ndarray) -> np.ndarray:
    """World vectors (n, 3) in the IMU frame: R(q)^T v for IMU-to-world q."""
    q = quat_wxyz / np.linalg.norm(quat_wxyz, axis=1, keepdims=True)
    w, x, y, z = q.T
    r = np.stack([
        np.column_stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)]),
        np.column_stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)]),
        np.column_stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]),
    ], axis=1)  # (n, 3, 3), rows of R
    return np.einsum("nji,nj->ni", r, v)


def inject_broad(source: Path, dest: Path, faults: list[Fault]) -> Labels:
    """Copy the BROAD trial ``source`` into the folder ``dest`` under its
    own name with ``faults`` added; their true intervals."""
    from scipy.io import savemat

    for fault in faults:
        if fault.kind not in SUPPORTED:
            raise GslamError(f"--fault {fault.text()}: a BROAD trial has an IMU only (faults: {', '.join(SUPPORTED)})")
    d = _load(source)
    fs = float(np.asarray(d["sampling_rate"]).ravel()[0])
    n = len(d["imu_gyr"])
    t = np.arange(n) / fs
    tracked = np.isfinite(d["opt_quat"]).all(axis=1)
    quat = _filled(d["opt_quat"], tracked)
    pos = np.asarray(d.get("opt_pos", np.zeros((n, 3))), dtype=np.float64)
    pos = _filled(pos, tracked & np.isfinite(pos).all(axis=1)) if pos.shape == (n, 3) else np.zeros((n, 3))
    w, x, y, z = quat.T
    yaw = np.arctan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    up = _truth_up(quat)
    labels = Labels()
    for fault in faults:
        on = physics.inside(t, fault.start_s, fault.end_s)
        if isinstance(fault, DipoleFault):
            if fault.target == "heading":
                raise GslamError(f"--fault {fault.text()}: a BROAD trial's compass is a magnetometer")
            k = int(np.argmin(np.abs(t - 0.5 * (fault.start_s + fault.end_s))))
            side = 1.0 if fault.side == "left" else -1.0
            where = pos[k] + fault.distance_m * side * np.array([-np.sin(yaw[k]), np.cos(yaw[k]), 0.0])
            where[2] -= fault.height_m
            az = yaw[k] + np.radians(fault.azimuth_deg)
            moment = fault.moment_A_m2 * np.array([np.cos(az), np.sin(az), 0.0])
            added = _rotate_to_imu(quat, dipole_field(pos, where, moment)) * 1e6 * on[:, None]
            before, _ = level_field(d["imu_mag"] * 1e-6, up)
            d["imu_mag"] = d["imu_mag"] + added
            after, _ = level_field(d["imu_mag"] * 1e-6, up)
            change = wrap_angle(heading_from_magnetometer(after) - heading_from_magnetometer(before))
            labels.add("IMU_YAW", t, tracked & (np.abs(change) > np.radians(fault.label_deg)))
        elif isinstance(fault, GyroBiasFault):
            d["imu_gyr"] = d["imu_gyr"] + np.radians(fault.bias_deg_s) * up * on[:, None]
            labels.add("IMU_GYRO", t, on & (abs(fault.bias_deg_s) > fault.label_deg_s))
    dest.mkdir(parents=True, exist_ok=True)
    data = {k: v for k, v in d.items() if not k.startswith("__")}
    savemat(str(dest / source.name), data, do_compression=True)
    return labels
