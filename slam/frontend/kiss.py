"""Laser front-end: KISS-ICP on 2D scans.

Each scan becomes points at z = 0 in the laser frame (beams without a return
or outside [min_range, max_range] dropped) and is registered by KISS-ICP
against its local map. The result is one planar pose per scan in the frame
of the first scan; relative poses between keyframes and the scan-matching
yaw and distance streams for validation come from it.

KISS-ICP reports no quality of its own: with no points in range it returns
its constant-velocity prediction, with one straight wall it slides along it.
That silent failure is what sensor validation is for, so the front-end does
not try to detect it; on request it reports, per scan, what a scan check
needs to (:func:`scan_quality`): its returns and how well its geometry
constrains each direction.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass

import numpy as np

from slam.config import FrontendConfig
from slam.recording import Scans, Trajectory
from slam.frontend.scan_geometry import range_ceiling, scan_geometry

log = logging.getLogger(__name__)


def planar(transform: np.ndarray) -> np.ndarray:
    """The exact planar rigid transform (x, y, yaw; z = roll = pitch = 0)
    closest in yaw to a 4x4 ``transform``."""
    yaw = np.arctan2(transform[1, 0], transform[0, 0])
    c, s = np.cos(yaw), np.sin(yaw)
    out = np.eye(4)
    out[:2, :2] = [[c, -s], [s, c]]
    out[:2, 3] = transform[:2, 3]
    return out


def scan_points(ranges: np.ndarray, angles: np.ndarray, min_range: float, max_range: float) -> np.ndarray:
    """Points (m, 3) of one scan in the laser frame, z = 0.

    Beams that are not finite or fall outside [min_range, max_range) are
    dropped: a beam at the maximum range is a "no return" on many scanners.
    """
    r = np.asarray(ranges, dtype=np.float64)
    keep = np.isfinite(r) & (r >= min_range) & (r < max_range)
    rk, ak = r[keep], angles[keep]
    return np.column_stack([rk * np.cos(ak), rk * np.sin(ak), np.zeros_like(rk)])


class ScanProjector:
    """:func:`scan_points` for many scans of one scanner, with the beam
    directions computed once; the points are bit-identical to it.

    ``angles`` (beams,) rad in the laser frame; ranges outside
    [``min_range``, ``max_range``) m or not finite are dropped.
    """

    def __init__(self, angles: np.ndarray, min_range: float, max_range: float):
        a = np.asarray(angles)
        self.cos, self.sin = np.cos(a), np.sin(a)
        self.min_range, self.max_range = min_range, max_range

    def keep(self, ranges: np.ndarray) -> np.ndarray:
        """Mask of the beams in range, same shape as ``ranges`` (one scan or (n, beams))."""
        with np.errstate(invalid="ignore"):
            return np.isfinite(ranges) & (ranges >= self.min_range) & (ranges < self.max_range)

    def __call__(self, ranges: np.ndarray) -> np.ndarray:
        """Points (m, 3) of one scan, z = 0, in beam order."""
        r = np.asarray(ranges, dtype=np.float64)
        keep = self.keep(r)
        rk = r[keep]
        out = np.zeros((len(rk), 3))
        np.multiply(rk, self.cos[keep], out=out[:, 0])
        np.multiply(rk, self.sin[keep], out=out[:, 1])
        return out

    def planar_points(self, ranges: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Points (m, 2) of scans ``ranges`` (n, beams), scan by scan in beam
        order, and the scan (row) index of each point (m,)."""
        r = np.asarray(ranges, dtype=np.float64)
        keep = self.keep(r)
        row, beam = np.nonzero(keep)
        rk = r[row, beam]
        return np.column_stack([rk * self.cos[beam], rk * self.sin[beam]]), row

    def world_points(self, ranges: np.ndarray, poses: Trajectory) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`planar_points` of scans taken at ``poses`` (one per row of
        ``ranges``; the laser at the pose), in the world frame (m)."""
        p, row = self.planar_points(ranges)
        c, s = np.cos(poses.yaw[row]), np.sin(poses.yaw[row])
        x = poses.x[row] + c * p[:, 0] - s * p[:, 1]
        y = poses.y[row] + s * p[:, 0] + c * p[:, 1]
        return np.column_stack([x, y]), row


@dataclass
class FrontendResult:
    """Scan-matching output.

    ``poses``: KISS-ICP pose of every scan (planar projection, frame of the
    first scan). ``n_points``: points in range per scan. ``time_s``: wall
    time of the registration.
    """

    poses: Trajectory
    n_points: np.ndarray
    time_s: float


def kiss_config(config: FrontendConfig, range_max: float):
    """KISS-ICP's config for a 2D scanner whose beams reach ``range_max``."""
    from kiss_icp.config import KISSConfig

    kiss = KISSConfig()
    kiss.data.max_range = min(config.max_range_m, range_max)
    kiss.data.min_range = config.min_range_m
    kiss.data.deskew = False  # 2D scanners give no per-point stamps
    kiss.mapping.voxel_size = config.voxel_size_m
    kiss.mapping.max_points_per_voxel = config.max_points_per_voxel
    kiss.adaptive_threshold.initial_threshold = config.initial_threshold_m
    kiss.adaptive_threshold.min_motion_th = config.min_motion_m
    kiss.registration.max_num_iterations = config.max_iterations
    kiss.registration.max_num_threads = config.threads
    return kiss


