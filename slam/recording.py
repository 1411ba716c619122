"""In-memory form of one recorded run, whatever it was read from.

Conventions used everywhere in the project:

* Times are float64 seconds relative to ``Recording.t0`` (the absolute UNIX
  time of the first message, also in seconds). TUM files written by the
  project carry absolute stamps ``t0 + t``.
* The world frame is ENU-like and planar: x east, y north, yaw measured from
  the x axis counter-clockwise, in radians, wrapped to (-pi, pi].
* The body frame follows REP-103: x forward, y left, z up.
* Component names (the diagnosis vocabulary) are the paper's, one per
  modality as in its Table 1: ``ODO_DIST`` and ``ODO_YAW`` (the distance
  and the turn the track odometry reports), ``IMU_GYRO`` (gyroscope),
  ``IMU_YAW`` (compass heading), ``SM_DIST``, ``SM_LAT`` and ``SM_YAW``
  (scan matching's motion along the robot's heading, sideways, and its
  turn), ``GPS``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from validation.base.geometry import wrap_angle

COMPONENTS: tuple[str, ...] = ("ODO_DIST", "ODO_YAW", "IMU_GYRO", "IMU_YAW", "SM_DIST", "SM_LAT", "SM_YAW", "GPS")

SENSOR_MODALITIES: dict[str, tuple[str, ...]] = {
    "ODO": ("ODO_DIST", "ODO_YAW"),
    "SM": ("SM_DIST", "SM_LAT", "SM_YAW"),
}
"""The modality components of a sensor with several; a fault label of the
whole sensor (``SM``) stands for all of them."""


def expand_sensor_labels(faults: dict[str, list]) -> dict[str, list]:
    """Fault intervals with whole-sensor labels (``SM``, ``ODO``) given to each
    of the sensor's modality components, merged with their own labels."""
    spans: dict[str, list] = {}
    for name, intervals in faults.items():
        for comp in SENSOR_MODALITIES.get(name, (name,)):
            spans.setdefault(comp, []).extend(tuple(iv) for iv in intervals)
    out: dict[str, list] = {}
    for comp, intervals in spans.items():
        merged: list[list[float]] = []
        for a, b in sorted(intervals):
            if merged and a <= merged[-1][1]:
                merged[-1][1] = max(merged[-1][1], b)
            else:
                merged.append([a, b])
        out[comp] = [(a, b) for a, b in merged]
    return out

Interval = tuple[float, float]


@dataclass
class Trajectory:
    """Planar poses over time: ``t`` (n,) s, ``x``/``y`` (n,) m, ``yaw`` (n,) rad."""

    t: np.ndarray
    x: np.ndarray
    y: np.ndarray
    yaw: np.ndarray

    def __len__(self) -> int:
        return len(self.t)

    def xy(self) -> np.ndarray:
        """Positions as an (n, 2) array."""
        return np.column_stack([self.x, self.y])


@dataclass
class Scans:
    """2D laser scans.

    ``ranges`` is (n, beams) float32 in metres; a beam without a return is
    ``inf`` (REP-117) or NaN, or a value outside [range_min, range_max].
    ``angles`` (beams,) are the beam angles in the laser frame, rad.
    """

    t: np.ndarray
    ranges: np.ndarray
    angles: np.ndarray
    range_min: float
    range_max: float

    def __len__(self) -> int:
        return len(self.t)


@dataclass
class Gyro:
    """Yaw rate about the body z axis: ``rate`` (n,) rad/s."""

    t: np.ndarray
    rate: np.ndarray


@dataclass
class Compass:
    """Heading of the robot in the world frame, ``yaw`` (n,) rad.

    ``field`` (n, 3) is the raw magnetic field in the body frame in tesla when
    the heading came from a magnetometer (None when it came from an IMU's
    orientation estimate); plausibility observers use its strength and dip.
    """

    t: np.ndarray
    yaw: np.ndarray
    field: np.ndarray | None = None


@dataclass
class Gps:
    """GPS fixes projected to the local world frame about a datum.

    ``x``/``y`` (n,) m; ``sigma`` (n,) m, the horizontal standard deviation
    reported by the receiver; ``status`` (n,) int, NavSatStatus (0 fix,
    1 SBAS, 2 GBAS; fixes without a position are dropped by the readers).
    """

    t: np.ndarray
    x: np.ndarray
    y: np.ndarray
    sigma: np.ndarray
    status: np.ndarray


@dataclass
class MagneticReference:
    """The undisturbed local Earth field: strength (T), dip (rad, positive
    downward, as in the northern hemisphere) and declination (rad, east
    positive)."""

    strength_T: float
    dip_rad: float
    declination_rad: float = 0.0


@dataclass
class PlaceMatches:
    """Loop closures a recording lists (e.g. libRSF ``loop`` lines): at
    ``t`` the robot is back where it was at ``t_other`` (n,) s, with a
    place-recognition ``weight`` (n,) (similarity, higher is surer)."""

    t: np.ndarray
    t_other: np.ndarray
    weight: np.ndarray


