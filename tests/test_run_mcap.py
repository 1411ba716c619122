"""run.mcap (slam.outputs.run_mcap) read back as Foxglove and ROS read it: with
rosbags, and with the ``mcap`` package decoding through the message
definitions the file carries (mcap-ros2-support)."""

from __future__ import annotations

import csv
import io
from pathlib import Path

import numpy as np
import pytest
from rosbags.rosbag2 import Reader
from rosbags.typesys import Stores, get_typestore

from slam.outputs.map_server import read_map
from slam.outputs.run_mcap import TOPICS, _Messages
from slam.outputs.tum import read_tum
from slam.outputs.validation_status import Level, Status, StepStatuses

mcap_reader = pytest.importorskip("mcap.reader", reason="the test extra installs mcap")
mcap_ros2 = pytest.importorskip("mcap_ros2.decoder", reason="the test extra installs mcap-ros2-support")

STORE = get_typestore(Stores.ROS2_HUMBLE)


def read_rosbags(path: Path) -> dict[str, list]:
    """Every message per topic, deserialised by rosbags."""
    out: dict[str, list] = {}
    with Reader(path) as reader:
        for conn in reader.connections:
            out.setdefault(conn.topic, [])
            assert conn.msgtype == TOPICS[conn.topic]
        for conn, stamp, data in reader.messages():
            out[conn.topic].append((stamp, STORE.deserialize_cdr(data, conn.msgtype)))
    return out


def read_mcap(path: Path) -> tuple[dict[str, str], dict[str, int], dict[str, list]]:
    """Each topic's schema name and message count from the file's summary,
    and every message decoded with the schemas in the file."""
    with path.open("rb") as f:
        reader = mcap_reader.make_reader(f, decoder_factories=[mcap_ros2.DecoderFactory()])
        summary = reader.get_summary()
        schemas = {c.topic: summary.schemas[c.schema_id].name for c in summary.channels.values()}
        counts = {summary.channels[i].topic: n for i, n in summary.statistics.channel_message_counts.items()}
        decoded: dict[str, list] = {}
        for _, channel, message, msg in reader.iter_decoded_messages():
            decoded.setdefault(channel.topic, []).append((message.log_time, msg))
    return schemas, counts, decoded


def test_the_bag_holds_every_topic_with_its_type_and_count(mapped):
    res = mapped("on")
    path = res.out_dir / "run.mcap"
    n, steps = res.metrics["n_poses"], res.metrics["validation_steps"]
    expected = {"/map": 1, "/path": 1, "/ground_truth/path": 1, "/tf": n, "/scan_registered": n, "/validation": steps}
    assert res.metrics["mcap_messages"] == expected
    bag = read_rosbags(path)
    assert {t: len(m) for t, m in bag.items()} == expected
    schemas, counts, decoded = read_mcap(path)
    assert counts == expected
    assert schemas == {t: TOPICS[t] for t in expected}
    assert {t: len(m) for t, m in decoded.items()} == expected


def test_the_bag_shows_the_result_files(mapped, short_run):
    res = mapped("on")
    bag = read_rosbags(res.out_dir / "run.mcap")
    t0_ns = round(short_run.t0 * 1e9)
    est, _ = read_tum(res.out_dir / "trajectory.tum", short_run.t0)

    # /map is map.pgm as map_server loads it, latched at the first keyframe.
    (stamp, grid), = bag["/map"]
    loaded = read_map(res.out_dir / "map.yaml")
    assert (grid.info.width, grid.info.height) == (loaded.data.shape[1], loaded.data.shape[0])
    np.testing.assert_array_equal(grid.data.reshape(loaded.data.shape), loaded.data)
    assert grid.info.resolution == pytest.approx(loaded.resolution)
    assert (grid.info.origin.position.x, grid.info.origin.position.y) == pytest.approx(loaded.origin[:2])
    assert grid.header.frame_id == "map" and stamp == t0_ns + round(est.t[0] * 1e9)

    # /path and /tf: the optimised keyframes.
    (_, path), = bag["/path"]
    xy = np.array([[p.pose.position.x, p.pose.position.y] for p in path.poses])
    np.testing.assert_allclose(xy, est.xy(), atol=1e-6)
    tf = bag["/tf"]
    assert [s for s, _ in tf] == [t0_ns + round(t * 1e9) for t in est.t]
    frames = {(m.transforms[0].header.frame_id, m.transforms[0].child_frame_id) for _, m in tf}
    assert frames == {("map", "base_link")}
    yaw = [2 * np.arctan2(m.transforms[0].transform.rotation.z, m.transforms[0].transform.rotation.w) for _, m in tf]
    np.testing.assert_allclose(np.angle(np.exp(1j * (np.array(yaw) - est.yaw))), 0.0, atol=1e-6)

    # /scan_registered: each keyframe's points, in the map frame, on map.ply's walls.
    clouds = bag["/scan_registered"]
    assert all(m.header.frame_id == "map" and m.point_step == 12 for _, m in clouds)
    points = np.concatenate([np.frombuffer(m.data.tobytes(), dtype="<f4").reshape(-1, 3) for _, m in clouds])
    assert len(points) > 1000 and np.all(points[:, 2] == 0.0)
    occupied = loaded.data == 100
    col = ((points[:, 0] - loaded.origin[0]) / loaded.resolution).astype(int)
    row = ((points[:, 1] - loaded.origin[1]) / loaded.resolution).astype(int)
    near = np.zeros_like(occupied)  # an occupied cell or its neighbour
    for dr in (-1, 0, 1):
        for dc in (-1, 0, 1):
            near |= np.roll(np.roll(occupied, dr, axis=0), dc, axis=1)
    assert np.mean(near[row, col]) > 0.95


