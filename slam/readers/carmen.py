"""Reader for CARMEN text logs (plain or gzip'd), e.g. the Radish / Freiburg
"corrected" logs.

Lines used (everything else is ignored)::

    FLASER n r_1..r_n x y theta odom_x odom_y odom_theta ts host logger_ts
    ROBOTLASER1 type start_angle fov resolution max_range accuracy
                remission_mode n r_1..r_n m rem_1..rem_m laser_x laser_y
                laser_theta robot_x robot_y robot_theta tv rv fwd side
                turn_axis ts host logger_ts
    ODOM x y theta tv rv accel ts host logger_ts
    PARAM name value ...

What becomes of them:

* **Scans.** FLASER beams span 180 deg from -90 deg (right) in steps of
  ``180 / n`` deg for an even count (180, 360 beams: the last beam is one
  step short of +90 deg) and ``180 / (n - 1)`` deg for an odd count (181,
  361: both ends included), as CARMEN and GMapping read them; PARAM
  ``laser_front_laser_fov`` changes the 180 deg (in degrees, or in radians
  where the value is at most 2 pi: csail writes 3.14159). ROBOTLASER1 lines carry
  their own start angle, step and maximum range. ``range_max``: PARAM
  ``robot_front_laser_max`` if given, else just below the largest reading of
  the log (1 % less), because these logs encode "no return" as the
  scanner's saturation value (81.91, 81.83, 50.0, 51.1 or 32.767 m
  depending on the log), and the front-end drops beams at or beyond
  ``range_max``. A range limit no laser has (NaN, 0 or below, in the
  PARAM or a ROBOTLASER1 line) is an error naming the line.
* **Reference.** In "corrected" logs the pose on a scan line is the
  SLAM-corrected laser pose: it becomes ``Recording.groundtruth`` (a good
  SLAM result, not an independent ground truth).
* **Raw odometry.** After each scan the log repeats the corrected pose in an
  ``ODOM`` line and then adds raw odometry increments from that pose. The
  raw step between scans k and k+1 is ``inverse(corrected_k) * last ODOM
  before scan k+1``; the steps are chained from the first corrected pose
  into ``Recording.odometry`` at the scan times. A step without any raw ODOM
  line after the repeat has no odometry reading (seattle: one step, an 80 deg
  turn in place): the odometry trajectory has no sample at the scan after
  it, so that step is a gap, not a fake "no motion". When most steps have no
  reading (orebro: 219 of 236) the odometry stream is left out with a
  warning.
* **Times.** The scan's ``ts`` field, relative to the first scan. Logs whose
  stamps are unusable (belgioioso, orebro: all zero; csail: printed with six
  significant digits, so hundreds of scans share one stamp; infinite-corridor:
  equal stamps and a 2^32 wrap) are recognised by more than
  ``MAX_BAD_STEP_FRACTION`` of non-increasing steps; their times are
  synthesised from the scan order at ``NOMINAL_SCAN_PERIOD_S`` with a
  warning (they are then not physical seconds). A few stamps that step back
  (intel: 4 of 909, by up to 0.9 s) are moved just after their predecessor,
  with a warning.

Errors are one line: ``FILE:LINE: expected ...`` for a malformed line. Every
numeric field of a line read must be a finite number, used or not (an
ODOM line's velocities, a ROBOTLASER1's remissions): the error names the
field.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from slam.config import InputConfig
from slam.errors import GslamError
from validation.base.geometry import wrap_angle
from slam.readers.data_checks import MAX_RANGE_M
from slam.readers.files import NOT_PLAIN, log_lines, plain, unplain_number
from validation.base.yamlio import check_regular_file
from slam.recording import relative_poses
from slam.recording import Recording, Scans, Trajectory

log = logging.getLogger(__name__)

NOMINAL_SCAN_PERIOD_S = 1.0
MAX_BAD_STEP_FRACTION = 0.1
MAX_MISSING_ODOMETRY_FRACTION = 0.5
MIN_STAMP_STEP_S = 1e-3
MAX_ANGLE_RAD = 1e5
"""Largest pose angle read (unwrapped odometry turns many times, not 16,000 times)."""
MAX_STEP_BACK_S = 10.0
"""A scan stamp stepping back further is not jitter (intel's reach 0.9 s)."""
DEFAULT_FOV_DEG = 180.0
SUFFIXES = (".log", ".log.gz", ".clf", ".clf.gz")

_FLASER = "FLASER n r_1..r_n x y theta odom_x odom_y odom_theta ts host logger_ts"
_ROBOTLASER1 = "ROBOTLASER1 type start fov resolution max_range accuracy mode n r_1..r_n m rem_1..rem_m poses ... ts"
_ODOM = "ODOM x y theta tv rv accel ts host logger_ts"


def looks_like_carmen(path: str | Path) -> bool:
    """A file named ``*.log``/``*.clf`` (optionally ``.gz``)."""
    path = Path(path)
    return path.is_file() and path.name.lower().endswith(SUFFIXES)


@dataclass
class _Log:
    """What one pass over the file collects."""

    ranges: list[np.ndarray] = field(default_factory=list)
    poses: list[tuple[float, float, float]] = field(default_factory=list)
    stamps: list[float] = field(default_factory=list)
    last_odom: list[tuple[float, float, float] | None] = field(default_factory=list)
    raw_readings: list[int] = field(default_factory=list)
    lines: list[int] = field(default_factory=list)  # of each scan
    params: dict[str, str] = field(default_factory=dict)
    angles: np.ndarray | None = None
    range_max: float | None = None


def _open_lines(path: Path) -> Iterator[str]:
    check_regular_file(path, "CARMEN log")
    return log_lines(path, "CARMEN text log")


def _floats(parts: list[str], where: str, expected: str, names: Callable[[int], str]) -> np.ndarray:
    """``parts`` as numbers, every one finite, used or not: a NaN the reader
    skips today is a corrupt line all the same. ``names(k)`` names field k
    of ``parts`` in the error."""
    try:
        values = np.array(parts, dtype=np.float64)
    except ValueError:
        raise GslamError(f"{where}: expected {expected}") from None
    odd = unplain_number(parts)
    if odd is not None:
        raise GslamError(f"{where}: expected {expected}; {names(odd)} is {parts[odd]!r}, {NOT_PLAIN}")
    bad = ~np.isfinite(values)
    if bad.any():
        k = int(np.argmax(bad))
        raise GslamError(f"{where}: expected finite numbers in {expected}; {names(k)} is {parts[k]}")
    return values


def _named(*fields: str) -> Callable[[int], str]:
    return lambda k: fields[k]


def _ranges_then(n: int, *fields: str) -> Callable[[int], str]:
    """Names of ``n`` ranges r_1..r_n followed by ``fields``."""
    return lambda k: f"r_{k + 1}" if k < n else fields[k - n]


def _count(parts: list[str], i: int, where: str, expected: str) -> int:
    try:
        n = int(parts[i])
    except (IndexError, ValueError):
        raise GslamError(f"{where}: expected {expected}") from None
    if not plain(parts[i]):
        raise GslamError(f"{where}: expected {expected}; the beam count is {parts[i]!r}, {NOT_PLAIN}")
    if n < 1:
        raise GslamError(f"{where}: expected a positive beam count in {expected}")
    return n


def _more(parts: list[str], fields: int, counts: str) -> str:
    """What a line with more fields than its counts say means."""
    return f"; more values than {counts} says (is {counts} the count of values given?)" if len(parts) > fields else ""


def _fov_rad(value: float) -> float:
    """PARAM ``laser_front_laser_fov`` in radians. CARMEN writes degrees
    (180, 100), but some logs write radians (csail: 3.14159 for its 180 deg
    SICK at 0.5 deg resolution); a field of view of at most 2 pi "degrees"
    is no scanner's, so such a value is taken as radians."""
    return value if value <= 2.0 * np.pi + 1e-6 else float(np.radians(value))


def _flaser_angles(n: int, fov_param: float) -> np.ndarray:
    fov = _fov_rad(fov_param)
    step = fov / (n - 1) if n % 2 == 1 and n > 1 else fov / n
    return -fov / 2.0 + step * np.arange(n)


def _add_scan(d: _Log, where: str, ranges: np.ndarray, angles: np.ndarray, pose, stamp: float, range_max) -> None:
    if d.angles is None:
        d.angles, d.range_max = angles, range_max
    elif len(angles) != len(d.angles) or not np.allclose(angles, d.angles):
        raise GslamError(f"{where}: expected {len(d.angles)} beams at the same angles as the first scan")
    with np.errstate(over="ignore"):  # a range beyond float32 is no return (inf), checked later
        d.ranges.append(ranges.astype(np.float32))
    d.poses.append(pose)
    d.stamps.append(stamp)
    d.lines.append(int(where.rsplit(":", 1)[1]))
    d.last_odom.append(None)
    d.raw_readings.append(-1)  # the next ODOM line repeats this pose


def _parse_flaser(d: _Log, parts: list[str], where: str) -> None:
    n = _count(parts, 1, where, _FLASER)
    if len(parts) < n + 11:
        raise GslamError(f"{where}: expected {_FLASER} ({n + 11} fields, got {len(parts)})")
    values = _floats(parts[2 : n + 9], where, _FLASER,
                     _ranges_then(n, "x", "y", "theta", "odom_x", "odom_y", "odom_theta", "ts"))
    if len(parts) > n + 11:  # n is not the number of ranges: every field after them would be read shifted
        raise GslamError(f"{where}: expected {_FLASER} ({n + 11} fields, got {len(parts)}){_more(parts, n + 11, 'n')}")
    given = d.params.get("laser_front_laser_fov", str(DEFAULT_FOV_DEG))
    try:
        fov = float(given)
        if not plain(given):
            raise ValueError(given)
    except ValueError:
        raise GslamError(f"{where}: expected a number in PARAM laser_front_laser_fov") from None
    if not 0.0 < fov <= 360.0:
        raise GslamError(f"{where}: PARAM laser_front_laser_fov {fov:g}: expected the laser's field of view, "
                         "more than 0 and at most 360 degrees")
    pose = (values[n], values[n + 1], values[n + 2])
    _add_scan(d, where, values[:n], _flaser_angles(n, fov), pose, values[n + 6], None)


def _parse_robotlaser(d: _Log, parts: list[str], where: str) -> None:
    n = _count(parts, 8, where, _ROBOTLASER1)
    try:
        m = int(parts[9 + n])
    except (IndexError, ValueError):
        raise GslamError(f"{where}: expected {_ROBOTLASER1}") from None
    if not plain(parts[9 + n]):
        raise GslamError(f"{where}: expected {_ROBOTLASER1}; the remission count is {parts[9 + n]!r}, {NOT_PLAIN}")
    tail = 10 + n + max(m, 0)  # laser pose, robot pose, tv rv fwd side turn_axis, ts
    if m < 0 or len(parts) < tail + 14:
        raise GslamError(f"{where}: expected {_ROBOTLASER1} ({tail + 14} fields, got {len(parts)})")
    head = _floats(parts[2:7], where, _ROBOTLASER1, _named("start", "fov", "resolution", "max_range", "accuracy"))
    ranges = _floats(parts[9 : 9 + n], where, _ROBOTLASER1, _ranges_then(n))
    _floats(parts[10 + n : tail], where, _ROBOTLASER1, lambda k: f"rem_{k + 1}")
    rest = _floats(parts[tail : tail + 12], where, _ROBOTLASER1, _named(
        "laser_x", "laser_y", "laser_theta", "robot_x", "robot_y", "robot_theta", "tv", "rv", "fwd", "side",
        "turn_axis", "ts"))
    if len(parts) > tail + 14:  # n or m is not the number of values: the poses after them would be read shifted
        raise GslamError(f"{where}: expected {_ROBOTLASER1} ({tail + 14} fields, got {len(parts)})"
                         + _more(parts, tail + 14, "n or m"))
    start, _fov, res, max_range, _accuracy = head
    _check_range_limit(parts[5], where, "ROBOTLASER1 max_range")
    angles = start + res * np.arange(n)
    _add_scan(d, where, ranges, angles, (rest[0], rest[1], rest[2]), rest[11], float(max_range))


def _parse_odom(d: _Log, parts: list[str], where: str) -> None:
    if len(parts) < 8:
        raise GslamError(f"{where}: expected {_ODOM}")
    x, y, theta, *_ = _floats(parts[1:8], where, _ODOM, _named("x", "y", "theta", "tv", "rv", "accel", "ts"))
    if d.poses:
        d.last_odom[-1] = (x, y, theta)
        d.raw_readings[-1] += 1


def _check_range_limit(given: str, where: str, name: str) -> None:
    """A laser's range limit no laser has (NaN, 0 or below) is an error, as
    a LaserScan's is: it left every scan out as "returns nothing". Text
    that is no number is left to :func:`_range_max`, which ignores it."""
    try:
        limit = float(given)
    except ValueError:
        return
    if math.isnan(limit) or (plain(given) and limit <= 0.0):
        raise GslamError(f"{where}: {name} {given}: expected the laser's maximum range in metres, above 0 "
                         "(inf: no limit)")


def _parse(path: Path) -> _Log:
    d = _Log()
    for lineno, line in enumerate(_open_lines(path), start=1):
        parts = line.split()
        if not parts:
            continue
        kind, where = parts[0], f"{path}:{lineno}"
        if kind == "FLASER":
            _parse_flaser(d, parts, where)
        elif kind == "ROBOTLASER1":
            _parse_robotlaser(d, parts, where)
        elif kind == "ODOM":
            _parse_odom(d, parts, where)
        elif kind == "PARAM":
            if len(parts) < 3:
                raise GslamError(f"{where}: expected PARAM name value ...")
            if parts[1] == "robot_front_laser_max":
                _check_range_limit(parts[2], where, "PARAM robot_front_laser_max")
            d.params[parts[1]] = parts[2]
    return d


# --- streams -------------------------------------------------------------


def chain_steps(start: np.ndarray, steps: np.ndarray) -> np.ndarray:
    """Poses (n + 1, 3) from ``start`` (x, y, yaw) and the relative steps
    (n, 3), each in the frame of the pose before it: ``P_k+1 = P_k * step_k``."""
    start = np.asarray(start, dtype=np.float64)
    yaw = start[2] + np.concatenate([[0.0], np.cumsum(steps[:, 2])])
    c, s = np.cos(yaw[:-1]), np.sin(yaw[:-1])
    dxy = np.column_stack([c * steps[:, 0] - s * steps[:, 1], s * steps[:, 0] + c * steps[:, 1]])
    xy = start[:2] + np.vstack([np.zeros((1, 2)), np.cumsum(dxy, axis=0)])
    return np.column_stack([xy, wrap_angle(yaw)])


def _raw_odometry_steps(d: _Log) -> tuple[np.ndarray, np.ndarray]:
    """Raw odometry steps (n - 1, 3) between consecutive scans in the frame
    of the earlier scan, and a mask (n - 1,) of the steps that had a raw
    reading (the others are the identity)."""
    corrected = np.asarray(d.poses, dtype=np.float64)
    has = np.array([o is not None and r >= 1 for o, r in zip(d.last_odom[:-1], d.raw_readings[:-1])], dtype=bool)
    last = np.array([o if o is not None else p for o, p in zip(d.last_odom[:-1], d.poses[:-1])], dtype=np.float64)
    steps = np.zeros((len(corrected) - 1, 3))
    if has.any():
        steps[has] = relative_poses(corrected[:-1][has], last.reshape(-1, 3)[has])
    return steps, has


def _odometry(path: Path, d: _Log, t: np.ndarray) -> Trajectory | None:
    n = len(d.poses)
    steps, has = _raw_odometry_steps(d)
    missing = int(np.sum(~has))
    if n > 1 and missing > MAX_MISSING_ODOMETRY_FRACTION * (n - 1):
        log.warning("%s: %d of %d scan steps have no raw odometry; odometry left out", path, missing, n - 1)
        return None
    if missing:
        log.warning("%s: %d of %d scan steps have no raw odometry; odometry has a gap there", path, missing, n - 1)
    poses = chain_steps(np.asarray(d.poses[0]), steps)
    # The scan after a step without a reading gets no odometry sample, so
    # the step shows as a gap (no measurement) rather than as "no motion".
    keep = np.concatenate([[True], has])
    return Trajectory(t=t[keep], x=poses[keep, 0], y=poses[keep, 1], yaw=poses[keep, 2])


def scan_times(path: Path, stamps: np.ndarray, lines: list[int] | None = None) -> tuple[float, np.ndarray]:
    """``(t0, t)``: scan times relative to the first scan, repaired or
    synthesised as described in the module docstring. A stamp that steps
    back by more than :data:`MAX_STEP_BACK_S` among increasing ones is a
    second log after the first (or a clock reset): an error naming its line
    (``lines``: each scan's)."""
    n = len(stamps)
    if n < 2:
        return float(stamps[0]), np.zeros(n)
    steps = np.diff(stamps)
    bad = int(np.sum(steps <= 0.0))
    unusable = unusable_stamps(stamps)
    if unusable is not None:
        log.warning("%s: %s", path, unusable)
        return 0.0, NOMINAL_SCAN_PERIOD_S * np.arange(n)
    back = int(np.argmin(steps))
    if -steps[back] > MAX_STEP_BACK_S:
        where = f"{path}:{lines[back + 1]}" if lines is not None else f"{path}: scan {back + 1}"
        raise GslamError(f"{where}: time goes back by {-steps[back]:.6g} s (from {stamps[back]:.6f} to "
                         f"{stamps[back + 1]:.6f}): two logs in one file, or a clock reset? Expected one run per file")
    t = stamps.astype(np.float64).copy()
    if bad:
        for k in range(1, n):
            t[k] = max(t[k], t[k - 1] + MIN_STAMP_STEP_S)
        moved = int(np.sum(t != stamps))
        log.warning("%s: %d scan stamps step back; %d stamps moved to %g s after their predecessor",
                    path, bad, moved, MIN_STAMP_STEP_S)
    return float(t[0]), t - t[0]


def unusable_stamps(stamps: np.ndarray) -> str | None:
    """Why :func:`scan_times` synthesises the times of these scan stamps
    (too many do not increase), or None where it keeps them."""
    n = len(stamps)
    bad = int(np.sum(np.diff(stamps) <= 0.0)) if n > 1 else 0
    if bad <= MAX_BAD_STEP_FRACTION * (n - 1):
        return None
    return (f"{bad} of {n - 1} scan stamps do not increase (zero or low-resolution stamps); "
            f"times synthesised at one scan per {NOMINAL_SCAN_PERIOD_S:.1f} s")


def _check_angles(path: Path, d: _Log) -> None:
    """Pose angles are radians, wrapped when read; they may be unwrapped
    (csail's reach 10.9), but beyond :data:`MAX_ANGLE_RAD` they are no
    angle in any unit."""
    theta = np.abs(np.array([p[2] for p in d.poses] + [o[2] for o in d.last_odom if o is not None]))
    worst = float(theta.max()) if theta.size else 0.0
    if worst > MAX_ANGLE_RAD:
        raise GslamError(f"{path}: pose angles reach {worst:.6g}; expected radians (CARMEN's theta)")


def _range_max(d: _Log, ranges: np.ndarray) -> float:
    if d.range_max is not None:
        return d.range_max
    param = d.params.get("robot_front_laser_max")
    if param is not None:
        try:
            if not plain(param):
                raise ValueError(param)
            return float(param)
        except ValueError:
            log.warning("PARAM robot_front_laser_max %r is not a number; ignored", param)
    # Ranges no laser measures are no return (slam.readers.data_checks), not the laser's reach.
    with np.errstate(invalid="ignore"):
        measured = ranges[np.isfinite(ranges) & (ranges <= MAX_RANGE_M)]
    return 0.99 * float(np.max(measured)) if measured.size else 0.0


def read_carmen(path: str | Path, config: InputConfig | None = None) -> Recording:
    """Read a CARMEN log into a :class:`Recording` with ``scans``,
    ``odometry`` (raw, recovered as in the module docstring, may be None) and
    ``groundtruth`` (the corrected poses), all at the scan times.

    ``config`` is accepted for the reader interface; CARMEN logs need no
    input options. Raises :class:`GslamError` (one line) for a missing,
    unreadable or malformed file and for a log without scans.
    """
    path = Path(path)
    if not path.exists():
        raise GslamError(f"{path}: no such file")
    if path.is_dir():
        raise GslamError(f"{path}: expected a CARMEN log file, got a directory")
    d = _parse(path)
    if not d.poses:
        raise GslamError(f"{path}: no FLASER or ROBOTLASER1 scans; expected a CARMEN laser log")
    ranges = np.vstack(d.ranges)
    _check_angles(path, d)
    t0, t = scan_times(path, np.asarray(d.stamps), d.lines)
    corrected = np.asarray(d.poses, dtype=np.float64)
    scans = Scans(t=t, ranges=ranges, angles=d.angles, range_min=0.0, range_max=_range_max(d, ranges))
    groundtruth = Trajectory(t=t.copy(), x=corrected[:, 0], y=corrected[:, 1], yaw=wrap_angle(corrected[:, 2]))
    rec = Recording(
        name=path.name.split(".")[0],
        t0=t0,
        scans=scans,
        odometry=_odometry(path, d, t),
        groundtruth=groundtruth,
        stamps_synthesised=unusable_stamps(np.asarray(d.stamps)),
    )
    log.info("%s: %d scans of %d beams over %.1f s", path, len(scans), ranges.shape[1], rec.duration)
    return rec
