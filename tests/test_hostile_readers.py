"""The eleventh attack, on what gslam reads: every reader and every file
read back, fed what it has not seen in tests/test_fuzz.py or
tests/test_hostile.py.

* a ROS 2 bag's metadata.yaml that is no mapping of its own key, not
  UTF-8, or that disagrees with its database on a topic's name, type,
  serialization format, type hash or message count (rosbags matches the
  database's messages to the metadata's topics: a misstated topic gave
  no messages, 'none recorded', in silence about why);
* a bag database edited or damaged: a message stored as text, cut short
  or with bytes past its end, tables dropped, every message twice,
  receive times reversed, messages of no topic, a topic of another type,
  encoding or type hash;
* truth.json read back: a truth value for a number, a negative duration,
  an integer of thousands of digits, values physics forbids;
* the system model a config names, as text that is not UTF-8 or no text;
* libRSF ground truth and loop lines, and CARMEN logs cut or joined.

Error cases run as tests/test_hostile.py's do (exit 1, one error line
naming the place and what was expected, no traceback, no hang, nothing of
the user's changed); warning cases map with one warning line saying what
the case expects and write the result.
"""

from __future__ import annotations

import gzip
import json
import logging
import os
import sqlite3
from collections.abc import Callable
from pathlib import Path

import pytest
import yaml

from tests.conftest import CONFIGS, TELEMAX_CONFIG
from tests.test_fuzz import (  # noqa: F401 - world is a fixture
    Case, World, both, copy_run, text, world,
)
from tests.test_hostile import CARMEN, LIBRSF, QUICK, Warned, _run, carmen, librsf_with, run_error, run_warned

pytestmark = pytest.mark.slow  # end to end: pytest -m 'not slow' leaves it out

RUN_MAP = ("map", "{d}/run", "--config", "{cfg}", *QUICK, "--out", "{d}/o")
RUN_INJECT = ("inject", "{d}/run", "--fault", "gyro_bias@2:4", "--out", "{d}/o")
RUN_CALIBRATE = ("calibrate", "{d}/run", "--config", "{cfg}", "--out", "{d}/m.yaml")
MODEL = CONFIGS / "validation" / "telemax_model.yaml"


# --- input builders ----------------------------------------------------------------


def metadata(change: Callable[[dict], None]) -> Callable[[Path], None]:
    """A run folder change: ``change`` applied to its bag's rosbag2_bagfile_information."""

    def run_change(run: Path) -> None:
        tree = yaml.safe_load((run / "bag" / "metadata.yaml").read_text())
        change(tree["rosbag2_bagfile_information"])
        (run / "bag" / "metadata.yaml").write_text(yaml.safe_dump(tree))

    return run_change


def metadata_bytes(change: Callable[[bytes], bytes]) -> Callable[[Path], None]:
    def run_change(run: Path) -> None:
        (run / "bag" / "metadata.yaml").write_bytes(change((run / "bag" / "metadata.yaml").read_bytes()))

    return run_change


def listed_topic(topic: str, **values) -> Callable[[dict], None]:
    """A metadata change: ``topic``'s topic_metadata updated with ``values``."""

    def change(info: dict) -> None:
        (entry,) = [e for e in info["topics_with_message_count"] if e["topic_metadata"]["name"] == topic]
        entry["topic_metadata"].update(values)

    return change


def listed_count(name: str, count) -> Callable[[dict], None]:
    def change(info: dict) -> None:
        (entry,) = [e for e in info["topics_with_message_count"] if e["topic_metadata"]["name"] == name]
        entry["message_count"] = count

    return change


def sql(query: str, *args) -> Callable[[Path], None]:
    """A run folder change: ``query`` run on its bag's database."""

    def run_change(run: Path) -> None:
        conn = sqlite3.connect(run / "bag" / "bag.db3")
        conn.execute(query, args)
        conn.commit()
        conn.close()

    return run_change


def first_message(topic: str, change: Callable[[bytes], object]) -> Callable[[Path], None]:
    """A run folder change: the first message of ``topic`` in its bag's database replaced by ``change(data)``."""

    def run_change(run: Path) -> None:
        conn = sqlite3.connect(run / "bag" / "bag.db3")
        (topic_id,) = conn.execute("SELECT id FROM topics WHERE name = ?", (topic,)).fetchone()
        row, data = conn.execute("SELECT id, data FROM messages WHERE topic_id = ? ORDER BY id", (topic_id,)).fetchone()
        conn.execute("UPDATE messages SET data = ? WHERE id = ?", (change(data), row))
        conn.commit()
        conn.close()

    return run_change


