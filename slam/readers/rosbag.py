"""Reader for recorded runs in ROS 1 bags and ROS 2 bags (sqlite3 or mcap).

Both are read through ``rosbags.highlevel.AnyReader``; an MCAP file with
channels besides ROS 2's, which rosbags refuses, through
:mod:`slam.readers.rosbag_mcap`. A channel whose messages are not CDR (JSON,
protobuf) is skipped with a warning naming its topic and encoding, and is an
error if a stream needs it. Only the topics named
in :class:`slam.config.TopicsConfig` are read; each message is deserialised
once even when two streams share a topic (gyro and compass from one Imu).
In ROS 2 bags, topics whose messages share one layout are decoded in bulk,
a chunk of messages at a time (:mod:`slam.readers.cdr`); other topics, and ROS 1
bags, message by message through rosbags. Both give the same streams.

Message -> stream mapping (all times are header stamps):

* ``scan``: sensor_msgs/LaserScan -> :class:`Scans`, ranges as published.
* ``gyro``: sensor_msgs/Imu -> :class:`Gyro`, ``angular_velocity.z`` or the
  world-vertical component of the angular velocity (``input.gyro.axis``).
* ``compass``: sensor_msgs/MagneticField or the orientation of a
  sensor_msgs/Imu -> :class:`Compass` (sign conventions in
  :mod:`slam.readers.rosbag_imu`).
* ``odometry``, ``groundtruth``, each of ``extra_odometry``:
  nav_msgs/Odometry (ground truth may also be geometry_msgs/PoseStamped) ->
  :class:`Trajectory` from the planar pose.
* ``gps``: sensor_msgs/NavSatFix -> :class:`Gps` in metres about a datum.

Each stream but GPS is turned from its own frame conventions into the
project's (``input.frames``, :mod:`slam.readers.frames`).

This module opens the bag, checks the topics and feeds the messages to the
streams; the streams are in :mod:`slam.readers.rosbag_streams` (base class and
message types), :mod:`slam.readers.rosbag_scans`, :mod:`slam.readers.rosbag_imu` and
:mod:`slam.readers.rosbag_poses`.

Bad input raises :class:`GslamError` with one line naming the bag and topic.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from pathlib import Path, PurePath
from typing import Any

import yaml

from slam.config import InputConfig
from slam.errors import GslamError
from slam.readers import cdr, rosbag2_sqlite, rosbag_mcap
from slam.readers.files import check_exists
from slam.readers.rosbag_imu import _CompassImuStream, _CompassMagStream, _GyroStream, world_yaw_rate
from slam.readers.rosbag_poses import _GpsStream, _PoseStream
from slam.readers.rosbag_scans import _ScanStream
from slam.readers.rosbag_streams import _NS, IMU, LASER_SCAN, MAGNETIC_FIELD, NAV_SAT_FIX, ODOMETRY, POSE_STAMPED, _Stream
from validation.base.yamlio import SAFE_LOADER, check_regular_file, read_text
from slam.recording import Recording, Scans

# The reader's public names, with the message types and world_yaw_rate of the
# stream modules, so one import serves callers and test bag writers.
__all__ = [
    "BAG_SUFFIXES", "BULK_CHUNK", "IMU", "LASER_SCAN", "MAGNETIC_FIELD", "NAV_SAT_FIX", "ODOMETRY",
    "POSE_STAMPED", "RosbagReader", "is_rosbag", "open_bag", "read_rosbag", "resolve_bag_path", "world_yaw_rate",
]

log = logging.getLogger(__name__)

BAG_SUFFIXES = (".bag", ".db3", ".mcap")

ScansHook = Callable[[Scans], None]

EXTRA_ODOMETRY = "extra_odometry."
"""Prefix of a further odometry source's stream name (``input.extra_odometry``)."""

BULK_CHUNK = 8192
"""Messages of one topic decoded together: bounds the raw bytes held."""


def _first_line(err: BaseException) -> str:
    text = str(err).strip().splitlines()
    return text[0] if text else type(err).__name__