def test_validation_statuses_say_what_validation_csv_says(mapped, short_run):
    res = mapped("on")
    bag = read_rosbags(res.out_dir / "run.mcap")
    rows = list(csv.DictReader(io.StringIO((res.out_dir / "validation.csv").read_text())))
    arrays = bag["/validation"]
    assert len(arrays) == len(rows)
    levels = {"include": 0, "inflate": 1, "exclude": 2}
    blamed = excluded = 0
    for (stamp, msg), row in zip(arrays, rows):
        assert abs(stamp - round(short_run.t0 * 1e9) - round(float(row["t"]) * 1e9)) <= 50_000  # the CSV's 0.1 ms
        assert (msg.header.stamp.sec, msg.header.stamp.nanosec) == divmod(stamp, 10**9)
        status = {s.name: s for s in msg.status}
        assert status["diagnosis"].message == row["diagnoses"]
        gate = status["gate/compass"]
        assert dict((kv.key, kv.value) for kv in gate.values) == {"yaw": row["gate.compass.yaw"]}
        assert gate.level == levels[row["gate.compass.yaw"]]
        for name in ("yaw_compass_gyro", "yaw_odo_gyro"):
            obs = status[f"observer/{name}"]
            assert obs.message == ("no data" if row[f"{name}.valid"] == "0" else
                                   "no_match" if row[f"{name}.no_match"] == "1" else "match")
        if row["diagnoses"] == "{IMU_YAW}":
            assert status["component/IMU_YAW"].level == 2 and status["component/IMU_GYRO"].level == 0
            blamed += 1
        excluded += row["gate.compass.yaw"] == "exclude"
    assert blamed > 10 and excluded > 10  # the steel cabinet's compass fault


def test_a_stamp_written_over_a_template_is_the_message_serialised_whole():
    statuses = (Status("gate/compass", Level.ERROR, "yaw exclude", (("yaw", "exclude"),)),
                Status("observer/x", Level.OK, "match", ()))
    t = np.array([0.0, 0.1, 1234.5678901])
    msgs = _Messages(1_700_000_000.25)
    patched = msgs.diagnostics(StepStatuses(t, [statuses], np.zeros(3, dtype=int)))
    T = msgs.T
    for (ns, data), tk in zip(patched, t):
        whole = T["diagnostic_msgs/msg/DiagnosticArray"](msgs.header(msgs.ns(tk), ""), [
            T["diagnostic_msgs/msg/DiagnosticStatus"](int(s.level), s.name, s.message, "",
                                                      [T["diagnostic_msgs/msg/KeyValue"](k, v) for k, v in s.values])
            for s in statuses
        ])
        assert data == msgs.ser(whole, "diagnostic_msgs/msg/DiagnosticArray")
        assert ns == msgs.ns(tk)


@pytest.mark.parametrize("mode", ["off", "oracle"])
def test_without_the_validator_there_is_no_validation_topic(mapped, mode):
    res = mapped(mode)
    assert "/validation" not in res.metrics["mcap_messages"]
    assert res.metrics["mcap_messages"]["/tf"] == res.metrics["n_poses"]


@pytest.mark.slow
def test_outputs_can_be_turned_off(mapped):
    res = mapped("off", "output.grid=false", "output.mcap=false")
    names = {p.name for p in res.out_dir.iterdir()}
    assert not names & {"map.pgm", "map.yaml", "run.mcap"}
    assert {"map.png", "map.ply"} <= names  # the map figure falls back to the laser points
    assert "grid" not in res.metrics and "mcap_messages" not in res.metrics
    res = mapped("off", "output.mcap=false")
    assert {"map.pgm", "map.yaml"} <= {p.name for p in res.out_dir.iterdir()}
