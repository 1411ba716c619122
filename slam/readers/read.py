"""Readers of recorded runs: one small interface, a registry keyed by format,
and run folders.

A *run folder* (written by ``gslam simulate`` and ``gslam inject``) is a
directory holding ``bag/`` and a ``truth.json`` sidecar. ``bag/`` is the
recording: a ROS 2 bag folder (the simulator's), or a folder holding one
recording file of any format (``gslam inject`` keeps the input's: a ROS 1
``.bag``, a CARMEN log, a BROAD trial). The sidecar::

    {"scenario": str, "seed": int, "t0": <absolute s>, "duration_s": float,
     "faults": {"ODO_DIST": [[start, end], ...], "IMU_GYRO": ..., ...},
     "magnetic_reference": {"strength_T", "dip_rad", "declination_rad"},
     "gps_datum": {"lat_deg", "lon_deg"}}

Fault intervals are seconds relative to the sidecar's ``t0``; they are
shifted into the recording's time base (relative to ``Recording.t0``). A
whole-sensor label (``SM``, ``ODO``, as older run folders have) stands for
every modality of that sensor.
"""

from __future__ import annotations

import json
import logging
import math
from dataclasses import dataclass
from pathlib import Path
from types import MappingProxyType
from typing import Annotated, Callable, Mapping, Protocol

from pydantic import ConfigDict, Field, ValidationError

from slam.config import GpsInputConfig, InputConfig
from slam.readers.data_checks import check_recording, check_time_offsets
from validation.base.yamlio import read_text
from validation.base.yamlio import MAX_INT_DIGITS, NoTruthValueForANumber, check_regular_file, unique_keys
from slam.errors import GslamError
from validation.base import bounds
from validation.base.bounds import within
from slam.readers import broad, carmen, librsf
from slam.readers.files import check_exists
from slam.readers.rosbag import BAG_SUFFIXES, RosbagReader, ScansHook, is_rosbag
from slam.results.records import result_command, result_input
from slam.recording import COMPONENTS, SENSOR_MODALITIES, MagneticReference, Recording, expand_sensor_labels

log = logging.getLogger(__name__)

SIDECAR = "truth.json"
RUN_BAG = "bag"


class Reader(Protocol):
    """Reads one recorded run into a :class:`Recording`."""

    def read(self, path: Path, config: InputConfig) -> Recording: ...


@dataclass(frozen=True)
class FunctionReader:
    """A :class:`Reader` made of a plain ``read(path, config)`` function."""

    fn: Callable[[Path, InputConfig], Recording]

    def read(self, path: Path, config: InputConfig) -> Recording:
        return self.fn(path, config)


READERS: Mapping[str, Reader] = MappingProxyType(
    {
        "rosbag": RosbagReader(),
        "carmen": FunctionReader(carmen.read_carmen),
        "broad": FunctionReader(broad.read_broad),
        "librsf": FunctionReader(librsf.read_librsf),
    }
)

# Formats recognised from the path alone, tried in this order.
_GUESSERS: tuple[tuple[str, Callable[[Path], bool]], ...] = (
    ("carmen", carmen.looks_like_carmen),
    ("broad", broad.looks_like_broad),
    ("librsf", librsf.looks_like_librsf),
)


def is_run_folder(path: Path) -> bool:
    """A run folder: a directory with ``truth.json`` and ``bag/`` (a
    ``truth.json`` that is not a file is then reported by its reader)."""
    return path.is_dir() and (path / SIDECAR).exists() and (path / RUN_BAG).exists()


def run_recording(path: Path) -> Path:
    """The recording of a run folder: ``bag/`` when it is a ROS 2 bag folder,
    else the one file in it (a folder holding several is left to the bag
    reader, which names them)."""
    bag = path / RUN_BAG
    if bag.is_dir() and not is_rosbag(bag):
        inside = [p for p in bag.iterdir() if not p.name.startswith(".")]
        if len(inside) == 1 and inside[0].is_file():
            return inside[0]
    return bag


RECORDING_COMMANDS = ("simulate", "inject")
"""The commands whose result folder is a run folder, a recording to read."""