class ScanMatcher:
    """KISS-ICP configured for a 2D scanner.

    :meth:`register` runs KISS-ICP's ``register_frame`` on a scan's points;
    :meth:`register_voxelized` runs its second half on what its first half
    (range filter and voxel grids, which depend on the scan alone) made of
    them elsewhere (:class:`slam.frontend.scan_prep.ScanPreparer`): the same calls,
    so the same poses to the last bit."""

    def __init__(self, config: FrontendConfig, range_max: float):
        from kiss_icp.kiss_icp import KissICP

        self.config = config
        self.max_range = min(config.max_range_m, range_max)
        self._icp = KissICP(kiss_config(config, range_max))

    def register(self, points: np.ndarray, guess: np.ndarray | None = None) -> tuple[float, float, float]:
        """Register one scan; returns the planar pose (x, y, yaw) of the laser.

        ``guess``: the motion (dx, dy, dyaw) since the previous scan, in its
        frame, to start from instead of KISS-ICP's constant velocity.
        """
        self._start_from(guess)
        self._icp.register_frame(points, np.zeros(len(points)))
        return self._planar_pose()

    def register_voxelized(
        self, source: np.ndarray, frame_downsample: np.ndarray, guess: np.ndarray | None = None
    ) -> tuple[float, float, float]:
        """:meth:`register` for a scan already through KISS-ICP's range
        filter and voxel grids: ``KissICP.register_frame`` from its
        threshold on (kiss-icp 1.x)."""
        self._start_from(guess)
        icp = self._icp
        sigma = icp.adaptive_threshold.get_threshold()
        initial_guess = icp.last_pose @ icp.last_delta
        new_pose = icp.registration.align_points_to_map(
            points=source,
            voxel_map=icp.local_map,
            initial_guess=initial_guess,
            max_correspondance_distance=3 * sigma,
            kernel=sigma,
        )
        icp.adaptive_threshold.update_model_deviation(np.linalg.inv(initial_guess) @ new_pose)
        icp.local_map.update(frame_downsample, new_pose)
        icp.last_delta = np.linalg.inv(icp.last_pose) @ new_pose
        icp.last_pose = new_pose
        return self._planar_pose()

    def _start_from(self, guess: np.ndarray | None) -> None:
        if guess is not None:
            delta = np.eye(4)
            c, s = np.cos(guess[2]), np.sin(guess[2])
            delta[:2, :2] = [[c, -s], [s, c]]
            delta[:2, 3] = guess[:2]
            self._icp.last_delta = delta

    def _planar_pose(self) -> tuple[float, float, float]:
        # KISS-ICP compounds its pose and velocity as 4x4 float products; over
        # a long blind stretch (no points: prediction only) round-off makes the
        # rotation non-orthogonal and Sophus aborts the process. A 2D scanner
        # has no z, roll or pitch: keep both exactly planar.
        self._icp.last_pose = planar(self._icp.last_pose)
        self._icp.last_delta = planar(self._icp.last_delta)
        pose = self._icp.last_pose
        return float(pose[0, 3]), float(pose[1, 3]), float(np.arctan2(pose[1, 0], pose[0, 0]))


