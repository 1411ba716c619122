"""``gslam inspect``: what a recording holds, and a starter config to map
and gate it.

For a ROS 1 or ROS 2 bag (or a simulated run folder) the report lists every
topic with its message type, count, rate and time span (bag receive times).
For the other formats (CARMEN, BROAD, libRSF) it reads the recording and
lists its streams.

With ``starter`` (``--config-out``), :attr:`Inspection.starter` is a
commented pipeline config for ``gslam map`` (:mod:`slam.commands.inspect.starter`): for a
bag, the topics guessed from what it holds (:mod:`slam.commands.inspect.topic_choice`); for
the other formats, the shipped config of that data set; with a ``base``
config (``--config``), that config. Its validation section holds the
system model proposed for the streams the recording holds as that config
reads them (:mod:`validation.proposal`), which ``gslam calibrate`` learns.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from slam.config import InputConfig, PipelineConfig, load_config
from slam.errors import GslamError
from slam.readers.read import SIDECAR, guess_format, is_run_folder, load_sidecar, read_recording, run_recording
from slam.readers.rosbag import open_bag
from slam.recording import Recording
from slam.resources import shipped_config
from slam.commands.inspect.starter import bag_input, bag_starter, base_starter, recording_sources
from slam.commands.inspect.topic_choice import TopicInfo, choose_topics
from validation.proposal import ModelProposal, propose_model

_NS = 1e9
_DATASET_CONFIGS = {"carmen": "datasets/carmen.yaml", "broad": "datasets/broad.yaml", "librsf": "datasets/librsf_corridor.yaml"}
_NAMES = {"carmen": "CARMEN log", "broad": "BROAD trial (.mat)", "librsf": "libRSF data set"}
_SHARED = {"librsf": {"gyro": "its yaw rate is the odometry's own (the odom2 lines' wz), not a sensor of its own"}}
"""Streams a reader makes from another stream's sensor: no witness of it."""


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
    proposal: ModelProposal | None = None

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
        if self.proposal is not None:
            lines.append(proposal_summary(self.proposal))
        return "\n".join(lines)


def proposal_summary(p: ModelProposal) -> str:
    """One line: what the proposed model holds, or why nothing can be validated."""
    nothing = p.nothing_to_validate()
    if nothing:
        return f"nothing can be validated: {nothing}"
    kinds = sorted({r.config.kind for r in p.relations})
    return (f"proposed system model: {len(p.components)} components, {len(p.relations)} observers "
            f"({', '.join(kinds)}) over {len({frozenset(r.config.components) for r in p.relations})} pairs of "
            f"components, {len(p.unary_checks)} checks")


def inspect_recording(path: str | Path, starter: bool = False, base: str | Path | None = None) -> Inspection:
    """Inspect a bag, a run folder, or a CARMEN, BROAD or libRSF recording;
    with ``starter``, also write the starter config (module docstring),
    built on the config ``base`` if given."""
    path = Path(path)
    fmt = guess_format(path)
    if fmt != "rosbag":
        found = _inspect_other(path, fmt)
    else:
        bag = run_recording(path) if is_run_folder(path) else path
        found = _inspect_bag(path, bag)
        if is_run_folder(path):
            sidecar = load_sidecar(path / SIDECAR)
            faults = ", ".join(f"{c} {len(iv)}" for c, iv in sidecar.faults.items() if iv) or "none"
            found.format = f"run folder ({found.format} + truth.json)"
            found.notes.append(f"scenario '{sidecar.scenario}', seed {sidecar.seed}; true fault intervals: {faults}")
    if starter or base is not None:
        _starter(found, fmt, Path(base) if base is not None else None)
    return found


def _starter(found: Inspection, fmt: str, base: Path | None) -> None:
    """The starter config and the proposal, on ``base`` or on the guess."""
    path = found.path
    if base is None and fmt == "rosbag":
        bag = run_recording(path) if is_run_folder(path) else path
        choice = choose_topics(bag, [TopicInfo(t.name, t.msgtype, t.count) for t in found.topics])
        config = PipelineConfig.model_validate({
            "input": bag_input(choice),
            "frontend": {"enabled": choice.scan is not None},
            "backend": {"factors": {"scan_matching": {"enabled": choice.scan is not None}}},
        })
        origins = {k: v for k, v in config.input.topics.model_dump().items() if v is not None}
        origins.update({name: extra.topic for name, extra in config.input.extra_odometry.items()})
        found.proposal = _propose(path, config, origins, {})
        found.starter = bag_starter(path, choice, found.proposal)
        return
    why = "the config given"
    if base is None:
        base, why = shipped_config(_DATASET_CONFIGS[fmt]), f"the shipped config for {_NAMES[fmt]} data sets"
    config = load_config(base)
    text = base.read_text()
    shared = _SHARED.get(fmt, {})
    origins = {"odometry": f"the {_NAMES.get(fmt, 'recording')}'s odometry"} if fmt != "rosbag" else {
        k: v for k, v in config.input.topics.model_dump().items() if v is not None}
    found.proposal = _propose(path, config, origins, shared)
    for stream, reason in shared.items():
        found.notes.append(f"not a witness: {stream}: {reason}")
    found.starter = base_starter(path, base, text, found.proposal, why)


def _propose(path: Path, config: PipelineConfig, origins: dict[str, str], shared: dict[str, str]) -> ModelProposal:
    rec = read_recording(path, config.input)
    return propose_model(recording_sources(rec, config, origins, shared), loops=config.loops.enabled)


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
    return Inspection(path, kind, start_ns / _NS, (end_ns - start_ns) / _NS, topics)


def _inspect_other(path: Path, fmt: str) -> Inspection:
    rec = read_recording(path, InputConfig(format=fmt))
    found = Inspection(path, _NAMES.get(fmt, fmt), rec.t0, rec.duration, _streams(rec))
    found.notes.append("streams as the reader makes them (this format has no topics)")
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


