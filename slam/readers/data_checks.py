"""Physics checks on what a reader read, whatever the format.

Every recording passes through :func:`check_recording` before anything
uses it (:func:`slam.readers.read.read_recording`). What cannot be physical
is a one-line error naming the file, the stream and where; what is odd but
still usable is a one-line warning and the data are used as the warning
says. The thresholds leave every shipped and real recording under
``../shared/data`` without a word (tests/test_data_checks.py).

* **Time offsets** (``input.time_offsets_s``) as long as the recording
  would move a stream off it: an error naming the key.
* **Stamps**: a stream whose time goes back (two recordings in one file,
  a clock reset), one that jumps forward by more than the rest of the
  recording lasts (a clock jump, recordings joined), and streams whose
  spans do not overlap (different clocks): errors.
* **Laser scans**: beam angles that do not turn, lie closer than a thousandth of a
  degree (:data:`MIN_BEAM_STEP_RAD`) or span more than a full
  circle, or are not angles in radians: errors. Negative ranges and ranges
  no laser measures (beyond :data:`MAX_RANGE_M`): a warning, taken as no
  return. A laser whose every beam is out of its own limits returns
  nothing, or has fewer than :data:`MIN_BEAMS` beams: a warning, and the
  scans are left out (no scan-matching factor from an empty scan).
* **Yaw rates** beyond :data:`MAX_YAW_RATE`: an error.
* **Fields and fixes**: a magnetometer whose median field is not the
  Earth's (:data:`EARTH_FIELD_UT`), a GPS fix whose sigma is beyond
  :data:`MAX_GPS_SIGMA_M`: errors.
"""

from __future__ import annotations

import logging
import math

import numpy as np

from slam.errors import GslamError
from slam.recording import Recording

log = logging.getLogger(__name__)

MAX_RANGE_M = 10_000.0
"""Ranges beyond this are no measurement (the longest 2D lidars reach a few km)."""
MIN_BEAMS = 3
"""Fewer beams than this per scan cannot be matched."""
MIN_BEAM_STEP_RAD = math.radians(1e-3)
"""Beams closer than a thousandth of a degree: the finest 2D lasers are a
hundred times coarser (0.1-0.25 deg; the logs under ../shared/data 0.25-1)."""
MAX_YAW_RATE = 1000.0
"""rad/s (57,000 deg/s); gyroscopes saturate at a few thousand deg/s."""
MAX_POSE_M = 1e7
"""m: a pose farther from its frame's origin than a quarter of the Earth's
circumference is no local map frame."""
MAX_POSE_STEP_M = 1000.0
"""m between two consecutive poses of one stream: no ground robot covers a
kilometre between two samples of its odometry."""
EARTH_FIELD_UT = (2.0, 1000.0)
"""The median magnetic field strength (uT) of a recording: the Earth's field
is 22-67 uT everywhere (BROAD's trials, magnets beside them included:
42-46); a tenth of the weakest or fifteen times the strongest is no field
in uT (one in tesla reads 5e-5, one in nT 5e4) or no magnetometer that
works (a field of 0 has no heading)."""
MAX_GPS_SIGMA_M = 1e6
"""m: a fix known to no better than 1000 km says nothing (the bound of every
configured position sigma, :data:`validation.base.bounds.SIGMA_M`)."""
MIN_JUMP_S = 60.0
"""A forward jump shorter than this is a gap, never an error."""
STREAMS = ("scans", "gyro", "compass", "odometry", "gps", "groundtruth")
EXTRA = "extra_odometry."
"""Prefix of a further odometry source's name here (``extra_odometry.NAME``)."""


def key(stream: str) -> str:
    """The key of a stream's time offset in the config (``scans`` is
    ``input.time_offsets_s.scan``, a further odometry source has its own)."""
    if stream.startswith(EXTRA):
        return f"input.extra_odometry.{stream[len(EXTRA):]}.time_offset_s"
    return f"input.time_offsets_s.{'scan' if stream == 'scans' else stream}"


