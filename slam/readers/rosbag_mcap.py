"""An MCAP file that holds channels besides ROS 2's, which rosbags refuses.

rosbags opens an MCAP file only if it is all ROS 2: the ``ros2`` profile
and every channel's schema a ROS 2 definition (``ros2msg``, ``ros2idl``,
``omgidl`` or none). A recording where a tool added a channel of its own
(JSON with a ``jsonschema``, protobuf, flatbuffers: Foxglove's messages, a
logger's diagnostics) is refused as a whole, though the topics a run
needs are ROS 2 messages like any other.

:func:`open_mixed_mcap` reads such a file, or the files of a rosbag2
folder split into several (``ros2 bag record --max-bag-size``), with the
``mcap`` package: each channel of each file becomes rosbags'
:class:`~rosbags.interfaces.Connection` (one of another encoding with no
definition), the messages stay raw bytes, merged across the files in the
order of their log times, and the ROS 2 ones are deserialised by a type
store of the files' own definitions, built as rosbags' ``AnyReader``
builds it.
:mod:`slam.readers.rosbag` reads the needed topics from it as from
rosbags, and skips the channels it cannot decode, naming each
(:func:`foreign_channels`).
"""

from __future__ import annotations

import heapq
import logging
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

from slam.errors import GslamError

log = logging.getLogger(__name__)

ROS2_ENCODING = "cdr"
"""The message encoding of a ROS 2 channel."""

MCAP_HINT = "an MCAP file with channels that are not ROS 2's is read with 'mcap': pip install mcap"


def foreign_channels(connections: Sequence[Any]) -> dict[str, str]:
    """Topic -> message encoding of the ROS 2 connections whose messages
    are not CDR (a JSON or protobuf channel of an MCAP file); a ROS 1
    bag's connections have none."""
    from rosbags.interfaces import ConnectionExtRosbag2

    return {c.topic: c.ext.serialization_format for c in connections
            if isinstance(c.ext, ConnectionExtRosbag2) and c.ext.serialization_format != ROS2_ENCODING}


class _McapFile:
    """One open MCAP file of a bag: its reader and the connection of each
    of its channels (by the file's own channel ids)."""

    def __init__(self, stream, reader, connections: dict[int, Any]):
        self.stream, self.reader, self.connections = stream, reader, connections

    def messages(self, wanted: dict[int, Any]) -> Iterator[tuple[int, Any, bytes]]:
        """(log time in ns, connection, raw bytes) of the messages of the
        ``wanted`` connections (by connection id), in log time order."""
        mine = {channel: conn for channel, conn in self.connections.items() if conn.id in wanted}
        if not mine:
            return
        topics = sorted({c.topic for c in mine.values()})
        for _, channel, message in self.reader.iter_messages(topics=topics, log_time_order=True):
            conn = mine.get(channel.id)
            if conn is not None:
                yield message.log_time, conn, message.data


class MixedMcap:
    """The MCAP files of a bag opened by :func:`open_mixed_mcap`, read as
    rosbags' ``AnyReader`` is: ``connections`` (one per channel of each
    file), ``messages``, ``deserialize`` and the ``typestore`` of their
    ROS 2 definitions."""

    is2 = True

    def __init__(self, path: Path, files: list[_McapFile], connections: list[Any], typestore):
        self.path = path
        self.connections = connections
        self.typestore = typestore
        self._files = files

    def messages(self, connections: Sequence[Any] | None = None) -> Iterator[tuple[Any, int, bytes]]:
        """(connection, log time in ns, raw bytes) of each message on
        ``connections`` (None: all), in the order of their log times across
        the files."""
        wanted = {c.id: c for c in (self.connections if connections is None else connections)}
        merged = heapq.merge(*(f.messages(wanted) for f in self._files), key=lambda m: m[0])
        for log_time, conn, data in merged:
            yield conn, log_time, data

    def deserialize(self, raw: bytes, msgtype: str) -> Any:
        return self.typestore.deserialize_cdr(raw, msgtype)

    def close(self) -> None:
        for f in self._files:
            f.stream.close()


def mcap_files(path: Path) -> list[Path]:
    """The MCAP files of a bag path: the file itself, or the ``.mcap``
    files of a rosbag2 folder (one, or several when it was split); none
    for anything else."""
    if path.is_file():
        return [path] if path.suffix == ".mcap" else []
    return sorted(path.glob("*.mcap")) if path.is_dir() else []