_CUT_SHORT = {
    "File end magic is invalid.": "the MCAP file ends early, a recording or a copy cut short",
    "Bag is not indexed": "the bag has no index, a recording cut short: 'rosbag reindex' it and read it again",
    "Bag index looks damaged": "the bag's index is cut off or damaged, a recording or a copy cut short: "
                               "'rosbag reindex' it and read it again",
}
"""How rosbags begins to say a bag was cut short, and what that means to its owner."""


def _refusal(err: BaseException) -> str:
    """Why rosbags could not open a bag, in one line: its own words, after
    what they mean where they name a bag cut short."""
    said = _first_line(err)
    meaning = next((m for start, m in _CUT_SHORT.items() if said.startswith(start)), None)
    return f"{meaning}: {said}" if meaning else said


def is_rosbag(path: Path) -> bool:
    """True for a ROS 1 ``.bag``, a ``.db3``/``.mcap`` file or a rosbag2
    directory (one holding ``metadata.yaml``)."""
    if path.is_dir():
        return (path / "metadata.yaml").is_file()
    return path.suffix in BAG_SUFFIXES


def resolve_bag_path(path: Path) -> Path:
    """The path to hand to rosbags: ``path`` itself, or the single bag file in
    a directory that is not a rosbag2 directory (as a run folder's ``bag/``
    may be)."""
    check_exists(path)
    if not path.is_dir():
        check_regular_file(path, "ROS bag")
        return path
    if (path / "metadata.yaml").is_file():
        for member in path.iterdir():  # a named pipe among them would block the reader forever
            if not member.is_dir():
                check_regular_file(member, "file of a ROS 2 bag")
        _check_listed_files(path)
        return path
    inside = sorted(p for p in path.iterdir() if p.suffix in BAG_SUFFIXES)
    if len(inside) != 1:
        raise GslamError(
            f"{path}: expected a rosbag2 directory (metadata.yaml) or exactly one "
            f".bag/.db3/.mcap file, found {len(inside)}"
        )
    check_regular_file(inside[0], "ROS bag")
    return inside[0]


def _check_listed_files(path: Path) -> None:
    """The folder's metadata.yaml is UTF-8 text holding a mapping of
    rosbag2_bagfile_information (rosbags said 'NoneType' object is not
    subscriptable, or named a byte's position in the file), and each file
    it lists is a name of a file in that folder: rosbags reads '../x.db3'
    or '/elsewhere/x.db3' as 'x.db3' of the folder (and says that one is
    missing), the plain reader of :mod:`rosbag2_sqlite` would read the file
    outside, another recording's. YAML that does not parse, and metadata
    whose file list is not a list, are left to rosbags to refuse."""
    meta_file = path / "metadata.yaml"
    text = read_text(meta_file, "bag metadata file", "YAML")
    try:
        tree = yaml.load(text, Loader=SAFE_LOADER)
    except Exception:  # YAML rosbags refuses in its own words
        return
    info = tree.get("rosbag2_bagfile_information") if isinstance(tree, dict) else None
    if not isinstance(info, dict):
        raise GslamError(f"{meta_file}: expected a mapping holding rosbag2_bagfile_information (the metadata "
                         f"ros2 bag record writes), found {_metadata_held(tree)}")
    try:
        listed = list(info["relative_file_paths"])
    except Exception:  # rosbags says what it makes of it
        return
    for name in listed:
        if not isinstance(name, str) or name in ("", ".", "..") or PurePath(name).name != name:
            raise GslamError(f"{path / 'metadata.yaml'}: relative_file_paths lists {name!r}, which is not the name "
                             "of a file in the bag's folder; expected the bag's own files, beside metadata.yaml")
        if not (path / name).is_file():
            raise GslamError(f"{path / 'metadata.yaml'}: relative_file_paths lists {name!r}, which is no file "
                             f"in {path}; expected the bag's own files, beside metadata.yaml (a bag copied in part?)")


