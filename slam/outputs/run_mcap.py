"""``run.mcap``: a mapped run as a ROS 2 bag in MCAP storage, to scrub
through in Foxglove (which opens MCAP files directly) or to play into RViz2
(``ros2 bag play run.mcap``).

=======================  =================================  ================================
topic                    type                               what, when
=======================  =================================  ================================
``/map``                 nav_msgs/msg/OccupancyGrid         the occupancy grid, once, at the
                                                            first keyframe (latched)
``/path``                nav_msgs/msg/Path                  the optimised keyframe poses,
                                                            once, at the first keyframe
                                                            (latched)
``/ground_truth/path``   nav_msgs/msg/Path                  the reference at the keyframes,
                                                            once (latched), where the run
                                                            has one
``/tf``                  tf2_msgs/msg/TFMessage             ``map`` -> ``base_link`` at each
                                                            keyframe
``/scan_registered``     sensor_msgs/msg/PointCloud2        each keyframe's laser points in
                                                            the ``map`` frame (x, y, z
                                                            float32), at its keyframe
``/validation``          diagnostic_msgs/msg/DiagnosticArray  the validator's statuses at each
                                                            validation step
                                                            (:mod:`slam.outputs.validation_status`)
=======================  =================================  ================================

Stamps (bag time and header) are the recording's absolute times, ns.
Latched topics are offered with transient-local durability, so a
subscriber that joins late (RViz2's map display) still gets them.

The bag is written by rosbags (ROS 2 Humble message definitions, embedded
in the file) into a temporary folder beside the target; its one MCAP file
is then renamed into place and the folder removed, so the result is a
single file, complete or absent. The diagnostic arrays of a run repeat a
few dozen distinct contents: each is serialised once and only its stamp
changed per step.
"""

from __future__ import annotations

import functools
import os
import shutil
import struct
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from slam.results.tempfiles import temp_name
from slam.outputs.occupancy import GridMap
from slam.recording import Trajectory

if TYPE_CHECKING:
    from slam.outputs.validation_status import StepStatuses

TOPICS: dict[str, str] = {
    "/map": "nav_msgs/msg/OccupancyGrid",
    "/path": "nav_msgs/msg/Path",
    "/ground_truth/path": "nav_msgs/msg/Path",
    "/tf": "tf2_msgs/msg/TFMessage",
    "/scan_registered": "sensor_msgs/msg/PointCloud2",
    "/validation": "diagnostic_msgs/msg/DiagnosticArray",
}
LATCHED = ("/map", "/path", "/ground_truth/path")
MAP_FRAME, BODY_FRAME = "map", "base_link"
_FLOAT32 = 7  # sensor_msgs/PointField.FLOAT32
_STAMP = struct.Struct("<iI")  # builtin_interfaces/Time at the start of a little-endian CDR header


@dataclass
class RunContent:
    """What goes into the bag. Times ``t`` are s relative to ``t0`` (s,
    absolute); ``scans``: each keyframe's points (n_k, 2) in the map frame,
    m; ``reference``: the reference at the keyframes."""

    t0: float
    estimate: Trajectory
    grid: GridMap | None = None
    scans: list[np.ndarray] | None = None
    reference: Trajectory | None = None
    statuses: StepStatuses | None = None


def write_run_mcap(path: str | Path, content: RunContent) -> dict[str, int]:
    """Write ``content`` to the MCAP file ``path`` (see the module
    docstring); returns the number of messages per topic."""
    from rosbags.rosbag2 import CompressionFormat, CompressionMode, StoragePlugin, Writer

    path = Path(path)
    msgs = _Messages(content.t0)
    streams = {
        "/map": msgs.grid(content.grid, content.estimate.t[0]) if content.grid is not None else None,
        "/path": msgs.path(content.estimate),
        "/ground_truth/path": msgs.path(content.reference) if content.reference is not None else None,
        "/tf": msgs.transforms(content.estimate),
        "/scan_registered": msgs.clouds(content.estimate.t, content.scans) if content.scans is not None else None,
        "/validation": msgs.diagnostics(content.statuses) if content.statuses is not None else None,
    }
    folder = temp_name(path)
    folder.mkdir()
    bag = folder / path.stem  # the bag's file is named after its folder, in the metadata too: run.mcap
    counts: dict[str, int] = {}
    try:
        writer = Writer(bag, version=8, storage_plugin=StoragePlugin.MCAP)
        writer.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)  # chunks: what MCAP readers expect
        with writer:
            for topic, stream in streams.items():
                if stream is None:
                    continue
                qos = (_latched_qos(),) if topic in LATCHED else ()
                conn = writer.add_connection(topic, TOPICS[topic], typestore=msgs.store, offered_qos_profiles=qos)
                counts[topic] = 0
                for ns, data in stream:
                    writer.write(conn, ns, data)
                    counts[topic] += 1
        os.replace(bag / f"{bag.name}.mcap", path)
    finally:
        shutil.rmtree(folder, ignore_errors=True)
    return counts


@functools.cache
def typestore():
    """rosbags' Humble type store, one per process: it makes each type's
    serialiser on first use."""
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.ROS2_HUMBLE)


def warm_up() -> None:
    """Load the type store and make the serialiser of every topic's type
    (e.g. while the scans are matched), by building a message of each."""
    import rosbags.rosbag2  # noqa: F401 - the writer

    from slam.outputs.validation_status import Level, Status, StepStatuses

    one = Trajectory(np.zeros(1), np.zeros(1), np.zeros(1), np.zeros(1))
    statuses = StepStatuses(np.zeros(1), [(Status("warm-up", Level.OK, "", (("k", "v"),)),)], np.zeros(1, dtype=int))
    msgs = _Messages(0.0)
    msgs.grid(GridMap(np.zeros((1, 1), dtype=np.int8), np.zeros(2), 1.0), 0.0)
    msgs.path(one)
    msgs.transforms(one)
    msgs.clouds(one.t, [np.zeros((1, 2))])
    msgs.diagnostics(statuses)


