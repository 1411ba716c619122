"""An MCAP file that holds channels besides ROS 2's, which rosbags refuses.

rosbags opens an MCAP file only if it is all ROS 2: the ``ros2`` profile
and every channel's schema a ROS 2 definition (``ros2msg``, ``ros2idl``,
``omgidl`` or none). A recording where a tool added a channel of its own
(JSON with a ``jsonschema``, protobuf, flatbuffers: Foxglove's messages, a
logger's diagnostics) is refused as a whole, though the topics a run
needs are ROS 2 messages like any other.

:func:`open_mixed_mcap` reads such a file with the ``mcap`` package: each
channel becomes rosbags' :class:`~rosbags.interfaces.Connection` (one of
another encoding with no definition), the messages stay raw bytes, and
the ROS 2 ones are deserialised by a type store of the file's own
definitions, built as rosbags' ``AnyReader`` builds it.
:mod:`slam.readers.rosbag` reads the needed topics from it as from
rosbags, and skips the channels it cannot decode, naming each
(:func:`foreign_channels`).
"""

from __future__ import annotations

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


class MixedMcap:
    """An MCAP file opened by :func:`open_mixed_mcap`, read as rosbags'
    ``AnyReader`` is: ``connections``, ``messages``, ``deserialize`` and
    the ``typestore`` of its ROS 2 definitions."""

    is2 = True

    def __init__(self, path: Path, stream, reader, connections: list[Any], typestore):
        self.path = path
        self.connections = connections
        self.typestore = typestore
        self._stream, self._reader = stream, reader

    def messages(self, connections: Sequence[Any] | None = None) -> Iterator[tuple[Any, int, bytes]]:
        """(connection, log time in ns, raw bytes) of each message on
        ``connections`` (None: all), in the order of their log times."""
        by_id = {c.id: c for c in (self.connections if connections is None else connections)}
        topics = sorted({c.topic for c in by_id.values()})
        for _, channel, message in self._reader.iter_messages(topics=topics, log_time_order=True):
            conn = by_id.get(channel.id)
            if conn is not None:
                yield conn, message.log_time, message.data

    def deserialize(self, raw: bytes, msgtype: str) -> Any:
        return self.typestore.deserialize_cdr(raw, msgtype)

    def close(self) -> None:
        self._stream.close()


def mcap_file(path: Path) -> Path | None:
    """The MCAP file of a bag path: the file itself, or the one ``.mcap``
    file of a rosbag2 folder; None for anything else."""
    if path.is_file():
        return path if path.suffix == ".mcap" else None
    files = sorted(path.glob("*.mcap")) if path.is_dir() else []
    return files[0] if len(files) == 1 else None


def open_mixed_mcap(path: Path, refused: str) -> MixedMcap | None:
    """``path`` (an MCAP file rosbags refused, saying ``refused``) opened
    here, if what rosbags refused is channels besides ROS 2's or a profile
    other than ``ros2``; None if the file is all ROS 2 or not a readable
    MCAP file, so that rosbags' own reason stands. Raises
    :class:`GslamError` when ``mcap`` is not installed or the file's ROS 2
    definitions do not parse."""
    try:
        from mcap.reader import make_reader
    except ImportError:
        raise GslamError(f"{path}: not a readable ROS bag ({refused}); {MCAP_HINT}") from None
    stream = open(path, "rb")
    try:
        reader = make_reader(stream)
        summary = reader.get_summary()
        header = reader.get_header()
    except Exception:  # a broken file: rosbags has said why
        stream.close()
        return None
    if summary is None:
        stream.close()
        return None
    counts = summary.statistics.channel_message_counts if summary.statistics is not None else {}
    connections = [_connection(ch, summary.schemas.get(ch.schema_id), counts.get(ch.id, 0))
                   for ch in summary.channels.values()]
    if header.profile == "ros2" and not foreign_channels(connections):
        stream.close()
        return None
    try:
        typestore = _typestore(path, connections)
    except BaseException:
        stream.close()
        raise
    return MixedMcap(path, stream, reader, connections, typestore)


def _connection(channel, schema, count: int) -> Any:
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
    return Connection(channel.id, channel.topic, msgtype, msgdef, "", count,
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
