"""Reader for BROAD trials (``*.mat``, MATLAB v5): a hand-held IMU with
optical motion-capture truth and real magnetic disturbances.

A trial holds ``imu_gyr`` (rad/s), ``imu_acc`` (m/s^2), ``imu_mag`` (uT), all
(N, 3) in the IMU frame at ``sampling_rate`` Hz (about 285.7), and the
optical ``opt_quat`` (N, 4; w, x, y, z; IMU-to-world, the world being ENU;
NaN where tracking was lost) and ``opt_pos`` (N, 3, m).

0. **Magnetometer lag.** The magnetometer's samples lag the gyro's and
   the optical truth's by ``MAG_LAG_S`` (12 ms, 3.5 samples); they are
   moved back onto the common clock by linear interpolation. Measured on
   the undisturbed trials, two ways: the field turned into a fixed frame by
   the integrated gyro changes least over 0.3 s at a lag of 3-4 samples
   (06 fast rotation: 99th percentile 13.5 uT without, 4.4-4.6 uT with),
   and the magnetometer's heading with the true tilt is closest to the
   optical heading at 12-16 ms (08: 99th percentile 25.7 deg without,
   10.5 deg at 12 ms). Uncorrected, the lag alone turns the heading more
   than 20 deg off in fast turns (8.7 s of undisturbed trial 08).

The IMU rotates in 3D, so the heading streams a planar robot would have are
made as follows (frames: IMU frame S; a *level frame* L that shares S's
heading with z up; world W, ENU):

1. **Tilt.** The up direction in S from a complementary filter: the gyro
   propagates it, the normalised accelerometer pulls it back with time
   constant ``TILT_TIME_CONSTANT_S`` (3 s). The raw accelerometer alone is
   wrong by 5-20 deg while the hand accelerates, which through the 65 deg dip
   of the Earth field becomes a heading error of tens of degrees.
2. **Gyro.** The trials start at rest: the gyro's mean over the first
   ``reference_s`` seconds is its bias (0.1-0.5 deg/s, stable over a
   trial) and is subtracted. ``Recording.gyro`` is the rate of the gyro's
   own heading (:func:`gyro_heading`): the ZYX yaw of an attitude the gyro
   propagates, its tilt held on the filtered up direction. That is the
   heading the compass and the optical truth measure; the rate about the
   vertical is not (it differs by ``roll_rate * sin(pitch)``).
3. **Compass.** The field is rotated into L (tilt compensation, roll/pitch of
   the ZYX convention) and turned into a heading with
   :func:`validation.base.geometry.heading_from_magnetometer`. The optical world's x axis
   is not exactly east: the constant offset between the compass heading and
   the true heading is estimated as the circular mean of their difference
   over the first ``reference_s`` seconds (the trials start at rest and
   undisturbed) and removed. ``Compass.field`` is the field in L in tesla,
   so its strength and dip (from z) are those of the real field whatever
   the IMU's tilt. Samples with ``|pitch| > max_pitch_deg`` are dropped
   (yaw is undefined near pitch +-90 deg).
4. **Truth.** ``Recording.groundtruth``: ZYX yaw of ``opt_quat`` and x, y of
   ``opt_pos``; samples with NaN and with ``|pitch| > max_pitch_deg`` are
   dropped.
5. **Magnetic reference.** Median strength and dip of the field over the
   first ``reference_s`` seconds.
6. **Faults.** ``faults["IMU_YAW"]``: intervals where the magnetometer's
   heading computed with the *true* tilt differs from the true heading
   (offset removed) by more than ``fault_threshold_deg``; gaps shorter than
   ``MERGE_GAP_S`` are bridged and intervals shorter than ``MIN_FAULT_S``
   dropped. Using the true tilt makes the label a property of the magnetic
   field, not of this reader's tilt filter. The default 20 deg lies above
   the undisturbed error: the horizontal field is only ~13 uT (dip ~71 deg),
   so the magnetometer's residual calibration error of 2-3 uT alone gives
   10 deg during fast rotations. Labelled seconds per trial at 10 / 20 deg
   (lag removed): undisturbed 01-15: 1-18 / 0; tapping 5 / 0; vibration
   25 / 0; stationary magnet 17-23 / 3.6-4.8; attached magnet 56-57 / 50-53.
   With the lag left in (``mag_lag_s=0``), 20 deg labels 8.7 s of
   undisturbed trial 08, 3.2 s of the vibration trial and 10-17 s of the
   stationary-magnet trials: fast turns, not the field.
"""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