def open_mixed_mcap(path: Path, files: list[Path], refused: str) -> MixedMcap | None:
    """The bag ``path`` (rosbags refused it, saying ``refused``) opened here
    from its MCAP ``files``, if what rosbags refused is channels besides
    ROS 2's or a profile other than ``ros2``; None if every file is all
    ROS 2 or one is not a readable MCAP file, so that rosbags' own reason
    stands. A topic's channels of one type in several files are one
    connection, as in a split bag's metadata. Raises :class:`GslamError`
    when ``mcap`` is not installed or the files' ROS 2 definitions do not
    parse."""
    try:
        from mcap.reader import make_reader
    except ImportError:
        raise GslamError(f"{path}: not a readable ROS bag ({refused}); {MCAP_HINT}") from None
    streams = []
    try:
        summaries = []
        for file in files:
            streams.append(open(file, "rb"))
            try:
                reader = make_reader(streams[-1])
                summaries.append((reader, reader.get_summary(), reader.get_header()))
            except Exception:  # a broken file: rosbags has said why
                return _closed(streams)
            if summaries[-1][1] is None:
                return _closed(streams)
        # 1. Each channel's key (topic, encoding, schema) and message count, over every file.
        counts: dict[tuple, int] = {}
        first: dict[tuple, tuple] = {}  # key -> the first channel and schema of that key
        keys: list[dict[int, tuple]] = []
        for _, summary, _ in summaries:
            stats = summary.statistics.channel_message_counts if summary.statistics is not None else {}
            keys.append({})
            for ch in summary.channels.values():
                schema = summary.schemas.get(ch.schema_id)
                key = (ch.topic, ch.message_encoding, *((schema.name, schema.encoding, schema.data) if schema else ()))
                keys[-1][ch.id] = key
                counts[key] = counts.get(key, 0) + stats.get(ch.id, 0)
                first.setdefault(key, (ch, schema))
        # 2. One connection per key, and each file's channels mapped to theirs.
        shared = {key: _connection(k, *first[key], counts[key]) for k, key in enumerate(counts)}
        connections = list(shared.values())
        if all(header.profile == "ros2" for _, _, header in summaries) and not foreign_channels(connections):
            return _closed(streams)
        opened = [_McapFile(stream, reader, {ch_id: shared[key] for ch_id, key in file_keys.items()})
                  for stream, (reader, _, _), file_keys in zip(streams, summaries, keys)]
        return MixedMcap(path, opened, connections, _typestore(path, connections))
    except BaseException:
        _closed(streams)
        raise


def _closed(streams: list) -> None:
    """Close ``streams``; None: the bag is not for this reader."""
    for stream in streams:
        stream.close()
    return None


def _connection(conn_id: int, channel, schema, count: int) -> Any:
    """rosbags' Connection of an MCAP channel; one of another encoding
    than CDR, or a schema that is not a ROS 2 definition, has none."""
    from rosbags.interfaces import Connection, ConnectionExtRosbag2, MessageDefinition
    from rosbags.interfaces import MessageDefinitionFormat as Format

    formats = {"ros2msg": Format.MSG, "ros2idl": Format.IDL, "omgidl": Format.IDL}
    text = schema.data.decode("utf-8", "replace") if schema is not None else ""
    form = formats.get(schema.encoding) if schema is not None else None
    ros2 = channel.message_encoding == ROS2_ENCODING and form is not None
    msgdef = MessageDefinition(form, text) if ros2 else MessageDefinition(Format.NONE, "")
    msgtype = schema.name if schema is not None else ""
    return Connection(conn_id, channel.topic, msgtype, msgdef, "", count,
                      ConnectionExtRosbag2(channel.message_encoding, []), None)


def _typestore(path: Path, connections: list[Any]):
    """A type store of the ROS 2 definitions the file carries (the latest
    standard ones if it carries none), as rosbags' AnyReader builds it."""
    from rosbags.interfaces import MessageDefinitionFormat as Format
    from rosbags.typesys import Stores, get_types_from_idl, get_types_from_msg, get_typestore

    types: dict = {}
    defined = [c for c in connections if c.msgdef.format is not Format.NONE]
    for conn in defined:
        try:
            if conn.msgdef.format is Format.MSG:
                types.update(get_types_from_msg(conn.msgdef.data, conn.msgtype))
                continue
            sep = "=" * 80 + "\n"
            parts = conn.msgdef.data.split(sep)[1:] if conn.msgdef.data.startswith(f"{sep}IDL: ") else None
            for idl in [p.split("\n", 1)[1] for p in parts] if parts is not None else [conn.msgdef.data]:
                types.update(get_types_from_idl(idl))
        except Exception as err:  # rosbags' parsers raise several types
            why = str(err).strip().splitlines()[0] if str(err).strip() else type(err).__name__
            raise GslamError(f"{path}: topic '{conn.topic}': its definition of {conn.msgtype} does not parse "
                             f"({why})") from None
    store = get_typestore(Stores.EMPTY)
    store.register(types if defined else get_typestore(Stores.LATEST).fielddefs)
    return store
