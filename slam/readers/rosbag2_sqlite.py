"""A ROS 2 sqlite3 bag read with the standard library, where that is exact.

Opening a bag with rosbags costs a fifth of a second before the first
message: importing it, building a type store and parsing the bag's
metadata. For the common case, a rosbag2 folder of one uncompressed
``.db3`` file whose topics carry the standard message definitions, the
raw CDR bytes of a topic are one SQL query away, and :mod:`slam.readers.cdr`
decodes them in bulk. :func:`open_plain` says whether a bag is that case;
:meth:`PlainBag.raw` returns a topic's messages in the order rosbags
gives them (by receive time, ties in the order written), :meth:`PlainBag.raw_many`
those of several topics in one pass.

A topic qualifies only if its type's RIHS01 hash (REP-2011, stored by
rosbag2 since ROS 2 Iron) is the hash of the standard definition
(:data:`STANDARD_HASHES`): the definition the bulk decoder assumes, so no
cross-check with rosbags is needed. Bags without hashes (Humble and
older), compressed, split or MCAP bags, and foreign types are read with
rosbags. The file is opened read-only.

:func:`metadata_mismatch` says where a bag folder's metadata.yaml
disagrees with its sqlite3 files on their topics; the reader then reads
the files themselves, as the plain reader always does.
"""

from __future__ import annotations

import sqlite3
from dataclasses import dataclass
from pathlib import Path

import yaml

from slam.errors import GslamError
from validation.base.yamlio import SAFE_LOADER

# RIHS01 hashes of the standard definitions (ROS 2 Iron, Jazzy and later;
# tests/test_rosbag2_sqlite.py checks them against rosbags' type stores).
STANDARD_HASHES = {
    "sensor_msgs/msg/LaserScan": "RIHS01_64c191398013af96509d518dac71d5164f9382553fce5c1f8cca5be7924bd828",
    "sensor_msgs/msg/Imu": "RIHS01_7d9a00ff131080897a5ec7e26e315954b8eae3353c3f995c55faf71574000b5b",
    "sensor_msgs/msg/MagneticField": "RIHS01_e80f32f56a20486c9923008fc1a1db07bbb273cbbf6a5b3bfa00835ee00e4dff",
    "nav_msgs/msg/Odometry": "RIHS01_3cc97dc7fb7502f8714462c526d369e35b603cfc34d946e3f2eda2766dfec6e0",
    "geometry_msgs/msg/PoseStamped": "RIHS01_10f3786d7d40fd2b54367835614bff85d4ad3b5dab62bf8bca0cc232d73b4cd8",
    "sensor_msgs/msg/NavSatFix": "RIHS01_62223ab3fe210a15976021da7afddc9e200dc9ec75231c1b6a557fc598a65404",
}


@dataclass(frozen=True)
class Topic:
    """One topic of a plain bag: its id in the file and its message type."""

    id: int
    msgtype: str


class PlainBag:
    """An open plain bag (see :func:`open_plain`); close it after use."""

    def __init__(self, db: Path, conn: sqlite3.Connection, topics: dict[str, Topic]):
        self.db = db
        self.topics = topics
        self._conn = conn

    def raw(self, topic: str) -> list[bytes]:
        """The CDR bytes of every message on ``topic``, in rosbags' order;
        a message stored as text or a number (a database edited by hand, or
        written by another tool) is refused naming the topic and the row."""
        return self.raw_many([topic])[topic]

    def raw_many(self, topics: list[str]) -> dict[str, list[bytes]]:
        """:meth:`raw` of each of ``topics``, read in one pass over the
        table: a query per topic walks the whole timestamp index each time
        (six topics of telemax_lab: 0.10-0.15 s against 0.06-0.08 s)."""
        ids = {self.topics[t].id: t for t in topics}
        query = (f"SELECT topic_id, id, data FROM messages WHERE topic_id IN ({', '.join('?' * len(ids))}) "
                 "ORDER BY timestamp, id")
        try:
            rows = self._conn.execute(query, tuple(ids)).fetchall()
        except sqlite3.Error as err:
            raise GslamError(f"{self.db}: corrupt bag ({err})") from None
        by_topic: dict[str, list[tuple[int, int, object]]] = {t: [] for t in topics}
        for message in rows:
            by_topic[ids[message[0]]].append(message)
        for topic, messages in by_topic.items():
            for k, (_, row, data) in enumerate(messages):
                if not isinstance(data, bytes):
                    raise GslamError(
                        f"{self.db}: corrupt bag: topic '{topic}', message {k} (row {row} of table messages) holds "
                        f"{type(data).__name__ if data is not None else 'nothing'}; expected the bytes of a CDR message"
                    )
        return {topic: [data for _, _, data in messages] for topic, messages in by_topic.items()}

    def close(self) -> None:
        self._conn.close()


def open_plain(path: Path) -> PlainBag | None:
    """``path`` (a rosbag2 folder) as a :class:`PlainBag`, or None when
    rosbags must read it (see the module docstring). Never raises for a
    bag rosbags may still read: anything unexpected means None."""
    try:
        return _open_plain(path)
    except (OSError, sqlite3.Error, yaml.YAMLError, KeyError, TypeError, ValueError, AttributeError):
        return None