def truth(change: Callable[[dict], None]) -> Callable[[Path], None]:
    def run_change(run: Path) -> None:
        tree = json.loads((run / "truth.json").read_text())
        change(tree)
        (run / "truth.json").write_text(json.dumps(tree, indent=2))

    return run_change


def truth_text(old: str, new: str) -> Callable[[Path], None]:
    def run_change(run: Path) -> None:
        (run / "truth.json").write_text((run / "truth.json").read_text().replace(old, new))

    return run_change


def with_model(content: bytes | None) -> Callable[[Path, World], None]:
    """``{d}/c.yaml``: configs/telemax.yaml naming ``m.yaml`` beside it as its
    system model, and ``{d}/m.yaml`` holding ``content`` (None: no such file)."""

    def make(d: Path, world: World) -> None:
        tree = yaml.safe_load(TELEMAX_CONFIG.read_text())
        tree["validation"]["model"] = "m.yaml"
        (d / "c.yaml").write_text(yaml.safe_dump(tree, sort_keys=False))
        if content is not None:
            (d / "m.yaml").write_bytes(content)

    return make


def gzipped_log(extra: bytes) -> Callable[[Path, World], None]:
    """The CARMEN log of tests/test_hostile.py gzipped at ``{d}/c.log.gz``, ``extra`` after the gzip stream."""

    def make(d: Path, world: World) -> None:
        carmen()(d, world)
        (d / "c.log.gz").write_bytes(gzip.compress((d / "c.log").read_bytes()) + extra)
        (d / "c.log").unlink()

    return make


def _last_line_cut(log: str) -> bytes:
    lines = log.rstrip("\n").split("\n")
    return "\n".join([*lines[:-3], lines[-3][:60]]).encode() + b"\n"


def _ground_truth(rows: Callable[[int], str]) -> str:
    return "".join(rows(k) + "\n" for k in range(100))


MODEL_TEXT = MODEL.read_bytes()
WITH_MODEL = ("map", "{run}", "--config", "{d}/c.yaml", "--gating", "on", *QUICK, "--out", "{d}/o")
LOOP = "loop 9.0 1.0 1"


# --- the error corpus -------------------------------------------------------------


