"""``gslam inject``: physically modelled faults added to a real recording,
with their true intervals written beside it, as the simulator does.

The result is a run folder (:mod:`slam.readers.read`): ``bag/`` holds the
recording in its own format (a ROS 1 or ROS 2 bag, a CARMEN log, a BROAD
trial) with the faults in it, and ``truth.json`` the true fault intervals:
those the input already had (a run folder's, a BROAD trial's own label)
and those of the injected faults, each where its error is physically
beyond the component's nominal noise (:mod:`slam.commands.inject.spec`). ``gslam
map``, ``compare`` and ``calibrate`` read it like any run folder, and the
validation metrics score against those intervals.
"""

from __future__ import annotations

import json
import logging
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from slam.config import InputConfig, TimeOffsetsConfig
from slam.errors import GslamError
from slam.commands.inject.broad import inject_broad
from slam.commands.inject.carmen import inject_carmen
from slam.commands.inject.labels import Labels
from slam.commands.inject.rosbag import inject_rosbag
from slam.commands.inject.physics import inside
from slam.commands.inject.spec import KINDS, Fault, no_sample, parse_fault
from slam.results.outdir import result_folder
from slam.readers.read import RUN_BAG, SIDECAR, guess_format, is_run_folder, read_recording, run_recording
from slam.recording import Interval, Recording
from slam.recording import union_intervals

__all__ = ["InjectResult", "KINDS", "inject", "parse_fault"]

log = logging.getLogger(__name__)

LABELLED_STREAM = {
    "IMU_YAW": "compass", "IMU_GYRO": "gyro", "ODO_DIST": "odometry", "ODO_YAW": "odometry",
    "SM_DIST": "scan", "SM_LAT": "scan", "SM_YAW": "scan", "GPS": "gps",
}
"""The stream whose samples an injected fault of each component changes."""


@dataclass
class InjectResult:
    """The run folder written, every true fault interval in it (s from the
    recording's start) and those of the injected faults alone."""

    run_dir: Path
    faults: dict[str, list[Interval]]
    injected: dict[str, list[Interval]]
    duration_s: float


CHANGED_STREAM = {"dipole": ("compass", "compass sample"), "laser_cut": ("scans", "laser scan"),
                  "gyro_bias": ("gyro", "gyro sample"), "slip": ("odometry", "odometry pose"),
                  "multipath": ("gps", "GPS fix with a position")}
"""The stream of the recording each kind of fault changes, and what one of its samples is called."""


def _check_intervals(faults: Sequence[Fault], rec: Recording) -> None:
    for fault in faults:
        if fault.start_s >= rec.duration:
            raise GslamError(f"--fault {fault.text()}: starts after the recording ends ({rec.duration:.1f} s)")
        if fault.end_s > rec.duration:
            raise GslamError(f"--fault {fault.text()}: ends at {fault.end_s:g} s, after the recording ends "
                             f"({rec.duration:.1f} s); its true interval would say the fault lasted past the data")
        # A stream the recording lacks is refused by each format's injector, saying why.
        attr, sample = CHANGED_STREAM[fault.kind]
        stream = getattr(rec, attr)
        if stream is not None and not inside(stream.t, fault.start_s, fault.end_s).any():
            raise GslamError(no_sample(fault, sample))


def _check_repeats(faults: Sequence[Fault]) -> None:
    """A fault given twice is refused: each ``--fault`` is added, so the two
    would add up (twice the gyro bias) where one was meant. Two faults of
    one kind over overlapping intervals both act there, one on top of the
    other: said in one warning line naming both."""
    for i, a in enumerate(faults):
        for b in faults[i + 1 :]:
            if a.kind != b.kind:
                continue
            if a == b:
                raise GslamError(f"--fault {a.text()} given twice; each --fault is added on top of the others, so "
                                 "the two would add up: give it once (or one fault of twice the size)")
            start, end = max(a.start_s, b.start_s), min(a.end_s, b.end_s)
            if start < end:
                log.warning("--fault %s and --fault %s overlap from %g to %g s: both are added there, one on top of "
                            "the other", a.text(), b.text(), start, end)