def _not_a_result(path: Path) -> None:
    """Refuse a result folder of a command that writes no recording (a map,
    a comparison, a sweep, a demo): read as one, it said 'run.mcap: scan
    topic '/scan': not in the bag' about gslam's own output, or that the
    format is unknown."""
    made_by = result_command(path) if path.is_dir() else None
    if made_by is None or made_by in RECORDING_COMMANDS:
        return
    made_from = result_input(path)
    raise GslamError(f"{path}: a gslam {made_by} result (its output), not a recording; "
                     + (f"give the recording it was made from, {made_from}" if made_from else
                        "give the recording it was made from"))


def guess_format(path: str | Path) -> str:
    """The registry key of the reader for ``path`` (a run folder's recording)."""
    path = Path(path)
    check_exists(path)
    if not path.is_dir():
        check_regular_file(path, "recording")
    _not_a_result(path)
    if is_run_folder(path):
        path = run_recording(path)
        if path.is_dir() and not is_rosbag(path):
            return "rosbag"  # a folder of bag files; the reader says what is wrong
    if is_rosbag(path) or (path.is_dir() and len([p for p in path.iterdir() if p.suffix in BAG_SUFFIXES]) == 1):
        return "rosbag"
    for fmt, looks_like in _GUESSERS:
        if looks_like(path):
            return fmt
    if path.is_dir():
        names = sorted(p.name for p in path.iterdir())
        shown = ", ".join(names[:3]) + (", ..." if len(names) > 3 else "")
        raise GslamError(
            f"{path}: unknown recording format: a folder must be a rosbag2 bag (with metadata.yaml), "
            "a run folder (truth.json + bag/), or hold one .bag/.db3/.mcap file or one libRSF *_Input.txt; "
            + (f"it holds {len(names)} entries ({shown})" if names else "it is empty")
        )
    raise GslamError(
        f"{path}: unknown recording format; expected a .bag file, a rosbag2 directory "
        "(metadata.yaml), a .db3/.mcap file, a run folder (truth.json + bag/), a CARMEN "
        ".log[.gz], a BROAD .mat or a libRSF *_Input.txt"
    )


# --- sidecar -------------------------------------------------------------


class _Sidecar(NoTruthValueForANumber):
    # Keys added by newer simulators are ignored: this is data, not a config.
    model_config = ConfigDict(extra="ignore", allow_inf_nan=False)


class _MagneticReference(_Sidecar):
    # The Earth's field as any scenario may set it (slam.sim.scenario): a
    # reference outside it turns every compass check into a false alarm.
    strength_T: Annotated[float, bounds.EARTH_FIELD_T]
    dip_rad: Annotated[float, within(-math.pi / 2, math.pi / 2, "rad", "a field points at most straight up",
                                     "a field points at most straight down")]
    declination_rad: Annotated[float, within(-math.pi, math.pi, "rad", "a declination is at most half a turn west",
                                             "a declination is at most half a turn east")] = 0.0


class _Datum(_Sidecar):
    lat_deg: Annotated[float, within(-90.0, 90.0, "deg", "south of the South Pole", "north of the North Pole")]
    lon_deg: Annotated[float, within(-180.0, 180.0, "deg", "a longitude is at most half a turn west",
                                     "a longitude is at most half a turn east")]


class Sidecar(_Sidecar):
    """Contents of ``truth.json``; times in seconds, ``t0`` absolute."""

    scenario: str = ""
    seed: int | None = None
    t0: float
    duration_s: Annotated[float, Field(ge=0.0)] | None = None
    faults: dict[str, list[tuple[float, float]]] = Field(default_factory=dict)
    magnetic_reference: _MagneticReference | None = None
    gps_datum: _Datum | None = None


def _no_constant(name: str) -> float:
    raise ValueError(f"{name} is not a number; expected finite numbers")


def _plain_int(digits: str) -> int:
    """An integer of truth.json, refused past :data:`MAX_INT_DIGITS` digits
    (Python's own limit, 4300, said 'use sys.set_int_max_str_digits()')."""
    if len(digits.lstrip("-")) > MAX_INT_DIGITS:
        raise ValueError(f"an integer of {len(digits.lstrip('-')):,} digits ({digits[:8]}...); expected a number of "
                         f"at most {MAX_INT_DIGITS} digits")
    return int(digits)