def _metadata_held(tree: Any) -> str:
    """What a metadata.yaml without a mapping of rosbag2_bagfile_information holds, in a few words."""
    if tree is None:
        return "an empty file"
    if not isinstance(tree, dict):
        return f"a YAML {type(tree).__name__}"
    if "rosbag2_bagfile_information" not in tree:
        return "keys " + ", ".join(repr(key) for key in list(tree)[:3])
    return f"rosbag2_bagfile_information of a {type(tree['rosbag2_bagfile_information']).__name__}"


def open_bag(path: Path) -> Any:
    """An open ``rosbags`` reader of the bag at ``path`` (as for
    :func:`resolve_bag_path`); the caller closes it."""
    path = resolve_bag_path(path)
    return _open_reader(path, _storage_read(path))


def _storage_read(path: Path) -> list[Path] | None:
    """The files to read instead of the rosbag2 folder ``path`` when its
    metadata.yaml disagrees with them on the topics they hold
    (:func:`rosbag2_sqlite.metadata_mismatch`), said in one warning; None
    when the folder is read as it is. The files are what was recorded;
    read through the metadata, a misstated topic gave no messages."""
    mismatch = rosbag2_sqlite.metadata_mismatch(path) if path.is_dir() else None
    if mismatch is None:
        return None
    more = f" (and {mismatch.count - 1} more such difference{'s' if mismatch.count > 2 else ''})" if mismatch.count > 1 else ""
    log.warning("%s: %s%s; read as %s hold%s them", path / "metadata.yaml", mismatch.said, more,
                " and ".join(f.name for f in mismatch.files), "" if len(mismatch.files) > 1 else "s")
    return mismatch.files


def _make_streams(path: Path, config: InputConfig) -> list[_Stream]:
    topics, compass, frames = config.topics, config.compass, config.frames
    streams: list[_Stream] = []
    if topics.scan is not None:
        streams.append(_ScanStream("scan", topics.scan, path))
    if topics.gyro is not None:
        streams.append(_GyroStream("gyro", topics.gyro, path, config.gyro, frames.gyro))
    if topics.compass is not None:
        cls = _CompassMagStream if compass.source == "magnetic_field" else _CompassImuStream
        streams.append(cls("compass", topics.compass, path, compass, frames.compass))
    if topics.odometry is not None:
        streams.append(_PoseStream("odometry", topics.odometry, path, frame=frames.odometry))
    if topics.gps is not None:
        streams.append(_GpsStream("gps", topics.gps, path, config.gps))
    for name, extra in config.extra_odometry.items():
        streams.append(_PoseStream(f"{EXTRA_ODOMETRY}{name}", extra.topic, path, frame=extra.frame))
    if topics.groundtruth is not None:
        gt_types = (ODOMETRY, POSE_STAMPED)
        streams.append(_PoseStream("groundtruth", topics.groundtruth, path, gt_types, frames.groundtruth))
    return streams


BAG_MAGIC = {".bag": b"#ROSBAG V2.0\n", ".mcap": b"\x89MCAP0\r\n", ".db3": b"SQLite format 3\x00"}
"""The bytes each bag file format starts with."""


def check_magic(path: Path) -> None:
    """Refuse a bag file that does not start as its format does, before a
    reader looks for its index (in a 20 GB sparse file of zeros, gigabytes
    into memory)."""
    magic = BAG_MAGIC.get(path.suffix)
    if magic is None or not path.is_file():
        return
    try:
        with open(path, "rb") as f:
            head = f.read(len(magic))
    except OSError as e:
        raise GslamError(f"{path}: cannot read ({e.strerror or e})") from None
    if head != magic:
        raise GslamError(f"{path}: not a readable ROS bag (a {path.suffix} file starts with {magic!r}, this one with {head!r})")


