"""Faults written into a CARMEN log: the file is copied line by line, the
scans and raw odometry lines of the faulty stretches changed.

* ``laser_cut``: on FLASER and ROBOTLASER1 lines, every range beyond the
  cut becomes the log's own no-return value (the largest reading of the
  log, which the reader takes as the scanner's saturation).
* ``slip``: the raw ``ODOM`` lines after scan k hold the odometry from the
  corrected pose of scan k (:mod:`slam.readers.carmen`); for a scan inside the
  interval each of them is replaced by ``corrected_k * scaled(inverse(
  corrected_k) * odom)``, so every raw step of the stretch is scaled.

A gzip'd log is written gzip'd (without a time stamp, so the same input and
faults give the same bytes). A scan's time is the reader's (repaired or
synthesised stamps, :func:`slam.readers.carmen.scan_times`).
"""

from __future__ import annotations

import gzip
from pathlib import Path

import numpy as np

from slam.errors import GslamError
from slam.commands.inject import physics
from slam.commands.inject.labels import Labels
from slam.commands.inject.spec import Fault, LaserCutFault, SlipFault
from slam.readers.carmen import _open_lines
from slam.recording import relative_poses
from slam.recording import Recording

SUPPORTED = ("laser_cut", "slip")


def _compose(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    c, s = np.cos(a[2]), np.sin(a[2])
    return np.array([a[0] + c * b[0] - s * b[1], a[1] + s * b[0] + c * b[1], a[2] + b[2]])


def _cut_line(parts: list[str], first: int, n: int, fault: LaserCutFault, no_return: str) -> None:
    for i in range(first, first + n):
        if float(parts[i]) > fault.range_m:
            parts[i] = no_return


def inject_carmen(source: Path, dest: Path, rec: Recording, faults: list[Fault]) -> Labels:
    """Copy the CARMEN log ``source`` into the folder ``dest`` under its own
    name with ``faults`` added; their true intervals."""
    for fault in faults:
        if fault.kind not in SUPPORTED:
            raise GslamError(f"--fault {fault.text()}: a CARMEN log has a laser and odometry only "
                             f"(faults: {', '.join(SUPPORTED)})")
    cuts = [f for f in faults if isinstance(f, LaserCutFault)]
    slips = [f for f in faults if isinstance(f, SlipFault)]
    if slips and rec.odometry is None:
        raise GslamError(f"--fault {slips[0].text()}: {source} has no raw odometry")
    t = rec.scans.t
    no_return = f"{float(np.max(rec.scans.ranges)):g}"
    corrected = np.column_stack([rec.groundtruth.x, rec.groundtruth.y, rec.groundtruth.yaw])
    lines = _open_lines(source)
    out: list[str] = []
    k, repeat = -1, False
    for line in lines:
        parts = line.split()
        kind = parts[0] if parts else ""
        if kind in ("FLASER", "ROBOTLASER1"):
            k += 1
            repeat = True
            first, n = (2, int(parts[1])) if kind == "FLASER" else (9, int(parts[8]))
            for f in cuts:
                if physics.inside(t[k], f.start_s, f.end_s):
                    _cut_line(parts, first, n, f, no_return if kind == "FLASER" else parts[5])
            line = " ".join(parts)
        elif kind == "ODOM" and k >= 0:
            if repeat:  # the first ODOM after a scan repeats its corrected pose
                repeat = False
            elif any(physics.inside(t[k], f.start_s, f.end_s) for f in slips):
                odom = np.array([float(v) for v in parts[1:4]])
                step = relative_poses(corrected[k][None], odom[None])[0]
                for f in slips:
                    if physics.inside(t[k], f.start_s, f.end_s):
                        step = np.array([f.scale * step[0], f.scale * step[1], f.yaw_scale * step[2]])
                parts[1:4] = [f"{v:.6f}" for v in _compose(corrected[k], step)]
                line = " ".join(parts)
        out.append(line)
    labels = Labels()
    for f in cuts:
        cut = physics.inside(t, f.start_s, f.end_s)
        ranges = physics.cut_ranges(rec.scans.ranges[cut], f.range_m, np.inf)
        for modality, mask in physics.laser_labels(ranges, rec.scans.angles, 0.0, rec.scans.range_max, f).items():
            labels.add(modality, t[cut], mask)
    for f in slips:
        o = rec.odometry
        for comp, mask in physics.slip_labels(o.t, o.x, o.y, o.yaw, f).items():
            labels.add(comp, o.t, mask)
    _write(dest / source.name, "\n".join(out) + "\n")
    return labels


def _write(path: Path, text: str) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    data = text.encode("utf-8", errors="surrogateescape")  # a Latin-1 byte of the log's, as it was
    if path.name.lower().endswith(".gz"):
        with open(path, "wb") as raw, gzip.GzipFile(fileobj=raw, mode="wb", mtime=0, filename="") as f:
            f.write(data)
    else:
        path.write_bytes(data)
