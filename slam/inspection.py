"""``gslam inspect``: what a recording holds, and a starter config to map it.

For a ROS 1 or ROS 2 bag (or a simulated run folder) the report lists every
topic with its message type, count, rate and time span (bag receive times),
without decoding a message. For the other formats (CARMEN, BROAD, libRSF) it
reads the recording and lists its streams. :attr:`Inspection.starter` is a
commented pipeline config for ``gslam map`` with the topics filled in from
what the bag holds; for the other formats it is the shipped config of that
data set.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from slam.config import InputConfig
from slam.errors import GslamError
from slam.io.outdir import result_file_mark
from slam.io.readers import SIDECAR, guess_format, is_run_folder, load_sidecar, read_recording, run_recording
from slam.io.rosbag import open_bag
from slam.io.rosbag_streams import IMU, LASER_SCAN, MAGNETIC_FIELD, NAV_SAT_FIX, ODOMETRY, POSE_STAMPED
from slam.recording import Recording
from slam.resources import configs_dir, shipped_config

_NS = 1e9
_DATASET_CONFIGS = {"carmen": "datasets/carmen.yaml", "broad": "datasets/broad.yaml", "librsf": "datasets/librsf_corridor.yaml"}
_GROUNDTRUTH_HINTS = ("ground_truth", "groundtruth", "gt", "vicon", "mocap", "optitrack")


@dataclass(frozen=True)
class Topic:
    """One topic (or stream): ``start_s``/``end_s`` relative to the
    recording's start, ``rate_hz`` = (count - 1) / span."""

    name: str
    msgtype: str
    count: int
    start_s: float
    end_s: float

    @property
    def rate_hz(self) -> float | None:
        span = self.end_s - self.start_s
        return (self.count - 1) / span if self.count > 1 and span > 0 else None


@dataclass
class Inspection:
    """What :func:`inspect_recording` found."""

    path: Path
    format: str
    start: float  # absolute start, s (UNIX time for bags)
    duration_s: float
    topics: list[Topic]
    notes: list[str] = field(default_factory=list)
    starter: str = ""

    def report(self) -> str:
        what = "topics" if "bag" in self.format or "run" in self.format else "streams"
        lines = [f"{self.path}: {self.format}, {self.duration_s:.1f} s from {self.start:.3f}, {len(self.topics)} {what}"]
        width = max([len(t.name) for t in self.topics] + [5])
        twidth = max([len(t.msgtype) for t in self.topics] + [4])
        lines.append(f"  {what[:-1]:<{width}}  {'type':<{twidth}}  {'count':>8}  {'rate Hz':>8}  span s")
        for t in self.topics:
            rate = f"{t.rate_hz:8.2f}" if t.rate_hz is not None else f"{'–':>8}"
            lines.append(f"  {t.name:<{width}}  {t.msgtype:<{twidth}}  {t.count:>8}  {rate}  {t.start_s:.1f}–{t.end_s:.1f}")
        lines += [f"  {n}" for n in self.notes]
        return "\n".join(lines)


def inspect_recording(path: str | Path) -> Inspection:
    """Inspect a bag, a run folder, or a CARMEN, BROAD or libRSF recording."""
    path = Path(path)
    fmt = guess_format(path)
    if fmt != "rosbag":
        return _inspect_other(path, fmt)
    bag = run_recording(path) if is_run_folder(path) else path
    found = _inspect_bag(path, bag)
    if is_run_folder(path):
        sidecar = load_sidecar(path / SIDECAR)
        faults = ", ".join(f"{c} {len(iv)}" for c, iv in sidecar.faults.items() if iv) or "none"
        found.format = f"run folder ({found.format} + truth.json)"
        found.notes.append(f"scenario '{sidecar.scenario}', seed {sidecar.seed}; true fault intervals: {faults}")
    return found


def _inspect_bag(path: Path, bag: Path) -> Inspection:
    reader = open_bag(bag)
    try:
        ros2 = getattr(reader, "is2", False)
        counts: dict[str, int] = {}
        first: dict[str, int] = {}
        last: dict[str, int] = {}
        types: dict[str, str] = {}
        for conn in reader.connections:
            types[conn.topic] = conn.msgtype
            counts.setdefault(conn.topic, 0)
        try:
            for conn, stamp, _ in reader.messages():
                counts[conn.topic] += 1
                first.setdefault(conn.topic, stamp)
                last[conn.topic] = stamp
        except Exception as err:  # rosbags, sqlite3, lz4...: all mean a broken file
            raise GslamError(f"{bag}: corrupt bag ({str(err).strip().splitlines()[0] if str(err).strip() else type(err).__name__})") from None
        start_ns = min(first.values()) if first else 0
        end_ns = max(last.values()) if last else 0
    finally:
        reader.close()
    topics = [
        Topic(name, types[name], counts[name], (first.get(name, start_ns) - start_ns) / _NS,
              (last.get(name, start_ns) - start_ns) / _NS)
        for name in sorted(types)
    ]
    kind = "ROS 2 bag" if ros2 else "ROS 1 bag"
    found = Inspection(path, kind, start_ns / _NS, (end_ns - start_ns) / _NS, topics)
    found.starter = starter_config(path, topics)
    return found