def _open_reader(path: Path, files: list[Path] | None = None) -> Any:
    """An open rosbags reader of ``path``, or of its storage ``files``
    instead (see :func:`_storage_read`)."""
    for file in files or [path]:
        check_magic(file)
    try:
        from rosbags.highlevel import AnyReader
        from rosbags.typesys import Stores, get_typestore
    except ImportError:
        raise GslamError("reading ROS bags needs 'rosbags': pip install rosbags") from None
    # Bags without embedded definitions (old rosbag2 sqlite files) need one.
    store = get_typestore(Stores.ROS1_NOETIC if path.suffix == ".bag" else Stores.LATEST)
    try:
        reader = AnyReader(files or [path], default_typestore=store)
        reader.open()
    except Exception as err:  # rosbags raises many types for foreign or broken files
        files = rosbag_mcap.mcap_files(path)
        mixed = rosbag_mcap.open_mixed_mcap(path, files, _refusal(err)) if files else None
        if mixed is None:
            raise GslamError(f"{path}: not a readable ROS bag ({_refusal(err)})") from None
        return mixed
    return reader


def _connections(reader: Any, path: Path, streams: list[_Stream]) -> dict[str, list[Any]]:
    """The bag's connections per needed topic; drops absent optional streams."""
    by_topic: dict[str, list[Any]] = {}
    for conn in reader.connections:
        by_topic.setdefault(conn.topic, []).append(conn)
    foreign = rosbag_mcap.foreign_channels(reader.connections)
    needed = {stream.topic for stream in streams}
    for topic, encoding in sorted(foreign.items()):
        if topic not in needed:
            log.warning("%s: topic '%s' skipped: its messages are %s, not ROS 2's CDR", path, topic, encoding)
    wanted: dict[str, list[Any]] = {}
    for stream in list(streams):
        if stream.topic in foreign:
            raise GslamError(f"{stream.where}: its messages are {foreign[stream.topic]}, expected ROS 2's CDR "
                             f"(a {' or '.join(stream.msgtypes)})")
        conns = by_topic.get(stream.topic)
        if not conns:
            if stream.name == "groundtruth":
                log.warning("%s: not in the bag; reading without ground truth", stream.where)
                streams.remove(stream)
                continue
            existing = ", ".join(sorted(by_topic)) or "none"
            raise GslamError(f"{stream.where}: not in the bag (topics: {existing})")
        found = sorted({c.msgtype for c in conns})
        problem = message_type_problem(found, stream.msgtypes)
        if problem is not None:
            raise GslamError(f"{stream.where}: {problem}")
        stream.msgtype = found[0]
        wanted[stream.topic] = conns
    return wanted


def message_type_problem(found: list[str], expected: tuple[str, ...]) -> str | None:
    """Why a topic whose connections declare the message types ``found``
    cannot be read as a stream of ``expected`` types, or None if it can. A
    type of another package (a driver's own message) is named as found, so
    the user sees the topic is there but carries something else."""
    wanted = " or ".join(expected)
    if len(found) > 1:
        right = [f for f in found if f in expected]
        if right:
            others = ", ".join(f for f in found if f not in expected)
            return f"carries {right[0]} and also {others} (two publishers?); expected only {wanted}"
        return f"type is {' and '.join(found)}, expected {wanted}"
    if found[0] not in expected:
        return f"type is {found[0]}, expected {wanted}"
    return None