@dataclass
class Recording:
    """One run: every stream is optional, since real robots differ.

    ``odometry`` is the pose integrated by the robot's odometry in its own
    ``odom`` frame; ``extra_odometry`` further odometry sources by name (a
    visual odometry, a second wheel odometry), each in its own frame. ``faults`` maps a component name to the intervals (s, in
    the recording's time) where its output is physically wrong beyond its
    nominal noise; it is known only for simulated runs. ``place_matches``:
    loop closures the recording lists, if any. ``fault_truth``: the fault
    intervals the recording's own truth gives, as read (a run folder's
    ``truth.json`` in the recording's time, a BROAD trial's labels); None
    where it has no truth (a plain log or bag). ``faults`` starts as these
    and may gain the times the pipeline finds the scan matcher wrong
    against ground truth (:mod:`slam.gating.truth`); the figures show only
    ``fault_truth``. ``stamps_synthesised``: why the reader made the times
    up (a log whose stamps are unusable): they are then not physical
    seconds, and nothing is measured against them (the real-time factor);
    None where they are the recording's own.
    """

    name: str
    t0: float = 0.0
    scans: Scans | None = None
    gyro: Gyro | None = None
    compass: Compass | None = None
    odometry: Trajectory | None = None
    gps: Gps | None = None
    groundtruth: Trajectory | None = None
    faults: dict[str, list[Interval]] = field(default_factory=dict)
    magnetic_reference: MagneticReference | None = None
    place_matches: PlaceMatches | None = None
    extra_odometry: dict[str, Trajectory] = field(default_factory=dict)
    fault_truth: dict[str, list[Interval]] | None = None
    stamps_synthesised: str | None = None

    @property
    def duration(self) -> float:
        """Time from the first to the last message of any stream, s."""
        ends = [
            s.t[-1]
            for s in (self.scans, self.gyro, self.compass, self.odometry, self.gps, self.groundtruth,
                      *self.extra_odometry.values())
            if s is not None and len(s.t)
        ]
        return float(max(ends)) if ends else 0.0


# --- poses and intervals along a run ----------------------------------------


def relative_poses(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``inverse(a) * b`` for rows of planar poses (x, y, yaw), (n, 3)."""
    c, s = np.cos(a[:, 2]), np.sin(a[:, 2])
    dx, dy = b[:, 0] - a[:, 0], b[:, 1] - a[:, 1]
    return np.column_stack([c * dx + s * dy, -s * dx + c * dy, wrap_angle(b[:, 2] - a[:, 2])])


def interpolate_poses(traj: Trajectory, t: np.ndarray) -> np.ndarray:
    """Poses (len(t), 3) linearly interpolated at ``t`` (yaw unwrapped first)."""
    yaw = np.unwrap(traj.yaw)
    return np.column_stack(
        [np.interp(t, traj.t, traj.x), np.interp(t, traj.t, traj.y), wrap_angle(np.interp(t, traj.t, yaw))]
    )


def covered(sample_t: np.ndarray, t: np.ndarray, max_gap_s: float) -> np.ndarray:
    """True where ``t`` lies within the stream's span and a sample is no
    further than ``max_gap_s`` away."""
    idx = np.clip(np.searchsorted(sample_t, t), 1, len(sample_t) - 1)
    nearest = np.minimum(np.abs(sample_t[idx] - t), np.abs(sample_t[idx - 1] - t))
    return (t >= sample_t[0]) & (t <= sample_t[-1]) & (nearest <= max_gap_s)


def path_length(xy: np.ndarray) -> np.ndarray:
    """Cumulative path length (n,) of positions (n, 2), starting at 0."""
    steps = np.hypot(*np.diff(xy, axis=0).T) if len(xy) > 1 else np.zeros(0)
    return np.concatenate([[0.0], np.cumsum(steps)])


def intervals_from_mask(t: np.ndarray, mask: np.ndarray, merge_gap_s: float, min_duration_s: float) -> list[Interval]:
    """Runs of True in ``mask`` over times ``t`` (s) as merged intervals."""
    if not np.any(mask):
        return []
    m = np.concatenate([[False], mask.astype(bool), [False]])
    starts = np.flatnonzero(~m[:-1] & m[1:])
    ends = np.flatnonzero(m[:-1] & ~m[1:]) - 1
    merged: list[list[float]] = []
    for a, b in zip(t[starts], t[ends]):
        if merged and a - merged[-1][1] <= merge_gap_s:
            merged[-1][1] = float(b)
        else:
            merged.append([float(a), float(b)])
    return [(round(a, 6), round(b, 6)) for a, b in merged if b - a >= min_duration_s]


def union_intervals(*lists: list[Interval]) -> list[Interval]:
    """Union of interval lists, sorted and merged where they overlap."""
    spans = sorted(iv for lst in lists for iv in lst)
    out: list[list[float]] = []
    for a, b in spans:
        if out and a <= out[-1][1]:
            out[-1][1] = max(out[-1][1], b)
        else:
            out.append([a, b])
    return [(a, b) for a, b in out]