from slam.config import InputConfig
from slam.errors import GslamError
from slam.readers.data_checks import EARTH_FIELD_UT
from validation.base.geometry import heading_from_magnetometer, wrap_angle
from slam.recording import Compass, Gyro, Interval, MagneticReference, Recording, Trajectory

log = logging.getLogger(__name__)

TILT_TIME_CONSTANT_S = 3.0
MAG_LAG_S = 0.012
MERGE_GAP_S = 0.5
MIN_FAULT_S = 0.5
REQUIRED = ("imu_gyr", "imu_acc", "imu_mag", "opt_quat", "sampling_rate")


def looks_like_broad(path: str | Path) -> bool:
    """A ``.mat`` file."""
    path = Path(path)
    return path.is_file() and path.suffix.lower() == ".mat"


def _load(path: Path) -> dict[str, np.ndarray]:
    from scipy.io import loadmat

    if not path.exists():
        raise GslamError(f"{path}: no such file")
    try:
        data = loadmat(str(path))
    except Exception as e:  # scipy raises assorted types (MatReadError, ValueError...) for foreign files
        if isinstance(e, MemoryError):
            raise
        reason = str(e).strip().splitlines()[0] if str(e).strip() else type(e).__name__
        raise GslamError(f"{path}: cannot read as a MATLAB v5 file ({reason})") from None
    for key in REQUIRED:
        if key not in data:
            raise GslamError(f"{path}: expected a BROAD trial with '{key}' ({', '.join(REQUIRED)})")
    n = len(data["imu_gyr"])
    if n < 2:
        raise GslamError(f"{path}: no samples; expected a BROAD trial with N x 3 IMU arrays")
    for key, width in (("imu_gyr", 3), ("imu_acc", 3), ("imu_mag", 3), ("opt_quat", 4), ("opt_pos", 3)):
        if key not in data:  # opt_pos: a trial without positions has its heading truth still
            continue
        a = _real(path, key, data[key])
        if a.shape != (n, width):
            raise GslamError(f"{path}: {key}: expected shape ({n}, {width}), got {a.shape}")
        data[key] = a
    if np.asarray(data["sampling_rate"]).size != 1:
        raise GslamError(f"{path}: sampling_rate: expected one IMU rate in Hz (BROAD's is 285.7), got "
                         f"{np.asarray(data['sampling_rate']).size} values")
    return data


_KINDS = {"c": "complex numbers", "U": "text", "S": "text", "O": "a cell array or a struct", "V": "a struct",
          "b": "true/false values"}


def _real(path: Path, key: str, value: object) -> np.ndarray:
    """``value`` as float64, or a one-line :class:`GslamError` naming
    ``key`` if MATLAB stored something else (text, complex numbers, cells):
    numpy would raise on text and drop an imaginary part in silence."""
    a = np.asarray(value)
    if a.dtype.kind not in "iuf":
        raise GslamError(f"{path}: {key}: expected real numbers, got {_KINDS.get(a.dtype.kind, str(a.dtype))}")
    return a.astype(np.float64)


def up_direction(acc: np.ndarray, gyr: np.ndarray, dt: float, time_constant_s: float = TILT_TIME_CONSTANT_S) -> np.ndarray:
    """Unit up vectors (n, 3) in the IMU frame from a complementary filter:
    gyro propagation corrected towards the normalised accelerometer
    (specific force points up at rest) with time constant ``time_constant_s``."""
    a = acc / np.linalg.norm(acc, axis=1, keepdims=True)
    alpha = min(1.0, dt / time_constant_s)
    w = gyr * dt
    out = np.empty_like(a)
    ux, uy, uz = a[0]
    # Plain floats: a numpy call per 3-vector would cost ten times more.
    for k, ((wx, wy, wz), (ax, ay, az)) in enumerate(zip(w.tolist(), a.tolist())):
        # A world-fixed vector seen from a frame rotating by w: u -= w x u.
        ux, uy, uz = ux - (wy * uz - wz * uy), uy - (wz * ux - wx * uz), uz - (wx * uy - wy * ux)
        ux, uy, uz = ux + alpha * (ax - ux), uy + alpha * (ay - uy), uz + alpha * (az - uz)
        norm = (ux * ux + uy * uy + uz * uz) ** 0.5
        ux, uy, uz = ux / norm, uy / norm, uz / norm
        out[k] = ux, uy, uz
    return out