def load_sidecar(path: str | Path) -> Sidecar:
    """Read and check a ``truth.json``; one-line :class:`GslamError` if bad."""
    path = Path(path)
    text = read_text(path, "truth.json sidecar", "JSON")
    try:
        data = json.loads(text, parse_constant=_no_constant, parse_int=_plain_int, object_pairs_hook=unique_keys)
    except json.JSONDecodeError as e:
        raise GslamError(f"{path}: line {e.lineno}: invalid JSON ({e.msg})") from None
    except ValueError as e:
        raise GslamError(f"{path}: {e}") from None
    except RecursionError:
        raise GslamError(f"{path}: JSON nested too deeply") from None
    try:
        sidecar = Sidecar.model_validate(data)
    except ValidationError as e:
        first = e.errors()[0]
        loc = ".".join(str(p) for p in first["loc"])
        where = f"{loc}: " if loc else ""  # a check of the whole names its key itself
        raise GslamError(f"{path}: {where}{first['msg'].removeprefix('Value error, ')}") from None
    unknown = sorted(set(sidecar.faults) - set(COMPONENTS) - set(SENSOR_MODALITIES))
    if unknown:
        raise GslamError(
            f"{path}: faults: unknown component {unknown[0]!r}, expected one of {', '.join(COMPONENTS)}"
        )
    for name, intervals in sidecar.faults.items():
        for start, end in intervals:
            if not start <= end:
                raise GslamError(
                    f"{path}: faults.{name}: interval [{start}, {end}] ends before it starts"
                )
    return sidecar


TRUTH_SLACK_S = 10.0
"""How far a fault interval of ``truth.json`` may reach outside the recording
(s): the simulator's and gslam inject's lie within it."""


def attach_sidecar(rec: Recording, sidecar: Sidecar, source: str | Path = SIDECAR) -> None:
    """Fill ``rec.faults`` (shifted into the recording's time base) and
    ``rec.magnetic_reference`` from the sidecar; a one-line
    :class:`GslamError` naming ``source`` if a fault reaches outside the
    recording by more than :data:`TRUTH_SLACK_S` (a ``t0`` or faults of
    another recording would leave it without truth in silence, and a fault
    lasting past the data would be scored as missed there)."""
    shift = sidecar.t0 - rec.t0
    rec.faults = {
        name: [(start + shift, end + shift) for start, end in intervals]
        for name, intervals in expand_sensor_labels(sidecar.faults).items()
    }
    for name, intervals in sidecar.faults.items():
        for start, end in intervals:
            if start + shift > rec.duration + TRUTH_SLACK_S or end + shift < -TRUTH_SLACK_S:
                raise GslamError(f"{source}: faults.{name} [{start:g}, {end:g}] s after t0 {sidecar.t0:.10g} lies "
                                 f"outside the recording ({rec.t0:.10g} s plus {rec.duration:.1f} s); the truth of "
                                 "another recording?")
            if end + shift > rec.duration + TRUTH_SLACK_S or start + shift < -TRUTH_SLACK_S:
                raise GslamError(f"{source}: faults.{name} [{start:g}, {end:g}] s after t0 {sidecar.t0:.10g} reaches "
                                 f"outside the recording ({rec.t0:.10g} s plus {rec.duration:.1f} s) by more than "
                                 f"{TRUTH_SLACK_S:g} s; a fault is scored where the data are")
    mag = sidecar.magnetic_reference
    if mag is not None:
        rec.magnetic_reference = MagneticReference(mag.strength_T, mag.dip_rad, mag.declination_rad)


# --- entry point ---------------------------------------------------------