def _sidecar(rec: Recording, source: Path, faults: Sequence[Fault], truth: dict[str, list[Interval]],
             injected: dict[str, list[Interval]]) -> str:
    data: dict = {
        "scenario": f"{rec.name} with injected faults",
        "seed": None,
        "t0": rec.t0,
        "duration_s": round(rec.duration, 6),
        "faults": {c: [list(iv) for iv in v] for c, v in sorted(truth.items())},
        "source": str(source),
        "injected": [{"fault": f.text(), **f.model_dump()} for f in faults],
        "injected_faults": {c: [list(iv) for iv in v] for c, v in sorted(injected.items())},
    }
    if rec.magnetic_reference is not None:
        m = rec.magnetic_reference
        data["magnetic_reference"] = {"strength_T": m.strength_T, "dip_rad": m.dip_rad,
                                      "declination_rad": m.declination_rad}
    return json.dumps(data, indent=2) + "\n"


def inject(
    input_path: str | Path,
    faults: Sequence[Fault | str],
    out: str | Path,
    config: InputConfig,
    inputs: Sequence[str | Path] = (),
    force: bool = False,
) -> InjectResult:
    """Add ``faults`` (typed, or ``KIND@T0:T1[,param=value]`` texts) to the
    recording at ``input_path``, read with ``config`` (its stamps as
    recorded: ``time_offsets_s`` apply when the result is mapped), and
    write the run folder ``out`` (:mod:`slam.results.outdir`'s rule; ``inputs``
    are other files the command read, which ``out`` must not be or hold)."""
    input_path = Path(input_path)
    parsed = [parse_fault(f) if isinstance(f, str) else f for f in faults]
    if not parsed:
        raise GslamError("gslam inject: no fault given; add --fault KIND@T0:T1 (kinds: " + ", ".join(KINDS) + ")")
    _check_repeats(parsed)
    fmt = guess_format(input_path) if config.format == "auto" else config.format
    if fmt == "librsf":
        raise GslamError(f"{input_path}: gslam inject writes ROS bags, CARMEN logs and BROAD trials, not libRSF data sets")
    # The faults are written into the messages as stamped: read without
    # input.time_offsets_s, which apply when the injected run is mapped; the
    # labels are moved by them, to the times the faulty samples were taken.
    offsets = config.time_offsets_s.model_dump()
    config = config.model_copy(update={"time_offsets_s": TimeOffsetsConfig()})
    source = run_recording(input_path) if is_run_folder(input_path) else input_path
    need = _size(source)  # the recording is written again, faults added
    with result_folder(out, "inject", [input_path, *inputs], force, (f"{RUN_BAG}/", SIDECAR), need) as tmp:
        rec = read_recording(input_path, config)
        _check_intervals(parsed, rec)
        dest = tmp / RUN_BAG
        labels: Labels
        if fmt == "rosbag":
            labels = inject_rosbag(source, dest, rec, config, parsed)
        elif fmt == "carmen":
            labels = inject_carmen(source, dest, rec, parsed)
        else:
            labels = inject_broad(source, dest, parsed)
        injected = {c: _moved(spans, offsets[LABELLED_STREAM[c]]) for c, spans in labels.intervals().items()}
        truth = {c: union_intervals(rec.faults.get(c, []), injected.get(c, [])) for c in {*rec.faults, *injected}}
        (tmp / SIDECAR).write_text(_sidecar(rec, input_path, parsed, truth, injected))
    for comp, spans in sorted(injected.items()):
        log.info("injected %s: %s", comp, ", ".join(f"{a:.1f}-{b:.1f} s" for a, b in spans) or "nothing labelled")
    return InjectResult(Path(out), truth, injected, rec.duration)


def _size(path: Path) -> int:
    """Bytes of a file, or of the files in a folder."""
    if path.is_file():
        return path.stat().st_size
    return sum(p.stat().st_size for p in path.rglob("*") if p.is_file() and not p.is_symlink())


def _moved(spans: list[Interval], offset_s: float) -> list[Interval]:
    return [(a + offset_s, b + offset_s) for a, b in spans]