ERRORS: list[Case] = [
    # -- a bag's metadata.yaml that is no mapping of rosbag2_bagfile_information, or no UTF-8 text --
    *(Case(f"bag-metadata-{name}", RUN_MAP, says, copy_run(change))
      for name, change, says in (
          ("empty", metadata_bytes(lambda b: b""), "bag/metadata.yaml: expected a mapping holding "
           "rosbag2_bagfile_information (the metadata ros2 bag record writes), found an empty file"),
          ("a-list", metadata_bytes(lambda b: b"- 1\n- 2\n"), "bag/metadata.yaml: expected a mapping holding "
           "rosbag2_bagfile_information (the metadata ros2 bag record writes), found a YAML list"),
          ("without-its-key", metadata_bytes(lambda b: b"rosbag2_info: {}\n"), "bag/metadata.yaml: expected a "
           "mapping holding rosbag2_bagfile_information (the metadata ros2 bag record writes), found keys 'rosbag2_info'"),
          ("its-key-a-list", metadata_bytes(lambda b: b"rosbag2_bagfile_information: [1]\n"),
           "found rosbag2_bagfile_information of a list"),
          ("latin1-comment", metadata_bytes(lambda b: b + b"# enregistr\xe9\n"),
           "bag/metadata.yaml: line 71: byte 0xE9 is not UTF-8 text (a Latin-1 character?); expected a YAML bag "
           "metadata file in UTF-8"),
          ("utf16", metadata_bytes(lambda b: b.decode().encode("utf-16")),
           "bag/metadata.yaml: UTF-16 text; expected a YAML bag metadata file in UTF-8 (save it as UTF-8)"),
          ("nul-bytes", metadata_bytes(lambda b: b[:200] + b"\0" * 64 + b[200:]),
           "bag/metadata.yaml: binary content; expected a YAML bag metadata file (text)"),
          ("storage-of-no-plugin", metadata(lambda i: i.update(storage_identifier="hdf5")),
           "Storage plugin 'hdf5' not supported"),
      )),
    # -- a bag's database: a message stored as text, where each command reads the bag --
    *(Case(f"{command}-bag-message-stored-as-text", argv, "bag/bag.db3: corrupt bag: topic '/imu/data', message 0 "
           "(row 3 of table messages) holds str; expected the bytes of a CDR message",
           copy_run(first_message("/imu/data", lambda data: "hello")))
      for command, argv in (("map", RUN_MAP), ("inject", RUN_INJECT), ("calibrate", RUN_CALIBRATE))),
    # -- messages cut short or with bytes past their end, tables dropped --
    *(Case(f"bag-{name}", RUN_MAP, says, copy_run(change))
      for name, change, says in (
          ("scan-cut-short", first_message("/scan", lambda data: data[:40]),
           "bag: corrupt bag (Could not deserialize 'sensor_msgs/msg/LaserScan'"),
          ("odometry-cut-short", first_message("/odom", lambda data: data[:40]),
           "bag: corrupt bag (Could not deserialize 'nav_msgs/msg/Odometry'"),
          ("imu-bytes-past-its-end", first_message("/imu/data", lambda data: data + bytes(64)),
           "bag: corrupt bag (CDR message size mismatch for 'sensor_msgs/msg/Imu'.)"),
          ("imu-message-empty", first_message("/imu/data", lambda data: b""),
           "bag: corrupt bag (Invalid or unsupported CDR encapsulation.)"),
          ("messages-table-dropped", sql("DROP TABLE messages"), "bag/bag.db3: corrupt bag (no such table: messages)"),
          ("topics-table-dropped", sql("DROP TABLE topics"), "or database missing tables"),
          ("every-message-twice", sql("INSERT INTO messages (topic_id, timestamp, data) "
                                      "SELECT topic_id, timestamp, data FROM messages"),
           "scan topic '/scan': duplicate header stamp at message 1"),
          ("receive-times-reversed", sql("UPDATE messages SET timestamp = -timestamp"),
           "scan topic '/scan': decreasing header stamp at message 1"),
      )),
    # -- a topic of the database whose type, encoding or type hash the metadata misstates: 'no messages' before --
    *(Case(f"{command}-bag-db-{name}", argv, says, copy_run(change))
      for command, argv in (("map", RUN_MAP), ("inject", RUN_INJECT))
      for name, change, says in (
          ("odometry-of-a-drivers-type", sql("UPDATE topics SET type = 'my_msgs/msg/Odo' WHERE name = '/odom'"),
           "bag: odometry topic '/odom': type is my_msgs/msg/Odo, expected nav_msgs/msg/Odometry"),
          ("odometry-in-json", sql("UPDATE topics SET serialization_format = 'json' WHERE name = '/odom'"),
           "bag: odometry topic '/odom': its messages are json, expected ROS 2's CDR (a nav_msgs/msg/Odometry)"),
      )),
    Case("bag-db-scan-of-a-foreign-type-hash", RUN_MAP, "bag: not a readable ROS bag (Message type "
         "'sensor_msgs/msg/LaserScan' hash mismatch", copy_run(sql("UPDATE topics SET type_description_hash = "
                                                                   "'RIHS01_00' WHERE name = '/scan'"))),
    # -- truth.json read back --
    *(Case(f"truth-{name}", RUN_MAP, says, copy_run(change))
      for name, change, says in (
          ("fault-interval-starting-at-true", truth(lambda t: t["faults"].update(GPS=[[True, 2.0]])),
           "truth.json: faults.GPS.0.0: expected a number, not true"),
          ("seed-false", truth(lambda t: t.update(seed=False)), "truth.json: seed: expected a number, not false"),
          ("duration-negative", truth(lambda t: t.update(duration_s=-3.0)),
           "truth.json: duration_s: Input should be greater than or equal to 0"),
          ("seed-of-5000-digits", truth_text('"seed": 3', '"seed": ' + "1" * 5000),
           "truth.json: an integer of 5,000 digits (11111111...); expected a number of at most 30 digits"),
          ("t0-1e400", truth_text("1700000000.0", "1e400"), "truth.json: t0: Input should be a finite number"),
          ("fault-interval-of-three", truth(lambda t: t["faults"].update(GPS=[[1.0, 2.0, 3.0]])),
           "truth.json: faults.GPS.0: Tuple should have at most 2 items"),
          ("faults-a-list", truth(lambda t: t.update(faults=[1, 2])), "truth.json: faults: Input should be a valid "
                                                                      "dictionary"),
          ("magnetic-dip-100-rad", truth(lambda t: t["magnetic_reference"].update(dip_rad=100.0)),
           "truth.json: magnetic_reference.dip_rad: 100 rad is above 1.5708 rad"),
          ("magnetic-field-negative", truth(lambda t: t["magnetic_reference"].update(strength_T=-4e-5)),
           "truth.json: magnetic_reference.strength_T: -4e-05 T is below 1e-06 T"),
      )),
    Case("inject-truth-fault-interval-ending-at-true", RUN_INJECT, "truth.json: faults.IMU_YAW.0.1: expected a number, "
         "not true", copy_run(truth(lambda t: t["faults"].update(IMU_YAW=[[1.0, True]])))),
    Case("calibrate-truth-seed-of-5000-digits", RUN_CALIBRATE, "truth.json: an integer of 5,000 digits",
         copy_run(truth_text('"seed": 3', '"seed": ' + "1" * 5000))),
    # -- the system model a config names: said once as a YAML file ('a YAML YAML file' before) --
    *(Case(f"model-{name}", WITH_MODEL, says, with_model(content))
      for name, content, says in (
          ("latin1-comment", MODEL_TEXT + b"# r\xe9glages\n", "m.yaml: line 95: byte 0xE9 is not UTF-8 text (a Latin-1 "
                                                            "character?); expected a YAML file in UTF-8"),
          ("utf16", MODEL_TEXT.decode().encode("utf-16"), "m.yaml: UTF-16 text; expected a YAML file in UTF-8 (save it "
                                                          "as UTF-8)"),
          ("nul-bytes", MODEL_TEXT[:100] + b"\0" + MODEL_TEXT[100:], "m.yaml: binary content; expected a YAML file (text)"),
          ("a-list", b"- a\n- b\n", "m.yaml: expected a YAML mapping of keys at the top level, found a list"),
          ("missing-beside-the-config", None, "m.yaml: cannot read YAML file (No such file or directory)"),
      )),
    # -- libRSF ground truth and loops --
    *(Case(f"librsf-{name}", LIBRSF, says, make)
      for name, make, says in (
          ("ground-truth-utf16", both(librsf_with(LOOP), lambda d, w: (d / "X_GT.txt").write_bytes(_ground_truth(
              lambda k: f"point2 {0.1 * k:.1f} {0.05 * k} 0 0.1 0 0 0.1").encode("utf-16"))),
           "X_GT.txt: cannot read: UTF-16 text; expected a libRSF text file in ASCII or UTF-8"),
          ("ground-truth-nul-bytes", librsf_with(LOOP, "\0" * 400),
           "X_GT.txt: cannot read: not a libRSF text file (binary content)"),
          ("ground-truth-on-another-clock", librsf_with(LOOP, _ground_truth(
              lambda k: f"point2 {1e6 + 0.1 * k:.1f} {0.05 * k} 0 0.1 0 0 0.1")),
           "groundtruth stamps (1e+06 to 1.00001e+06 s) do not overlap the other streams' (0 to 9.9 s)"),
          ("ground-truth-stamps-repeat", librsf_with(LOOP, _ground_truth(
              lambda k: f"point2 {0.1 * (k // 2):.1f} {0.05 * k} 0 0.1 0 0 0.1")),
           "X_GT.txt: point2 line #2: expected increasing times, got 0.0 after 0.0"),
          ("ground-truth-backwards", librsf_with(LOOP, _ground_truth(
              lambda k: f"point2 {10 - 0.1 * k:.1f} {0.05 * k} 0 0.1 0 0 0.1")),
           "X_GT.txt: point2 line #2: expected increasing times, got 9.9 after 10.0"),
          ("ground-truth-empty", librsf_with(LOOP, ""), "X_GT.txt: expected 'point2 t x y c_xx c_xy c_yx c_yy' lines, "
                                                        "found none"),
          ("ground-truth-nan", librsf_with(LOOP, _ground_truth(lambda k: f"point2 {0.1 * k:.1f} nan 0 0.1 0 0 0.1")),
           "X_GT.txt:1: expected point2 t x y c_xx c_xy c_yx c_yy"),
          ("odom2-stamps-repeat", text("X_Input.txt", "".join(f"odom2 {0.1 * (k // 2):.1f} 0.5 0 0 0.01 0.01 0.01\n"
                                                              for k in range(100)) + LOOP + "\n"),
           "X_Input.txt: odom2 line #2: expected increasing times, got 0.0 after 0.0"),
      )),
    # -- a ground truth beside the log that is no file: mapped without truth before, saying there was none --
    *(Case(f"librsf-ground-truth-{name}", LIBRSF, says, both(librsf_with(LOOP), make))
      for name, make, says in (
          ("a-folder", lambda d, w: (d / "X_GT.txt").mkdir(), "X_GT.txt: cannot read libRSF ground truth (a folder; "
                                                              "expected a file)"),
          ("a-named-pipe", lambda d, w: os.mkfifo(d / "X_GT.txt"), "X_GT.txt: cannot read libRSF ground truth: it is a "
                                                                   "named pipe, not a regular file"),
          ("a-link-to-nothing", lambda d, w: (d / "X_GT.txt").symlink_to(d / "gone.txt"),
           "X_GT.txt: a symbolic link to"),
      )),
    # -- CARMEN logs cut short or joined to bytes of no log --
    Case("carmen-last-line-cut", CARMEN, "c.log:118: expected FLASER n r_1..r_n x y theta odom_x odom_y odom_theta ts "
         "host logger_ts (192 fields, got 9)",
         carmen(encoding=_last_line_cut)),
    Case("carmen-gz-with-bytes-after-its-stream", (*CARMEN[:1], "{d}/c.log.gz", *CARMEN[2:]),
         "c.log.gz: not a valid gzip file", gzipped_log(b"garbage!")),
]