def check_time_offsets(rec: Recording, offsets: dict[str, float], source: object) -> None:
    """An offset (by stream: ``scan``, ``gyro``..., ``extra_odometry.NAME``)
    as long as the recording moves its stream off it: an error; one of more
    than a tenth of it leaves the stream a part: a warning (a lag is a
    fraction of a second; GPS time against UTC 18 s)."""
    span = _span(rec)
    streams = _streams(rec)
    for name, offset in offsets.items():
        stream = "scans" if name == "scan" else name
        if stream not in streams:
            continue
        if abs(offset) >= max(span, 1e-9):
            raise GslamError(f"{source}: {key(stream)} {offset:+g} s is as long as the recording "
                             f"({span:.3g} s) or longer: it would move the {name} stream off it; "
                             "expected the stream's lag, a fraction of a second")
        if abs(offset) > 0.1 * span:
            log.warning("%s: %s %+g s moves the %s stream by %.0f %% of the recording (%.3g s); "
                        "a lag is usually a fraction of a second", source, key(stream), offset, name,
                        100 * abs(offset) / span, span)


def _span(rec: Recording) -> float:
    starts = [s.t[0] for s in _streams(rec).values()]
    ends = [s.t[-1] for s in _streams(rec).values()]
    return float(max(ends) - min(starts)) if starts else 0.0


def _streams(rec: Recording) -> dict:
    """The streams with samples, further odometry sources included."""
    found = {n: getattr(rec, n) for n in STREAMS}
    found.update({f"{EXTRA}{n}": s for n, s in getattr(rec, "extra_odometry", {}).items()})
    return {n: s for n, s in found.items() if s is not None and len(s.t)}


def check_recording(rec: Recording, source: object, offsets: dict[str, float] | None = None) -> Recording:
    """Check ``rec`` as the module docstring says; it may leave the scans
    out (in place). ``offsets``: the time offsets applied, to name them."""
    check_stamps(rec, source, offsets or {})
    check_scans(rec, source)
    check_rates(rec, source)
    check_poses(rec, source)
    check_fields(rec, source)
    return rec


def check_poses(rec: Recording, source: object) -> None:
    """Poses (odometry, ground truth, further odometries) are finite, within
    :data:`MAX_POSE_M` of their origin and at most :data:`MAX_POSE_STEP_M`
    apart from one sample to the next."""
    streams = {"odometry": rec.odometry, "groundtruth": rec.groundtruth,
               **{f"odometry {name}": traj for name, traj in rec.extra_odometry.items()}}
    for name, traj in streams.items():
        if traj is None or not len(traj.t):
            continue
        xy = np.column_stack([traj.x, traj.y]).astype(np.float64)
        bad = ~np.isfinite(xy).all(axis=1) | ~np.isfinite(np.asarray(traj.yaw, dtype=np.float64))
        if bad.any():
            i = int(np.argmax(bad))
            raise GslamError(f"{source}: {name} pose {i} (t = {traj.t[i]:.3f} s) is not finite")
        far = np.abs(xy).max(axis=1) > MAX_POSE_M
        if far.any():
            i = int(np.argmax(far))
            raise GslamError(f"{source}: {name} pose {i} (t = {traj.t[i]:.3f} s) is at ({xy[i, 0]:.6g}, {xy[i, 1]:.6g}) m, "
                             f"beyond {MAX_POSE_M:g} m of its origin: no local map frame (the unit wrong?)")
        step = np.hypot(*np.diff(xy, axis=0).T) if len(xy) > 1 else np.zeros(0)
        if step.size and step.max() > MAX_POSE_STEP_M:
            i = int(np.argmax(step)) + 1
            raise GslamError(f"{source}: {name} pose {i} (t = {traj.t[i]:.3f} s) is {step[i - 1]:.6g} m from the one "
                             f"before; no robot moves more than {MAX_POSE_STEP_M:g} m between two samples")


def check_rates(rec: Recording, source: object) -> None:
    """A yaw rate no gyroscope measures is no measurement."""
    if rec.gyro is None or not len(rec.gyro.rate):
        return
    rate = np.abs(np.asarray(rec.gyro.rate, dtype=np.float64))
    if not np.all(np.isfinite(rate)):
        raise GslamError(f"{source}: gyro rate {int(np.argmin(np.isfinite(rate)))} is not a finite number")
    if rate.max() > MAX_YAW_RATE:
        i = int(np.argmax(rate))
        raise GslamError(f"{source}: gyro rate {i} is {rec.gyro.rate[i]:.6g} rad/s; no gyroscope measures more than "
                         f"{MAX_YAW_RATE:g} rad/s (the unit wrong?)")


