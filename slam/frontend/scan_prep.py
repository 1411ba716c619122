"""KISS-ICP's first half where the scans are read.

KISS-ICP's ``register_frame`` first filters a scan's points by range and
thins them on two voxel grids, which depends on that scan alone, and then
registers the result against its local map, which depends on every scan
before. When scan matching runs in a second process (:mod:`slam.frontend.worker`),
the first half runs where the scans are read, :data:`CHUNK` scans at a time
handed over as they are made, and the scan-matching process runs only the
second (:meth:`slam.frontend.kiss.ScanMatcher.register_voxelized`): a tenth of
KISS-ICP's time leaves the longest path. The calls are KISS-ICP's own on
the same points, so the poses are the same to the last bit
(``tests/test_concurrent_outputs.py`` maps a run both ways).
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass

import numpy as np

from slam.config import FrontendConfig
from slam.frontend.kiss import FrontendResult, ScanMatcher, ScanProjector, kiss_config, progress_bar
from slam.recording import Scans, Trajectory

log = logging.getLogger(__name__)

CHUNK = 64  # scans per hand-over: the first reaches scan matching after a few milliseconds


@dataclass
class PreparedScans:
    """Consecutive scans through KISS-ICP's range filter and voxel grids:
    per scan the points to register (``source``) and to add to the map
    (``frame_downsample``), the points in range and the odometry's guess
    (or None)."""

    source: list[np.ndarray]
    frame_downsample: list[np.ndarray]
    n_points: np.ndarray
    guesses: list[np.ndarray | None]


@dataclass(frozen=True)
class PreparedHeader:
    """What scan matching needs before the first :class:`PreparedScans`."""

    n: int
    range_max: float


def prepared_chunks(
    scans: Scans, config: FrontendConfig, guesses: list[np.ndarray | None] | None
) -> Iterator[PreparedScans]:
    """``scans`` through KISS-ICP's first half, :data:`CHUNK` at a time."""
    from kiss_icp.kiss_icp import KissICP

    kiss = kiss_config(config, scans.range_max)
    assert not kiss.data.deskew, "without deskewing the first half depends on the scan alone"
    icp = KissICP(kiss)  # only its range filter and voxel grids are used
    project = ScanProjector(scans.angles, config.min_range_m, kiss.data.max_range)
    still = np.eye(4)  # the motion a deskewing filter would use: none
    for lo in range(0, len(scans), CHUNK):
        source, frame_downsample, n_points = [], [], []
        for ranges in scans.ranges[lo : lo + CHUNK]:
            points = project(ranges)
            frame = icp.preprocessor.preprocess(points, np.zeros(len(points)), still)
            src, down = icp.voxelize(frame)
            source.append(src)
            frame_downsample.append(down)
            n_points.append(len(points))
        part = guesses[lo : lo + CHUNK] if guesses is not None else [None] * len(source)
        yield PreparedScans(source, frame_downsample, np.asarray(n_points, dtype=np.int64), part)


def register_prepared(
    header: PreparedHeader, chunks: Callable[[], PreparedScans | None], config: FrontendConfig, progress: bool = False
) -> FrontendResult:
    """KISS-ICP's second half over the chunks ``chunks()`` returns until
    None; the poses' times are the scans' indices (the caller has the times)."""
    matcher = ScanMatcher(config, header.range_max)
    xyyaw = np.zeros((header.n, 3))
    n_points = np.zeros(header.n, dtype=np.int64)
    bar = progress_bar(header.n, progress)
    start, i = None, 0
    while (chunk := chunks()) is not None:
        start = start if start is not None else time.perf_counter()
        for src, down, guess in zip(chunk.source, chunk.frame_downsample, chunk.guesses):
            xyyaw[i] = matcher.register_voxelized(src, down, guess)
            i += 1
        n_points[i - len(chunk.source) : i] = chunk.n_points
        if bar is not None:
            bar.update(len(chunk.source))
    if bar is not None:
        bar.close()
    if i != header.n:
        raise RuntimeError(f"scan matching got {i} of {header.n} scans")
    elapsed = time.perf_counter() - start if start is not None else 0.0
    log.info("KISS-ICP registered %d scans in %.2f s", header.n, elapsed)
    poses = Trajectory(t=np.arange(header.n, dtype=float), x=xyyaw[:, 0], y=xyyaw[:, 1], yaw=xyyaw[:, 2])
    return FrontendResult(poses=poses, n_points=n_points, time_s=elapsed)