# --- the warning corpus: usable recordings, one warning each -----------------------


WARNINGS: list[Warned] = [
    # -- a bag's metadata.yaml that misstates its database: read as the database holds it, said once --
    *(Warned(f"bag-metadata-{name}", RUN_MAP, f"bag/metadata.yaml: {says}; read as bag.db3 holds them",
             copy_run(change), '"n_poses"')
      for name, change, says in (
          ("odometry-listed-as-imu", metadata(listed_topic("/odom", type="sensor_msgs/msg/Imu")),
           "lists topic '/odom' as sensor_msgs/msg/Imu, bag.db3 holds it as nav_msgs/msg/Odometry"),
          ("odometry-renamed", metadata(listed_topic("/odom", name="/odometry")),
           "does not list topic '/odom', which bag.db3 holds (nav_msgs/msg/Odometry) (and 1 more such difference)"),
          ("odometry-listed-as-json", metadata(listed_topic("/odom", serialization_format="json")),
           "lists topic '/odom' as json, bag.db3 holds it as cdr"),
          ("scan-count-a-word", metadata(listed_count("/scan", "many")),
           "lists many messages on topic '/scan', bag.db3 holds 240"),
          ("gyro-count-of-another-bag", metadata(listed_count("/imu/data", 10)),
           "lists 10 messages on topic '/imu/data', bag.db3 holds 2400"),
          ("messages-of-no-topic", sql("UPDATE messages SET topic_id = 99 WHERE topic_id = "
                                       "(SELECT id FROM topics WHERE name = '/gps/fix') AND id % 2 = 0"),
           "lists 120 messages on topic '/gps/fix', bag.db3 holds 60"),
      )),
]