def check_fields(rec: Recording, source: object) -> None:
    """A magnetometer reads the Earth's field (:data:`EARTH_FIELD_UT`); a
    GPS fix's sigma is at most :data:`MAX_GPS_SIGMA_M` (NaN: unknown)."""
    field = rec.compass.field if rec.compass is not None else None
    if field is not None and len(field):
        b = float(np.median(np.linalg.norm(np.asarray(field, dtype=np.float64), axis=1))) * 1e6
        if not EARTH_FIELD_UT[0] <= b <= EARTH_FIELD_UT[1]:
            raise GslamError(f"{source}: compass: median field {b:.3g} uT, expected the Earth's (22-67 uT, within "
                             f"{EARTH_FIELD_UT[0]:g} to {EARTH_FIELD_UT[1]:g}; in tesla, as a MagneticField is?)")
    if rec.gps is not None and len(rec.gps.t):
        sigma = np.asarray(rec.gps.sigma, dtype=np.float64)
        with np.errstate(invalid="ignore"):
            far = sigma > MAX_GPS_SIGMA_M
        if far.any():
            i = int(np.argmax(far))
            raise GslamError(f"{source}: gps fix {i} has a sigma of {sigma[i]:.3g} m; one beyond "
                             f"{MAX_GPS_SIGMA_M:g} m says nothing (a covariance in other units?)")


# --- stamps ------------------------------------------------------------------------

MIN_STAMP_S, MAX_STAMP_S = 0, 2**31 - 1
"""The seconds since 1970 a result can carry: a ROS 2 time's ``sec`` is an
int32 (up to 2038-01-19), and the log time of every message of ``run.mcap``
(and of a ROS 1 bag) is unsigned, so nothing before 1970. A stamp before
1970 was read, mapped, and then failed the writing of ``run.mcap``."""


def check_absolute_stamps(t: np.ndarray, where: str) -> None:
    """Absolute stamps (s since 1970) must be times a ROS 2 bag can hold."""
    if not len(t):
        return
    bad = np.flatnonzero((t < MIN_STAMP_S) | (t > MAX_STAMP_S))
    if len(bad):
        i = int(bad[0])
        raise GslamError(f"{where} stamp {i} is {t[i]:.6g} s since 1970; expected {MIN_STAMP_S} to {MAX_STAMP_S} s "
                         "(1970 to 2038, what a ROS 2 time holds and a bag's log time, which starts in 1970): a stamp "
                         "in another unit, or a corrupt log?")



def check_stamps(rec: Recording, source: object, offsets: dict[str, float]) -> None:
    streams = _streams(rec)
    for name, s in streams.items():
        t = np.asarray(s.t, dtype=np.float64)
        if not np.all(np.isfinite(t)):
            raise GslamError(f"{source}: {name} stamp {int(np.argmin(np.isfinite(t)))} is not a finite time")
        steps = np.diff(t)
        if len(steps) and steps.min() < 0:  # first: a clock reset may also reach before 1970
            i = int(np.argmin(steps)) + 1
            raise GslamError(f"{source}: {name} time goes back by {-steps[i - 1]:.6g} s at sample {i} "
                             f"(t = {t[i]:.3f} s after {t[i - 1]:.3f} s): two recordings in one, or a clock reset? "
                             "Expected increasing stamps")
        check_absolute_stamps(rec.t0 + t, f"{source}: {name}")
        if len(t) < 2:
            continue
        i = int(np.argmax(steps))
        jump, rest = float(steps[i]), float(t[-1] - t[0] - steps[i])
        if jump > MIN_JUMP_S and jump > rest:
            raise GslamError(f"{source}: {name} stamps jump forward by {jump:.6g} s at sample {i + 1} "
                             f"(t = {t[i + 1]:.3f} s after {t[i]:.3f} s), longer than the rest of the stream "
                             f"({rest:.3g} s): a clock jump, or recordings joined? Map the parts one by one")
    if len(streams) < 2:
        return
    for name, s in streams.items():
        others = [o for n, o in streams.items() if n != name]
        start, end = min(o.t[0] for o in others), max(o.t[-1] for o in others)
        if s.t[0] > end or s.t[-1] < start:
            moved = offsets.get("scan" if name == "scans" else name, 0.0)
            by = f", moved by {key(name)} {moved:+g} s" if moved else ""
            raise GslamError(f"{source}: {name} stamps ({s.t[0]:.6g} to {s.t[-1]:.6g} s{by}) do not overlap the other "
                             f"streams' ({start:.6g} to {end:.6g} s): a stream on another clock? ({key(name)}, or "
                             "leave the stream out of input.topics)")