def odometry_guesses(
    scan_t: np.ndarray, config: FrontendConfig, odometry: Trajectory | None
) -> list[np.ndarray | None] | None:
    """Per scan, the odometry's motion since the previous scan (dx, dy,
    dyaw), or None where the odometry has no data; None for all when
    ``config.initial_guess`` is not ``odometry`` or there is no odometry."""
    if config.initial_guess != "odometry" or odometry is None or len(odometry) < 2:
        return None
    from slam.recording import covered, interpolate_poses, relative_poses

    poses = interpolate_poses(odometry, scan_t)
    guesses = np.zeros_like(poses)
    guesses[1:] = relative_poses(poses[:-1], poses[1:])
    ok = covered(odometry.t, scan_t, max_gap_s=1.0)
    usable = np.zeros(len(scan_t), dtype=bool)
    usable[1:] = ok[1:] & ok[:-1]
    return [g if u else None for g, u in zip(guesses, usable)]


def progress_bar(total: int, enabled: bool, desc: str = "scan matching"):
    """A tqdm bar ``desc`` over ``total`` scans (shown only on a terminal), or None."""
    if not enabled:
        return None
    from tqdm import tqdm

    return tqdm(total=total, desc=desc, unit="scan", leave=False, disable=None)


def run_frontend(
    scans: Scans, config: FrontendConfig, progress: bool = False, odometry: Trajectory | None = None
) -> FrontendResult:
    """Register every scan with KISS-ICP; see :class:`FrontendResult`.

    ``odometry`` seeds each registration when ``config.initial_guess`` is
    ``odometry`` (steps where it has no data fall back to KISS-ICP's guess).
    """
    matcher = ScanMatcher(config, scans.range_max)
    n = len(scans)
    guesses = odometry_guesses(scans.t, config, odometry)
    xyyaw = np.zeros((n, 3))
    n_points = np.zeros(n, dtype=np.int64)
    start = time.perf_counter()
    bar = progress_bar(n, progress)
    project = ScanProjector(scans.angles, config.min_range_m, matcher.max_range)
    for i in range(n):
        pts = project(scans.ranges[i])
        n_points[i] = len(pts)
        xyyaw[i] = matcher.register(pts, guesses[i] if guesses is not None else None)
        if bar is not None:
            bar.update()
    if bar is not None:
        bar.close()
    elapsed = time.perf_counter() - start
    log.info("KISS-ICP registered %d scans in %.2f s", n, elapsed)
    poses = Trajectory(t=scans.t.copy(), x=xyyaw[:, 0], y=xyyaw[:, 1], yaw=xyyaw[:, 2])
    return FrontendResult(poses=poses, n_points=n_points, time_s=elapsed)


@dataclass(frozen=True)
class ScanQuality:
    """Per scan: ``t`` (n,) s, ``returns`` (n,) in range, ``min_eigenvalue``
    (n,) of its normalised point-to-line information matrix and that
    eigenvector ``weak`` (n, 3) (forward, left, turn); the share of beams
    without a return ``no_return`` (n,), the returns bordering a gap
    ``gap_edges`` (n,), the share of those near the farthest return
    ``edges_at_ceiling`` (n,) and that return ``farthest`` (n,) m
    (:mod:`slam.frontend.scan_geometry`); ``reach_m``, the farthest a
    return may lie (the laser's range or the front-end's limit, the nearer)."""

    t: np.ndarray
    returns: np.ndarray
    min_eigenvalue: np.ndarray
    weak: np.ndarray
    no_return: np.ndarray
    gap_edges: np.ndarray
    edges_at_ceiling: np.ndarray
    farthest: np.ndarray
    reach_m: float = np.inf


def scan_quality(scans: Scans, config: FrontendConfig, chunk: int = 512) -> ScanQuality:
    """:class:`ScanQuality` of every scan (at least one), over the beams
    the front-end registers (``config``'s range limits), ``chunk`` scans at
    a time."""
    max_range = min(config.max_range_m, scans.range_max)
    parts = [(*scan_geometry(scans.ranges[i : i + chunk], scans.angles, config.min_range_m, max_range),
              *range_ceiling(scans.ranges[i : i + chunk], config.min_range_m, max_range))
             for i in range(0, len(scans), chunk)]
    return ScanQuality(scans.t.copy(), *(np.concatenate(p) for p in zip(*parts)), reach_m=float(max_range))