def _read_messages(
    reader: Any, path: Path, streams: list[_Stream], wanted: dict[str, list[Any]]
) -> dict[str, int]:
    """Feed every message of the wanted connections to its streams; return
    the number of messages per topic.

    In a ROS 2 bag, the raw messages of a topic whose type :mod:`slam.readers.cdr`
    knows are held back and decoded in bulk, ``BULK_CHUNK`` at a time. If a
    chunk does not decode in bulk (the layout changes), that topic is read
    again message by message after the others.
    """
    by_topic: dict[str, list[_Stream]] = {}
    for stream in streams:
        by_topic.setdefault(stream.topic, []).append(stream)
    counts = dict.fromkeys(by_topic, 0)
    conns = [c for cs in wanted.values() for c in cs]
    if not conns:  # rosbags reads every connection when given none
        return counts
    ros2 = getattr(reader, "is2", False)  # ROS 1 messages are not CDR
    bulk = {topic: [] for topic, group in by_topic.items() if ros2 and cdr.supported(group[0].msgtype)}
    fallback: set[str] = set()

    def decode(topic: str) -> None:
        pending = bulk[topic]
        group = by_topic[topic]
        fields = sorted({f for s in group for f in s.bulk_fields()})
        msgtype = group[0].msgtype
        cols = cdr.decode_columns(msgtype, pending, fields) if topic not in fallback else None
        # One message per chunk through rosbags: the layout must be the bag's.
        if cols is not None and not cdr.agrees(_deserialize(reader, path, pending[-1], msgtype), cols, -1):
            cols = None
        if cols is None:
            fallback.add(topic)
            for s in group:
                s.reset_columns()
        else:
            for s in group:
                s.add_columns(cols)
        pending.clear()

    for topic, conn, raw in _raw_messages(reader, path, conns):
        counts[topic] += 1
        pending = bulk.get(topic)
        if pending is None:
            msg = _deserialize(reader, path, raw, conn.msgtype)
            for stream in by_topic[topic]:
                stream.add(msg)
        elif topic not in fallback:
            pending.append(raw)
            if len(pending) >= BULK_CHUNK:
                decode(topic)
    for topic, pending in bulk.items():
        if pending and topic not in fallback:
            decode(topic)
    if fallback:
        log.info("%s: topics %s read message by message", path, ", ".join(sorted(fallback)))
        again = [c for t in fallback for c in wanted[t]]
        for topic, conn, raw in _raw_messages(reader, path, again):
            msg = _deserialize(reader, path, raw, conn.msgtype)
            for stream in by_topic[topic]:
                stream.add(msg)
    return counts


def _read_plain(
    plain: rosbag2_sqlite.PlainBag,
    streams: list[_Stream],
    counts: dict[str, int],
    on_scans: Callable[[_Stream], None] | None,
) -> list[_Stream]:
    """Read the streams whose topics ``plain`` serves with the standard
    definitions, the scans first (``on_scans`` is called with their stream
    as soon as they are read), adding the number of messages per topic read
    to ``counts``; return the streams read. A topic whose messages do not
    decode in bulk is left to rosbags."""
    by_topic: dict[str, list[_Stream]] = {}
    read: list[_Stream] = []
    for stream in sorted(streams, key=lambda s: s.name != "scan"):
        topic = plain.topics.get(stream.topic)
        if topic is not None and topic.msgtype in stream.msgtypes and cdr.supported(topic.msgtype):
            by_topic.setdefault(stream.topic, []).append(stream)
    names = list(by_topic)
    fetched: dict[str, list[bytes]] = {}
    for k, (name, group) in enumerate(by_topic.items()):
        if name not in fetched:  # the scans alone (handed on once decoded), then the other topics in one pass
            scans = any(s.name == "scan" for s in group)
            fetched = plain.raw_many(names[k : k + 1] if scans else names[k:])
        msgtype = plain.topics[name].msgtype
        raws = fetched.pop(name)
        fields = sorted({f for s in group for f in s.bulk_fields()})
        for s in group:
            s.msgtype = msgtype
        for lo in range(0, len(raws), BULK_CHUNK):
            cols = cdr.decode_columns(msgtype, raws[lo : lo + BULK_CHUNK], fields)
            if cols is None:  # the layout changes within the topic
                for s in group:
                    s.reset_columns()
                break
            for s in group:
                s.add_columns(cols)
        else:
            counts[name] = len(raws)
            read += group
            scan = next((s for s in group if s.name == "scan"), None)
            if scan is not None and on_scans is not None:
                on_scans(scan)
    return read


def _raw_messages(reader: Any, path: Path, conns: list[Any]):
    """(topic, connection, raw bytes) of every message on ``conns``."""
    messages = reader.messages(connections=conns)
    while True:
        # Corrupt chunks surface as assorted exception types from rosbags,
        # lz4, sqlite3 or struct while iterating; all mean "broken file".
        try:
            conn, _, raw = next(messages)
        except StopIteration:
            return
        except Exception as err:
            raise GslamError(f"{path}: corrupt bag ({_first_line(err)})") from None
        yield conn.topic, conn, raw