# --- laser scans -------------------------------------------------------------------


def check_scans(rec: Recording, source: object) -> None:
    scans = rec.scans
    if scans is None or len(scans) == 0:
        return
    where = f"{source}: laser scans"
    n_beams = scans.ranges.shape[1] if scans.ranges.ndim == 2 else 0
    if n_beams == 0:
        raise GslamError(f"{where} have no beams")
    if n_beams < MIN_BEAMS:
        log.warning("%s: %d beam%s per scan, too few to match scans (at least %d); the scans are left out, so no "
                    "scan-matching factor and no loop closing from them", where, n_beams, "s" if n_beams > 1 else "", MIN_BEAMS)
        rec.scans = None
        return
    angles = np.asarray(scans.angles, dtype=np.float64)
    if not np.all(np.isfinite(angles)):
        raise GslamError(f"{where}: beam angles are not finite")
    if n_beams > 1:
        steps = np.diff(angles)
        if np.any(steps == 0):
            raise GslamError(f"{where}: {n_beams} beams, two at the same angle (angle_increment 0?); expected beams "
                             "that turn")
        step = float(np.median(np.abs(steps)))
        span = float(abs(angles[-1] - angles[0]))
        if step < MIN_BEAM_STEP_RAD:
            raise GslamError(f"{where}: {n_beams} beams {math.degrees(step):.3g} deg apart span "
                             f"{math.degrees(span):.3g} deg; no 2D laser resolves a thousandth of a degree (a field "
                             "of view or increment in other units?)")
        if span > 2 * math.pi + 1.5 * step:
            raise GslamError(f"{where}: {n_beams} beams {math.degrees(step):.6g} deg apart span "
                             f"{math.degrees(span):.6g} deg; a 2D laser sees at most 360 deg (the increment in degrees?)")
    if np.max(np.abs(angles)) > 4 * math.pi:
        raise GslamError(f"{where}: beam angles reach {np.max(np.abs(angles)):.6g} rad; expected angles in radians "
                         "within a turn or two of 0")
    _check_ranges(rec, where)


def _check_ranges(rec: Recording, where: str) -> None:
    scans = rec.scans
    r = scans.ranges
    with np.errstate(invalid="ignore", over="ignore"):
        finite = np.isfinite(r)
        negative = finite & (r < 0)
        beyond = finite & (r > MAX_RANGE_M)
    total = r.size
    for mask, what in ((negative, "negative"), (beyond, f"beyond {MAX_RANGE_M:g} m (no laser measures that far)")):
        n = int(mask.sum())
        if n:
            worst = float(np.min(r[mask])) if what == "negative" else float(np.max(r[mask]))
            log.warning("%s: %d of %d ranges (%.3g %%) are %s, up to %.6g m; taken as no return",
                        where, n, total, 100.0 * n / total, what, worst)
    if beyond.any():
        scans.ranges = np.where(beyond, np.float32(np.inf), r).astype(r.dtype, copy=False)
    if math.isfinite(scans.range_max) and scans.range_max > MAX_RANGE_M:  # inf: no limit, as REP-117 allows
        log.warning("%s: the laser's range limit is %.6g m, beyond %g m (no laser measures that far); taken as %g m",
                    where, scans.range_max, MAX_RANGE_M, MAX_RANGE_M)
        scans.range_max = MAX_RANGE_M
    lo, hi = float(scans.range_min), float(scans.range_max)
    with np.errstate(invalid="ignore"):
        usable = finite & ~beyond & (r >= max(lo, 0.0)) & (r < hi) & (r > 0)
    if usable.any():
        return
    if not (finite & ~beyond).any():
        why = "no range is a finite distance"
    elif not (finite & (r > 0)).any():
        why = "every range is 0 or negative"
    elif not math.isfinite(hi) or hi <= 0 or lo >= hi:
        why = f"its range limits are [{lo:g}, {hi:g}] m"
    else:
        why = f"every range is outside its limits [{lo:g}, {hi:g}] m"
    log.warning("%s: the laser returns nothing (%s); the scans are left out, so no scan-matching factor and no "
                "loop closing from them", where, why)
    rec.scans = None