# --- the tests ----------------------------------------------------------------------


@pytest.mark.parametrize("case", ERRORS, ids=[c.id for c in ERRORS])
def test_a_hostile_file_read_gives_one_clean_error(case: Case, world: World, tmp_path: Path, capsys):
    run_error(case, world, tmp_path, capsys, longest_line=None)


@pytest.mark.parametrize("case", WARNINGS, ids=[c.id for c in WARNINGS])
def test_a_file_read_that_misstates_itself_is_used_with_one_warning(case: Warned, world: World, tmp_path: Path, capsys,
                                                                     caplog):
    assert case.says and case.also is not None  # each case names its warning and what its metrics hold
    run_warned(case, world, tmp_path, capsys, caplog, commands=("map",))


def test_inspect_reads_a_bag_whose_metadata_misstates_a_type_as_map_does(world: World, tmp_path: Path, capsys, caplog):
    """rosbags refused the bag ('hash mismatch') where gslam map read it."""
    copy_run(metadata(listed_topic("/odom", type="sensor_msgs/msg/Imu")))(tmp_path, world)
    with caplog.at_level(logging.WARNING):
        code, err, leaked = _run(["inspect", str(tmp_path / "run")], capsys)
    assert code == 0, err[-800:]
    said = [r.getMessage() for r in caplog.records if r.levelno >= logging.WARNING]
    assert sum("lists topic '/odom' as sensor_msgs/msg/Imu" in s for s in said) == 1, said


def test_corpus_counts():
    """At least 40 new cases, none named as one of the earlier corpora's."""
    from tests.test_fuzz import CASES
    from tests.test_hostile import ERRORS as EARLIER, WARNINGS as EARLIER_WARNED

    assert len(ERRORS) + len(WARNINGS) + 1 >= 40
    names = [c.id for c in [*CASES, *EARLIER, *EARLIER_WARNED, *ERRORS, *WARNINGS]]
    assert len(set(names)) == len(names)