def roll_pitch(up: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """ZYX roll and pitch (n,) rad of the tilt given by unit up vectors (n, 3)
    in the IMU frame."""
    return np.arctan2(up[:, 1], up[:, 2]), np.arctan2(-up[:, 0], np.hypot(up[:, 1], up[:, 2]))


def gyro_heading(gyr: np.ndarray, up: np.ndarray, dt: float) -> np.ndarray:
    """The gyro's own heading (n,), rad, unwrapped, from 0: the ZYX yaw of an
    attitude propagated by the gyro, whose tilt is pulled onto the filtered
    ``up`` after every sample by the smallest rotation (about a horizontal
    axis, which leaves the heading alone to first order).

    This is the heading the compass and the optical truth measure (ZYX yaw).
    The rate about the vertical, ``gyr . up``, is not: the two differ by
    ``roll_rate * sin(pitch)``, large when the hand rolls the board while
    pitched, and near pitch +-90 deg the ZYX yaw turns by up to 180 deg,
    which the attitude follows and a rate about the vertical misses.
    """
    n = len(gyr)
    yaw = np.empty(n)
    qw, qx, qy, qz = 1.0, 0.0, 0.0, 0.0
    # Start level with the filter's first tilt: roll and pitch from up[0].
    roll0, pitch0 = (float(a[0]) for a in roll_pitch(up[:1]))
    cr, sr, cp, sp = np.cos(roll0 / 2), np.sin(roll0 / 2), np.cos(pitch0 / 2), np.sin(pitch0 / 2)
    qw, qx, qy, qz = cp * cr, cp * sr, sp * cr, -sp * sr  # R_y(pitch) R_x(roll), ZYX with yaw 0
    for k, ((wx, wy, wz), (ux, uy, uz)) in enumerate(zip((gyr * (0.5 * dt)).tolist(), up.tolist())):
        if k:
            # q <- q * (1, w dt / 2), body-frame rates, then renormalised.
            qw, qx, qy, qz = (
                qw - qx * wx - qy * wy - qz * wz,
                qx + qw * wx + qy * wz - qz * wy,
                qy + qw * wy + qz * wx - qx * wz,
                qz + qw * wz + qx * wy - qy * wx,
            )
        # v = R(q) up: the filter's up in the world; rotate it onto e_z.
        vx = (1 - 2 * (qy * qy + qz * qz)) * ux + 2 * (qx * qy - qw * qz) * uy + 2 * (qx * qz + qw * qy) * uz
        vy = 2 * (qx * qy + qw * qz) * ux + (1 - 2 * (qx * qx + qz * qz)) * uy + 2 * (qy * qz - qw * qx) * uz
        vz = 2 * (qx * qz - qw * qy) * ux + 2 * (qy * qz + qw * qx) * uy + (1 - 2 * (qx * qx + qy * qy)) * uz
        # Shortest rotation from v to e_z: quaternion (1 + vz, vy, -vx, 0), normalised; c * q.
        cw, cx, cy = 1.0 + vz, vy, -vx
        qw, qx, qy, qz = (
            cw * qw - cx * qx - cy * qy,
            cw * qx + cx * qw + cy * qz,
            cw * qy - cx * qz + cy * qw,
            cw * qz + cx * qy - cy * qx,
        )
        norm = (qw * qw + qx * qx + qy * qy + qz * qz) ** 0.5
        qw, qx, qy, qz = qw / norm, qx / norm, qy / norm, qz / norm
        yaw[k] = np.arctan2(2 * (qw * qz + qx * qy), 1 - 2 * (qy * qy + qz * qz))
    return np.unwrap(yaw)


def level_field(mag: np.ndarray, up: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The field (n, 3) rotated from the IMU frame into the level frame
    (same heading, z up), and the ZYX pitch (n,) rad of the tilt ``up``."""
    roll, pitch = roll_pitch(up)
    cr, sr, cp, sp = np.cos(roll), np.sin(roll), np.cos(pitch), np.sin(pitch)
    mx, my, mz = mag[:, 0], mag[:, 1], mag[:, 2]
    # R_y(pitch) R_x(roll) m: undo roll, then pitch.
    y = cr * my - sr * mz
    z1 = sr * my + cr * mz
    x = cp * mx + sp * z1
    z = -sp * mx + cp * z1
    return np.column_stack([x, y, z]), pitch


def _truth_up(quat_wxyz: np.ndarray) -> np.ndarray:
    """World up (0, 0, 1) in the IMU frame for IMU-to-world quaternions:
    the third row of the rotation matrix."""
    w, x, y, z = quat_wxyz.T
    return np.column_stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)])


def _intervals(t: np.ndarray, flag: np.ndarray) -> list[Interval]:
    """Runs of ``flag`` as (start, end) s, gaps < MERGE_GAP_S bridged,
    runs < MIN_FAULT_S dropped."""
    if not flag.any():
        return []
    edges = np.flatnonzero(np.diff(np.concatenate([[0], flag.astype(np.int8), [0]])))
    runs = [[t[a], t[b - 1]] for a, b in zip(edges[::2], edges[1::2])]
    merged = [runs[0]]
    for start, end in runs[1:]:
        if start - merged[-1][1] < MERGE_GAP_S:
            merged[-1][1] = end
        else:
            merged.append([start, end])
    return [(float(a), float(b)) for a, b in merged if b - a >= MIN_FAULT_S]


GRAVITY_M_S2 = (4.9, 19.6)
"""The median of ``|imu_acc|`` (m/s^2) over a trial: an IMU held on the
Earth reads gravity, 9.81, whatever it does (BROAD's trials: 9.82-9.95);
half or twice that is no accelerometer in m/s^2 (one in g reads 1)."""
FIELD_UT = EARTH_FIELD_UT
"""The median of ``|imu_mag|`` (uT) over a trial, as every recording's field."""
MAX_GYRO_RAD_S = 1000.0
"""rad/s on any axis (as :data:`slam.readers.data_checks.MAX_YAW_RATE`):
gyroscopes saturate at a few thousand deg/s (BROAD's trials reach 24)."""


def check_imu_physics(path: Path, gyr: np.ndarray, acc: np.ndarray, mag: np.ndarray) -> None:
    """One-line errors for IMU samples no IMU on the Earth gives: no
    gravity, no Earth field (or one of a tesla), rates beyond any gyro."""
    g = float(np.median(np.linalg.norm(acc, axis=1)))
    if not GRAVITY_M_S2[0] <= g <= GRAVITY_M_S2[1]:
        raise GslamError(f"{path}: imu_acc: median magnitude {g:.3g} m/s^2, expected gravity (9.81 m/s^2, within "
                         f"{GRAVITY_M_S2[0]:g} to {GRAVITY_M_S2[1]:g}): an IMU on the Earth reads it (in g?)")
    b = float(np.median(np.linalg.norm(mag, axis=1)))
    if not FIELD_UT[0] <= b <= FIELD_UT[1]:
        raise GslamError(f"{path}: imu_mag: median magnitude {b:.3g} uT, expected the Earth's field (22-67 uT, "
                         f"within {FIELD_UT[0]:g} to {FIELD_UT[1]:g}; in tesla or nT?)")
    fastest = np.abs(gyr).max(axis=1)
    if fastest.max() > MAX_GYRO_RAD_S:
        i = int(np.argmax(fastest > MAX_GYRO_RAD_S))
        raise GslamError(f"{path}: imu_gyr at sample {i} is {fastest[i]:.3g} rad/s; no gyroscope measures more than "
                         f"{MAX_GYRO_RAD_S:g} rad/s (in deg/s or mrad/s?)")


def read_broad(
    path: str | Path,
    config: InputConfig | None = None,
    reference_s: float = 5.0,
    fault_threshold_deg: float = 20.0,
    max_pitch_deg: float = 60.0,
    mag_lag_s: float = MAG_LAG_S,
) -> Recording:
    """Read a BROAD trial into a :class:`Recording` with ``gyro`` (rate of
    the gyro's ZYX heading), ``compass`` (tilt-compensated heading, field in tesla in
    the level frame), ``groundtruth``, ``magnetic_reference`` and
    ``faults["IMU_YAW"]``, as described in the module docstring. Times are
    seconds from the first sample (``t0`` = 0: the files carry no clock).

    ``config`` is accepted for the reader interface; its compass
    declination and mounting are not used, the heading offset is estimated.
    ``mag_lag_s``: how late the magnetometer's samples are stamped (step 0).
    """
    path = Path(path)
    d = _load(path)
    rate = np.asarray(d["sampling_rate"]).ravel()
    try:
        fs = float(rate[0])
    except (TypeError, ValueError, IndexError):  # a string, a struct, an empty array
        fs = None
    if fs is None or not np.isfinite(fs) or not 1.0 <= fs <= 100_000.0:
        got = f"{fs:g}" if fs is not None else (repr(rate[0].item()) if rate.size else "nothing")
        raise GslamError(f"{path}: sampling_rate: expected an IMU's rate in Hz (1 to 100000; BROAD's is 285.7), got {got}")
    gyr, acc, mag, quat = d["imu_gyr"], d["imu_acc"], d["imu_mag"], d["opt_quat"]
    n = len(gyr)
    for name, values in (("imu_gyr", gyr), ("imu_acc", acc), ("imu_mag", mag)):  # as stored, before any lag
        bad = ~np.isfinite(values)
        if bad.any():
            k, axis = np.argwhere(bad)[0]
            count = int(bad.any(axis=1).sum())
            raise GslamError(f"{path}: imu_gyr/imu_acc/imu_mag: expected finite samples; {name} at sample {k} "
                             f"(t = {k / fs:.3f} s) is {values[k, axis]} on axis {'xyz'[axis]} ({count:,} of "
                             f"{len(values):,} samples not finite)")
    # 0: the magnetometer's sample stamped t + mag_lag_s was measured at t.
    if mag_lag_s:
        mag = np.column_stack([np.interp(np.arange(n) / fs + mag_lag_s, np.arange(n) / fs, m) for m in mag.T])
    check_imu_physics(path, gyr, acc, mag)
    t = np.arange(n) / fs
    tracked = np.isfinite(quat).all(axis=1)
    if not tracked.any():
        raise GslamError(f"{path}: opt_quat: no tracked sample (all NaN)")
    norm = np.linalg.norm(np.where(tracked[:, None], quat, 1.0 / 2.0), axis=1)
    if np.any(np.abs(norm - 1.0) > 0.1):
        i = int(np.argmax(np.abs(norm - 1.0) > 0.1))
        raise GslamError(f"{path}: opt_quat at sample {i} is not a rotation (quaternion of norm {norm[i]:.3g}, "
                         "expected 1)")
    max_pitch = np.radians(max_pitch_deg)

    # 1-2: tilt and the rate about the vertical.
    # The trials start at rest: the mean rate over the first reference_s
    # seconds is the gyro's bias (0.1-0.5 deg/s about z, stable over a trial).
    gyr = gyr - gyr[t < reference_s].mean(axis=0)
    up = up_direction(acc, gyr, 1.0 / fs)
    gyro = Gyro(t=t, rate=np.gradient(gyro_heading(gyr, up, 1.0 / fs), t))

    # 3-4: compass and truth headings, ZYX yaw, in rad.
    field_level, pitch = level_field(mag * 1e-6, up)
    heading = heading_from_magnetometer(field_level)
    q = np.where(tracked[:, None], quat, [1.0, 0.0, 0.0, 0.0])
    w, x, y, z = q.T
    true_yaw = np.arctan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    field_true_tilt, true_pitch = level_field(mag * 1e-6, _truth_up(q))
    # The first reference_s seconds of tracking (some trials start untracked).
    start = tracked & (t < t[np.argmax(tracked)] + reference_s)
    offset = float(np.angle(np.mean(np.exp(1j * (heading[start] - true_yaw[start])))))
    log.info("%s: compass heading offset to the optical frame %.2f deg", path, np.degrees(offset))
    keep = np.abs(pitch) <= max_pitch
    compass = Compass(t=t[keep], yaw=wrap_angle(heading[keep] - offset), field=field_level[keep])

    good = tracked & (np.abs(true_pitch) <= max_pitch)
    pos = d["opt_pos"] if "opt_pos" in d else np.zeros((n, 3))
    good &= np.isfinite(pos).all(axis=1)
    if not good.any():  # a trial must have its truth: the headings are scored against it
        raise GslamError(f"{path}: opt_quat/opt_pos: no sample has a tracked pose (finite opt_quat and opt_pos) with "
                         f"the pitch within {max_pitch_deg:g} deg; expected a BROAD trial with its optical truth")
    groundtruth = Trajectory(t=t[good], x=pos[good, 0], y=pos[good, 1], yaw=true_yaw[good])

    # 5: the undisturbed field at the start.
    rest = t < reference_s
    strength = np.linalg.norm(field_level[rest], axis=1)
    dip = np.arctan2(-field_level[rest, 2], np.hypot(field_level[rest, 0], field_level[rest, 1]))
    reference = MagneticReference(strength_T=float(np.median(strength)), dip_rad=float(np.median(dip)))

    # 6: label where the magnetometer itself is wrong.
    true_offset = float(np.angle(np.mean(np.exp(1j * (heading_from_magnetometer(field_true_tilt[start]) - true_yaw[start])))))
    error = wrap_angle(heading_from_magnetometer(field_true_tilt) - true_offset - true_yaw)
    wrong = good & (np.abs(error) > np.radians(fault_threshold_deg))
    faults = {"IMU_YAW": _intervals(t, wrong)}

    rec = Recording(
        name=path.stem,
        t0=0.0,
        gyro=gyro,
        compass=compass,
        groundtruth=groundtruth,
        faults=faults,
        magnetic_reference=reference,
    )
    log.info(
        "%s: %d samples at %.1f Hz, %.1f s, %d compass faults over %.1f s",
        path, n, fs, rec.duration, len(faults["IMU_YAW"]), sum(b - a for a, b in faults["IMU_YAW"]),
    )
    return rec