def _open_plain(path: Path) -> PlainBag | None:
    meta_file = path / "metadata.yaml"
    if not path.is_dir() or not meta_file.is_file():
        return None
    info = yaml.load(meta_file.read_text(), Loader=SAFE_LOADER)["rosbag2_bagfile_information"]
    files = info.get("relative_file_paths") or []
    if info.get("storage_identifier") != "sqlite3" or info.get("compression_mode") or len(files) != 1:
        return None
    db = path / files[0]
    if db.suffix != ".db3" or not db.is_file():
        return None
    conn = sqlite3.connect(f"{db.resolve().as_uri()}?mode=ro", uri=True)
    try:
        topics = _standard_topics(conn)
    except BaseException:
        conn.close()
        raise
    if topics is None:
        conn.close()
        return None
    return PlainBag(db, conn, topics)


@dataclass(frozen=True)
class Mismatch:
    """What a rosbag2 folder's metadata.yaml says of its topics that its
    sqlite3 files do not hold: the first difference in words, how many
    there are, and the files, which are read instead."""

    said: str
    count: int
    files: list[Path]


def metadata_mismatch(path: Path) -> Mismatch | None:
    """Where the metadata.yaml of the rosbag2 folder ``path`` disagrees with
    its uncompressed sqlite3 files on the topics they hold (a name, a
    message type, a serialization format, a type hash or a message count),
    or None if it agrees, or if the bag is of another storage or cannot be
    compared (the readers say why). rosbags takes the topics from the
    metadata and matches the files' messages to them: a topic whose type,
    format or hash the metadata misstates gave no messages at all, one the
    metadata leaves out was not in the bag, though the file holds them."""
    try:
        return _metadata_mismatch(path)
    except (OSError, sqlite3.Error, yaml.YAMLError, KeyError, TypeError, ValueError, AttributeError):
        return None


def _metadata_mismatch(path: Path) -> Mismatch | None:
    info = yaml.load((path / "metadata.yaml").read_text(), Loader=SAFE_LOADER)["rosbag2_bagfile_information"]
    if info.get("storage_identifier") != "sqlite3" or info.get("compression_mode"):
        return None
    files = [path / name for name in info["relative_file_paths"]]
    listed: dict[str, tuple] = {}
    for entry in info["topics_with_message_count"]:
        meta = entry["topic_metadata"]
        listed[meta["name"]] = (meta["type"], meta["serialization_format"], meta.get("type_description_hash") or "",
                                entry["message_count"])
    held: dict[str, list] = {}
    for file in files:
        conn = sqlite3.connect(f"{file.resolve().as_uri()}?mode=ro", uri=True)
        try:
            hashed = "type_description_hash" in {row[1] for row in conn.execute("PRAGMA table_info(topics)")}
            type_hash_column = "type_description_hash" if hashed else "''"
            counts = dict(conn.execute("SELECT topic_id, count(*) FROM messages GROUP BY topic_id"))
            rows = conn.execute(f"SELECT id, name, type, serialization_format, {type_hash_column} FROM topics")
            for topic_id, name, msgtype, fmt, type_hash in rows:
                count = counts.get(topic_id, 0)
                if name in held:
                    held[name][3] += count
                else:
                    held[name] = [msgtype, fmt, type_hash or "", count]
        finally:
            conn.close()
    where = " and ".join(f.name for f in files)
    found = []
    for name in sorted(set(listed) | set(held)):
        if name not in held:
            found.append(f"lists topic '{name}', which {where} does not hold")
        elif name not in listed:
            found.append(f"does not list topic '{name}', which {where} holds ({held[name][0]})")
        else:
            (m_type, m_fmt, m_hash, m_count), (d_type, d_fmt, d_hash, d_count) = listed[name], held[name]
            if m_type != d_type:
                found.append(f"lists topic '{name}' as {m_type}, {where} holds it as {d_type}")
            elif m_fmt != d_fmt:
                found.append(f"lists topic '{name}' as {m_fmt}, {where} holds it as {d_fmt}")
            elif m_hash and d_hash and m_hash != d_hash:
                found.append(f"lists topic '{name}' with type hash {m_hash}, {where} holds it with {d_hash}")
            elif m_count != d_count:
                found.append(f"lists {m_count} messages on topic '{name}', {where} holds {d_count}")
    return Mismatch(found[0], len(found), files) if found else None


def _standard_topics(conn: sqlite3.Connection) -> dict[str, Topic] | None:
    """The topics of the bag open on ``conn`` that carry a standard
    definition, or None when rosbags must read the bag."""
    columns = {row[1] for row in conn.execute("PRAGMA table_info(topics)")}
    if "type_description_hash" not in columns:
        return None
    rows = conn.execute("SELECT id, name, type, serialization_format, type_description_hash FROM topics").fetchall()
    names = [row[1] for row in rows]
    if len(set(names)) != len(names):  # a topic with two types or connections: rosbags sorts that out
        return None
    return {
        name: Topic(int(topic_id), msgtype)
        for topic_id, name, msgtype, fmt, type_hash in rows
        if fmt == "cdr" and STANDARD_HASHES.get(msgtype) == type_hash
    }