def read_recording(path: str | Path, config: InputConfig, on_scans: ScansHook | None = None) -> Recording:
    """Read a recorded run with the reader for ``config.format`` (``auto``
    guesses it from the path), each stream's stamps moved by its
    ``config.time_offsets_s`` (:func:`shift_streams`). A run folder reads its ``bag/``, is named
    after the folder and gets the sidecar's faults and magnetic reference;
    the sidecar's GPS datum is used when the config sets none.

    ``on_scans`` is called with the laser scans once they are read: by the
    ROS bag reader before it reads the other topics (their ``t`` is then
    relative to the first scan), by the others with the recording's scans
    at the end; not at all without scans."""
    path = Path(path)
    if path.exists() and not path.is_dir():
        check_regular_file(path, "recording")
    fmt = guess_format(path) if config.format == "auto" else config.format
    if fmt not in READERS:
        raise GslamError(f"unknown input format '{fmt}'; known: {', '.join(READERS)}")
    if fmt != "rosbag" and not config.frames.is_default():
        raise GslamError(f"input.frames: a {fmt} recording has fixed frame conventions; frames apply to ROS bags")
    if fmt != "rosbag" and config.extra_odometry:
        raise GslamError(f"input.extra_odometry: a {fmt} recording has no topics; further odometry sources are "
                         "read from ROS bags")
    if not is_run_folder(path):
        rec = _checked(_read(fmt, path, config, on_scans), fmt, path, config, on_scans)
        rec.fault_truth = _as_read(rec.faults) if rec.faults else None  # a reader's own labels (BROAD)
        return rec

    sidecar = load_sidecar(path / SIDECAR)
    unset = config.gps.datum_lat_deg is None and config.gps.datum_lon_deg is None
    if unset and sidecar.gps_datum is not None:
        lat, lon = sidecar.gps_datum.lat_deg, sidecar.gps_datum.lon_deg
        datum = GpsInputConfig(datum_lat_deg=lat, datum_lon_deg=lon)
        config = config.model_copy(update={"gps": datum})
    rec = _checked(_read(fmt, run_recording(path), config, on_scans), fmt, path, config, on_scans)
    rec.name = path.name
    attach_sidecar(rec, sidecar, path / SIDECAR)
    rec.fault_truth = _as_read(rec.faults)
    log.info("%s: run '%s' with faults in %s", path, sidecar.scenario, ", ".join(rec.faults) or "none")
    return rec


def _as_read(faults: dict[str, list]) -> dict[str, list]:
    """A copy of the fault intervals, which later additions to ``faults`` leave as they are."""
    return {name: list(intervals) for name, intervals in faults.items()}


def _read(fmt: str, path: Path, config: InputConfig, on_scans: ScansHook | None) -> Recording:
    """The reader's recording; the ROS bag reader hands its scans to
    ``on_scans`` while it reads (the others' go after the checks)."""
    reader = READERS[fmt]
    if isinstance(reader, RosbagReader):
        return reader.read(path, config, on_scans)
    return reader.read(path, config)


def _checked(rec: Recording, fmt: str, path: Path, config: InputConfig, on_scans: ScansHook | None) -> Recording:
    """The time offsets applied and the physics checks made
    (:mod:`slam.readers.data_checks`), then the scans to ``on_scans`` if the
    reader has not given them yet."""
    offsets = config.time_offsets_s.shifted()
    offsets.update({f"extra_odometry.{n}": e.time_offset_s for n, e in config.extra_odometry.items() if e.time_offset_s})
    check_time_offsets(rec, offsets, path)
    rec = check_recording(shift_streams(rec, config), path, offsets)
    if on_scans is not None and rec.scans is not None and fmt != "rosbag":
        on_scans(rec.scans)
    return rec


def shift_streams(rec: Recording, config: InputConfig) -> Recording:
    """Add each stream's offset (``config.time_offsets_s``, and each further
    odometry source's ``time_offset_s``) to its stamps (stamp + offset = the
    time the sample was taken), in place; ``rec.t0`` and the fault intervals
    stay. Scans handed to ``on_scans`` before this keep their stamps; the
    front-end's result takes the recording's."""
    for name, offset in config.time_offsets_s.shifted().items():
        stream = getattr(rec, "scans" if name == "scan" else name)
        if stream is not None:
            stream.t = stream.t + offset
            log.info("%s: %s stamps moved by %+.3f s (input.time_offsets_s)", rec.name, name, offset)
    for name, extra in config.extra_odometry.items():
        stream = rec.extra_odometry.get(name)
        if stream is not None and extra.time_offset_s != 0.0:
            stream.t = stream.t + extra.time_offset_s
            log.info("%s: %s stamps moved by %+.3f s (input.extra_odometry.%s.time_offset_s)", rec.name, name,
                     extra.time_offset_s, name)
    return rec
