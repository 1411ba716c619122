"""The plain sqlite3 path of the ROS 2 bag reader (slam.readers.rosbag2_sqlite)
reads the same recording as rosbags, and hands over to rosbags wherever it
cannot be sure."""

from __future__ import annotations

import dataclasses
import sqlite3

import numpy as np
import pytest
from rosbags.typesys import Stores, get_typestore

import slam.readers.rosbag as rosbag
from bagfactory import driving_bag
from slam.config import InputConfig
from slam.errors import GslamError
from slam.readers.rosbag2_sqlite import STANDARD_HASHES, open_plain


@pytest.mark.parametrize("store", [Stores.ROS2_IRON, Stores.ROS2_JAZZY, Stores.LATEST])
def test_standard_hashes_are_those_of_the_ros2_definitions(store):
    types = get_typestore(store)
    for msgtype, expected in STANDARD_HASHES.items():
        assert types.hash_rihs01(msgtype) == expected, msgtype


def _fields(rec) -> dict:
    out = {}
    for f in dataclasses.fields(rec):
        value = getattr(rec, f.name)
        if dataclasses.is_dataclass(value):
            for g in dataclasses.fields(value):
                out[f"{f.name}.{g.name}"] = getattr(value, g.name)
        else:
            out[f.name] = value
    return out


def _assert_same(a, b) -> None:
    fa, fb = _fields(a), _fields(b)
    assert fa.keys() == fb.keys()
    for key, value in fa.items():
        if isinstance(value, np.ndarray):
            np.testing.assert_array_equal(value, fb[key], err_msg=key)
        else:
            assert value == fb[key], key


def _read(path, plain: bool, monkeypatch) -> tuple:
    """The recording and the scans handed over early, with or without the plain path."""
    with monkeypatch.context() as m:
        if not plain:
            m.setattr(rosbag.rosbag2_sqlite, "open_plain", lambda p: None)
        early = []
        rec = rosbag.read_rosbag(path, InputConfig(), on_scans=early.append)
    return rec, early


def _bag(tmp_path):
    return driving_bag(ros=2, duration_s=3.0).write(tmp_path / "run")


def test_plain_and_rosbags_read_the_same_recording(tmp_path, monkeypatch):
    path = _bag(tmp_path)
    plain = open_plain(path)
    assert plain is not None and "/scan" in plain.topics  # the plain path is taken
    plain.close()
    a, early_a = _read(path, True, monkeypatch)
    b, early_b = _read(path, False, monkeypatch)
    _assert_same(a, b)
    assert len(early_a) == len(early_b) == 1
    _assert_same(early_a[0], early_b[0])


def _set_hash(path, msgtype: str, type_hash: str) -> None:
    """Give ``msgtype`` another type hash, in the topics and the definitions alike."""
    conn = sqlite3.connect(next(path.glob("*.db3")))
    conn.execute("UPDATE topics SET type_description_hash = ? WHERE type = ?", (type_hash, msgtype))
    conn.execute("UPDATE message_definitions SET type_description_hash = ? WHERE topic_type = ?", (type_hash, msgtype))
    conn.commit()
    conn.close()


def test_topics_without_the_standard_hash_are_read_by_rosbags(tmp_path, monkeypatch):
    path = _bag(tmp_path)
    reference, _ = _read(path, False, monkeypatch)
    # Scans and IMU as in a bag from before type hashes (ROS 2 Humble): rosbags reads them.
    _set_hash(path, "sensor_msgs/msg/Imu", "")
    _set_hash(path, "sensor_msgs/msg/LaserScan", "")
    plain = open_plain(path)
    assert plain is not None and "/scan" not in plain.topics and "/imu/data" not in plain.topics
    assert "/odom" in plain.topics
    plain.close()
    rec, early = _read(path, True, monkeypatch)
    _assert_same(rec, reference)
    assert len(early) == 1
    # A type whose definition is not the standard one is never decoded here.
    _set_hash(path, "sensor_msgs/msg/MagneticField", "RIHS01_" + "0" * 64)
    plain = open_plain(path)
    assert "/imu/mag" not in plain.topics
    plain.close()


def test_compressed_split_or_foreign_bags_are_not_plain(tmp_path):
    path = _bag(tmp_path)
    meta = path / "metadata.yaml"
    text = meta.read_text()
    meta.write_text(text.replace("compression_mode: ''", "compression_mode: MESSAGE"))
    assert open_plain(path) is None
    meta.write_text(text.replace("storage_identifier: sqlite3", "storage_identifier: mcap"))
    assert open_plain(path) is None
    meta.write_text("not: [yaml")
    assert open_plain(path) is None
    assert open_plain(tmp_path / "nowhere") is None


def test_the_plain_path_never_writes_the_bag(tmp_path, monkeypatch):
    path = _bag(tmp_path)
    before = {p.name: p.read_bytes() for p in path.iterdir()}
    _read(path, True, monkeypatch)
    assert {p.name: p.read_bytes() for p in path.iterdir()} == before


def test_corrupt_messages_are_one_line_errors(tmp_path):
    path = _bag(tmp_path)
    db = next(path.glob("*.db3"))
    data = bytearray(db.read_bytes())
    # Overwrite the second half of the file (message pages), keep the schema pages.
    half = len(data) // 2
    data[half:] = b"\xff" * (len(data) - half)
    db.write_bytes(bytes(data))
    with pytest.raises(GslamError, match="corrupt bag|not a readable ROS bag|non-finite"):
        rosbag.read_rosbag(path, InputConfig())