def _inspect_other(path: Path, fmt: str) -> Inspection:
    rec = read_recording(path, InputConfig(format=fmt))
    topics = _streams(rec)
    names = {"carmen": "CARMEN log", "broad": "BROAD trial (.mat)", "librsf": "libRSF data set"}
    found = Inspection(path, names.get(fmt, fmt), rec.t0, rec.duration, topics)
    found.notes.append("streams as the reader makes them (this format has no topics)")
    shipped = shipped_config(_DATASET_CONFIGS[fmt])
    # The model paths are relative to the shipped file: make them absolute.
    text = shipped.read_text().replace("../validation/", f"{configs_dir() / 'validation'}/")
    found.starter = (f"{result_file_mark('inspect')}: a starter config for {path.name}, the shipped config for "
                     f"{names[fmt]} data sets\n"
                     f"# ({shipped.name}); check the comments against your recording.\n" + text)
    return found


def _streams(rec: Recording) -> list[Topic]:
    kinds = {"scans": "laser scans", "gyro": "yaw rate", "compass": "heading", "odometry": "odometry poses",
             "gps": "GPS fixes", "groundtruth": "reference poses"}
    out = []
    for attr, kind in kinds.items():
        stream = getattr(rec, attr)
        if stream is not None and len(stream.t):
            out.append(Topic(attr, kind, len(stream.t), float(stream.t[0]), float(stream.t[-1])))
    return out


# --- starter config ------------------------------------------------------------------


def _pick(topics: list[Topic], types: tuple[str, ...], avoid: tuple[str, ...] = ()) -> tuple[str | None, list[str]]:
    """The busiest topic of one of ``types`` (preferring names without the
    ``avoid`` hints), and the other candidates."""
    found = [t for t in topics if t.msgtype in types]
    found.sort(key=lambda t: (any(h in t.name.lower() for h in avoid), -t.count))
    names = [t.name for t in found]
    return (names[0] if names else None), names[1:]


def _commented(line: str, comment: str, column: int = 31) -> str:
    return f"{line:<{column - 1}} # {comment}"


def starter_config(path: Path, topics: list[Topic]) -> str:
    """A commented pipeline config for ``gslam map`` with the bag's topics."""
    gt, gt_other = _pick([t for t in topics if any(h in t.name.lower() for h in _GROUNDTRUTH_HINTS)],
                         (ODOMETRY, POSE_STAMPED))
    rest = [t for t in topics if t.name != gt]
    scan, scan_other = _pick(rest, (LASER_SCAN,))
    gyro, gyro_other = _pick(rest, (IMU,))
    mag, mag_other = _pick(rest, (MAGNETIC_FIELD,))
    odom, odom_other = _pick(rest, (ODOMETRY,))
    gps, gps_other = _pick(rest, (NAV_SAT_FIX,))
    compass, source = (mag, "magnetic_field") if mag else (gyro, "imu_orientation")

    def topic(key: str, value: str | None, what: str, others: list[str]) -> str:
        note = what + (f"; also in the bag: {', '.join(others)}" if others else "") if value else f"{what}: none in the bag"
        return _commented(f"    {key}: {value or 'null'}", note)

    topics_lines = "\n".join([
        topic("scan", scan, "sensor_msgs/LaserScan", scan_other),
        topic("gyro", gyro, "sensor_msgs/Imu: angular_velocity.z", gyro_other),
        topic("compass", compass, "MagneticField, or an Imu's orientation (compass.source)", mag_other),
        topic("odometry", odom, "nav_msgs/Odometry", odom_other),
        topic("gps", gps, "sensor_msgs/NavSatFix", gps_other),
        topic("groundtruth", gt, "Odometry or PoseStamped, for evaluation only", gt_other),
    ])
    sm = "true" if scan else "false"
    initial = "groundtruth" if gt else "origin"
    return f"""\
{result_file_mark('inspect')}: a starter config for {path.name}, written by `gslam inspect`.
# Every key is optional and has a default (README, "Configuration");
# configs/telemax.yaml is a fully commented example. Check the sigmas
# against your sensors before trusting a result.
#   gslam map {path} --config THIS.yaml --out runs/first_map

input:
  format: auto
  topics:                      # null = stream not used
{topics_lines}
  gyro:
    axis: z                    # world_z for an IMU mounted tilted or rolled
  compass:
{_commented(f"    source: {source}", "magnetic_field | imu_orientation")}
    declination_deg: 0.0       # local magnetic declination, east positive
    mounting_yaw_deg: 0.0      # yaw of the sensor on the robot

frontend:                      # KISS-ICP on the 2D scans
  enabled: {sm}
  max_range_m: 30.0            # at most the laser's range_max

keyframes:
  period_s: 0.5                # a keyframe every 0.5 s (or set distance_m / yaw_deg)

backend:
  optimizer: batch             # batch | isam2 (long runs) | gnc_tls | gnc_gm
{_commented(f"  initial_pose: {initial}", "groundtruth | origin")}
  factors:                     # sigmas: the defaults; measure yours
    odometry: {{enabled: {"true" if odom else "false"}}}
    gyro: {{enabled: {"true" if gyro else "false"}}}
    compass: {{enabled: {"true" if compass else "false"}}}
    scan_matching: {{enabled: {sm}}}
    gps: {{enabled: {"true" if gps else "false"}}}

validation:
  mode: "off"                  # on needs a system model: see configs/validation/telemax_model.yaml
"""