def _deserialize(reader: Any, path: Path, raw: bytes, msgtype: str) -> Any:
    try:
        return reader.deserialize(raw, msgtype)
    except Exception as err:
        raise GslamError(f"{path}: corrupt bag ({_first_line(err)})") from None


def read_rosbag(path: str | Path, config: InputConfig, on_scans: ScansHook | None = None) -> Recording:
    """Read one recorded run from a ROS 1 or ROS 2 bag.

    ``path``: a ``.bag`` file, a rosbag2 directory, a ``.db3``/``.mcap``
    file, or a directory holding exactly one bag file. ``Recording.t0`` is
    the earliest first header stamp over the streams read (absolute s); each
    stream's ``t`` is relative to it. ``Recording.name`` is the file stem or
    directory name.

    ``on_scans``: called with the laser scans as soon as they are read,
    before the other topics, so scan matching can start while they are
    read; their ``t`` is then relative to the first scan (the recording's
    own scans are relative to ``t0``, as every stream).
    """
    path = resolve_bag_path(Path(path))
    storage = _storage_read(path)
    streams = _make_streams(path, config)
    counts: dict[str, int] = {}
    done: list[_Stream] = []

    def scans_read(scan: _Stream) -> None:
        _finish(scan, counts)
        done.append(scan)
        on_scans(scan.build(scan.first_ns()))

    plain = rosbag2_sqlite.open_plain(path) if path.is_dir() else None
    read_plain: list[_Stream] = []
    if plain is not None:
        try:
            read_plain = _read_plain(plain, streams, counts, scans_read if on_scans is not None else None)
        finally:
            plain.close()
    # By stream, not by topic: a stream set to another stream's topic (the
    # scan on the IMU's) was skipped there for its type and must be checked.
    rest = [s for s in streams if not any(s is r for r in read_plain)]
    if rest:
        reader = _open_reader(path, storage)
        try:
            wanted = _connections(reader, path, rest)
            streams = [s for s in streams if s.topic in counts or s in rest]  # absent optional ones dropped
            first = [s for s in rest if s.name == "scan"] if on_scans is not None else []
            if first:
                scan = first[0]
                counts.update(_read_messages(reader, path, first, {scan.topic: wanted[scan.topic]}))
                scans_read(scan)
            rest = [s for s in rest if s not in done]
            counts.update(_read_messages(reader, path, rest, {s.topic: wanted[s.topic] for s in rest}))
        finally:
            reader.close()

    for stream in streams:
        if stream not in done:
            _finish(stream, counts)
    firsts = [s.first_ns() for s in streams if s.first_ns() is not None]
    t0_ns = min(firsts) if firsts else 0
    built = {s.name: s.build(t0_ns) for s in streams}
    rec = Recording(
        name=path.stem if path.is_file() else path.name,
        t0=t0_ns / _NS,
        scans=built.get("scan"),
        gyro=built.get("gyro"),
        compass=built.get("compass"),
        odometry=built.get("odometry"),
        gps=built.get("gps"),
        groundtruth=built.get("groundtruth"),
        extra_odometry={name: built[f"{EXTRA_ODOMETRY}{name}"] for name in config.extra_odometry},
    )
    log.info(
        "%s: read %s over %.1f s",
        path,
        ", ".join(f"{len(s.ns)} {s.name}" for s in streams),
        rec.duration,
    )
    return rec


def _finish(stream: _Stream, counts: dict[str, int]) -> None:
    if counts[stream.topic] == 0:
        raise GslamError(f"{stream.where}: no messages (the bag declares the topic as {stream.msgtype}, "
                         "with none recorded)")
    stream.finish()


class RosbagReader:
    """The ``rosbag`` format of :mod:`slam.readers.read`."""

    def read(self, path: Path, config: InputConfig, on_scans: ScansHook | None = None) -> Recording:
        """See :func:`read_rosbag`."""
        return read_rosbag(path, config, on_scans)