def _latched_qos():
    """Reliable, transient local, keep last 1: a latched topic's profile."""
    from rosbags.interfaces import Qos, QosDurability, QosHistory, QosLiveliness, QosReliability, QosTime

    zero = QosTime(0, 0)
    return Qos(QosHistory.KEEP_LAST, 1, QosReliability.RELIABLE, QosDurability.TRANSIENT_LOCAL, zero, zero,
               QosLiveliness.AUTOMATIC, zero, False)


class _Messages:
    """Builds and serialises the messages (rosbags' Humble type store);
    each method returns a list of ``(stamp ns, CDR bytes)``."""

    def __init__(self, t0: float) -> None:
        self.store = typestore()
        self.T = self.store.types
        self.t0_ns = int(round(t0 * 1e9))

    def ns(self, t: float) -> int:
        return self.t0_ns + int(round(float(t) * 1e9))

    def header(self, ns: int, frame: str):
        T = self.T
        return T["std_msgs/msg/Header"](T["builtin_interfaces/msg/Time"](ns // 10**9, ns % 10**9), frame)

    def pose(self, x: float, y: float, yaw: float):
        T = self.T
        return T["geometry_msgs/msg/Pose"](
            T["geometry_msgs/msg/Point"](float(x), float(y), 0.0),
            T["geometry_msgs/msg/Quaternion"](0.0, 0.0, float(np.sin(yaw / 2.0)), float(np.cos(yaw / 2.0))),
        )

    def ser(self, msg, msgtype: str) -> bytes:
        return bytes(self.store.serialize_cdr(msg, msgtype))

    def grid(self, grid: GridMap, t: float) -> list[tuple[int, bytes]]:
        T, ns = self.T, self.ns(t)
        rows, cols = grid.cells.shape
        info = T["nav_msgs/msg/MapMetaData"](
            T["builtin_interfaces/msg/Time"](ns // 10**9, ns % 10**9), float(grid.resolution_m), cols, rows,
            self.pose(grid.origin[0], grid.origin[1], 0.0),
        )
        msg = T["nav_msgs/msg/OccupancyGrid"](self.header(ns, MAP_FRAME), info, grid.cells.astype(np.int8).ravel())
        return [(ns, self.ser(msg, TOPICS["/map"]))]

    def path(self, traj: Trajectory) -> list[tuple[int, bytes]]:
        T = self.T
        poses = [T["geometry_msgs/msg/PoseStamped"](self.header(self.ns(t), MAP_FRAME), self.pose(x, y, yaw))
                 for t, x, y, yaw in zip(traj.t.tolist(), traj.x.tolist(), traj.y.tolist(), traj.yaw.tolist())]
        ns = self.ns(traj.t[0])
        return [(ns, self.ser(T["nav_msgs/msg/Path"](self.header(ns, MAP_FRAME), poses), TOPICS["/path"]))]

    def transforms(self, traj: Trajectory) -> list[tuple[int, bytes]]:
        T = self.T
        out = []
        for t, x, y, yaw in zip(traj.t.tolist(), traj.x.tolist(), traj.y.tolist(), traj.yaw.tolist()):
            ns = self.ns(t)
            transform = T["geometry_msgs/msg/Transform"](
                T["geometry_msgs/msg/Vector3"](x, y, 0.0),
                T["geometry_msgs/msg/Quaternion"](0.0, 0.0, float(np.sin(yaw / 2.0)), float(np.cos(yaw / 2.0))),
            )
            stamped = T["geometry_msgs/msg/TransformStamped"](self.header(ns, MAP_FRAME), BODY_FRAME, transform)
            out.append((ns, self.ser(T["tf2_msgs/msg/TFMessage"]([stamped]), TOPICS["/tf"])))
        return out

    def clouds(self, t: np.ndarray, scans: list[np.ndarray]) -> list[tuple[int, bytes]]:
        T = self.T
        fields = [T["sensor_msgs/msg/PointField"](name, 4 * i, _FLOAT32, 1) for i, name in enumerate("xyz")]
        out = []
        for tk, xy in zip(t.tolist(), scans):
            ns = self.ns(tk)
            xyz = np.zeros((len(xy), 3), dtype="<f4")
            xyz[:, :2] = xy
            msg = T["sensor_msgs/msg/PointCloud2"](
                self.header(ns, MAP_FRAME), 1, len(xy), fields, False, 12, 12 * len(xy),
                xyz.view(np.uint8).ravel(), True,
            )  # fmt: skip
            out.append((ns, self.ser(msg, TOPICS["/scan_registered"])))
        return out

    def diagnostics(self, steps: StepStatuses) -> list[tuple[int, bytes]]:
        """One array per step: each distinct content serialised once with a
        zero stamp, then the step's stamp written over it."""
        T = self.T
        blank = self.header(0, "")
        templates = []
        for statuses in steps.patterns:
            msg = T["diagnostic_msgs/msg/DiagnosticArray"](blank, [
                T["diagnostic_msgs/msg/DiagnosticStatus"](
                    int(s.level), s.name, s.message, "", [T["diagnostic_msgs/msg/KeyValue"](k, v) for k, v in s.values]
                )
                for s in statuses
            ])  # fmt: skip
            templates.append(self.ser(msg, TOPICS["/validation"]))
        out = []
        for t, i in zip(steps.t.tolist(), steps.index.tolist()):
            ns = self.ns(t)
            data = bytearray(templates[i])
            _STAMP.pack_into(data, 4, ns // 10**9, ns % 10**9)
            out.append((ns, bytes(data)))
        return out
