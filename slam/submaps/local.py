"""Local SLAM: each scan matched against the submap being built, then inserted.

The scans are taken in order, as on the robot. A scan's pose is predicted
from the one before by a motion guess (the odometry's step, else the
sequential scan matcher's, fused: the dead-reckoning chain), searched for in
the *matching submap* by branch and bound (:mod:`slam.matching.search`)
within a window that covers the step's uncertainty, and refined by point-to-line ICP (:mod:`slam.matching.icp`).
Directions the submap does not pin (a corridor's axis) keep the guess. The
scan is then inserted into the active submaps.

Submaps follow Hess et al. 2016 (Sec. IV): each covers ``length_m`` of path
and a new one starts every half of that, so every scan lands in two and the
one matched against always holds at least half a submap of scans. A submap
is anchored at its first scan: its points are in that scan's frame.

Poses here are *local*: in the frame of the first scan, chained from match
to match, so they drift; the graph (:mod:`slam.submaps.graph`) places the
submaps globally. It can follow local SLAM scan by scan: what local SLAM
did with each scan is told as a :class:`LocalStep`.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from slam.config.submaps import SubmapsConfig
from slam.frontend.kiss import progress_bar
from slam.matching.grid import ScorePyramid, score_pyramid
from slam.matching.icp import pose_uncertainty, refine
from slam.matching.points import PointMap, point_map
from slam.matching.points import voxel_first
from slam.submaps.scans import ScanPoints
from slam.matching.search import CorrelativeSearch
from validation.base.geometry import between, compose, transform_points, wrap_angle

log = logging.getLogger(__name__)


@dataclass
class Submap:
    """Scans ``scans`` (indices, in order) placed in the frame of the first,
    ``anchor``; ``poses`` (k, 3) their poses in that frame."""

    scans: list[int] = field(default_factory=list)
    poses: list[np.ndarray] = field(default_factory=list)
    path_m: float = 0.0
    finished: bool = False
    _pyramid: ScorePyramid | None = None
    _pmap: PointMap | None = None
    _placed: list[tuple[np.ndarray, np.ndarray]] = field(default_factory=list)

    @property
    def anchor(self) -> int:
        return self.scans[0]

    def insert(self, scan: int, pose: np.ndarray, step_m: float) -> None:
        self.scans.append(scan)
        self.poses.append(np.asarray(pose, dtype=float))
        self.path_m += step_m
        self._pyramid = None
        self._pmap = None

    def gather(self, points: ScanPoints) -> tuple[np.ndarray, np.ndarray]:
        """The submap's points (m, 2) and normals (m, 2) in its frame. A
        scan's pose in the submap never changes once inserted, so each scan
        is placed once and kept (the grid and point map are rebuilt after
        every insertion)."""
        for k, pose in zip(self.scans[len(self._placed):], self.poses[len(self._placed):]):
            c, s = np.cos(pose[2]), np.sin(pose[2])
            self._placed.append((transform_points(pose, points.points[k]),
                                 points.normals[k] @ np.array([[c, s], [-s, c]])))
        return np.concatenate([p for p, _ in self._placed]), np.concatenate([n for _, n in self._placed])

    def points_about(self, points: ScanPoints, pose: np.ndarray, count: int | None = None) -> np.ndarray:
        """The points (m, 2) of its first ``count`` scans (all by default)
        in the frame of ``pose``, a pose in the submap's frame."""
        placed = zip(self.scans[:count], self.poses[:count])
        return np.concatenate([transform_points(between(pose, p), points.points[k]) for k, p in placed])

    def pyramid(self, points: ScanPoints, cfg: SubmapsConfig) -> ScorePyramid:
        if self._pyramid is None:
            pts, _ = self.gather(points)
            pad = 2 * int(np.ceil(cfg.max_window_m / cfg.resolution_m))
            self._pyramid = score_pyramid(pts, cfg.resolution_m, cfg.resolution_m, cfg.search_depth,
                                          3 * cfg.resolution_m, pad)
        return self._pyramid

    def point_map(self, points: ScanPoints, voxel_m: float) -> PointMap:
        """Its points on a line, one per ``voxel_m`` cell, with their normals."""
        if self._pmap is None:
            pts, nrm = self.gather(points)
            keep = np.linalg.norm(nrm, axis=1) > 0.5  # points on a line
            pts, nrm = pts[keep], nrm[keep]
            first = voxel_first(pts, voxel_m)
            self._pmap = point_map(pts[first], nrm[first])
        return self._pmap


@dataclass(frozen=True)
class Match:
    """A scan matched against a submap: its pose in the submap's frame,
    the search's score and the refinement's figures: ``covariance`` (3, 3)
    of the pose in the submap's axes, without the directions ``weak`` (k, 3)
    the match leaves free."""

    submap: int
    scan: int
    pose: np.ndarray
    score: float
    rms_m: float
    inliers: float
    covariance: np.ndarray
    weak: np.ndarray
    refined: bool = True
    """The pose is refined and pins at least the heading and one direction
    of travel: a constraint can be made of it (else it only places a scan
    in local SLAM)."""


def match_scan(
    submap: Submap, points: ScanPoints, scan: int, guess: np.ndarray, cfg: SubmapsConfig,
    linear_window_m: float, angular_window_rad: float, min_score: float, submap_id: int = -1,
    unique: bool = False, inside: bool = False,
) -> Match | None:
    """Search and refine ``scan``'s pose in ``submap`` around ``guess``
    (in the submap's frame); None when nothing scores ``min_score``. With
    ``unique``, a scan that fits elsewhere in the window about as well
    (:func:`rival_elsewhere`) is matched but not ``refined``: it makes no
    constraint. With ``inside``, neither is one whose best pose lies on the
    window's rim in a direction it pins (:func:`on_rim`)."""
    q = points.points[scan]
    if len(points.search[scan]) == 0:
        return None
    search = CorrelativeSearch(submap.pyramid(points, cfg), points.search[scan], guess, linear_window_m,
                               angular_window_rad, points.search_step(scan, cfg.resolution_m))
    found = search.best(min_score, cfg.tie_tolerance)
    if found is None:
        return None
    rc = cfg.refine
    ref = refine(q, submap.point_map(points, cfg.voxel_m), found.pose, rc.max_distance_m, rc.inlier_distance_m,
                 rc.kernel_m, max_points=rc.max_points)
    # The search put the scan within a cell and a yaw step of the optimum;
    # a refinement that wanders further has slid along a corridor or onto
    # another wall: keep the search's pose.
    d = ref.pose - found.pose
    d[2] = wrap_angle(d[2])
    near = np.hypot(d[0], d[1]) <= rc.max_shift_m and abs(d[2]) <= np.radians(rc.max_turn_deg)
    usable = ref.converged and near and ref.inliers >= rc.min_inliers
    if not usable:
        return Match(submap_id, scan, found.pose, found.score, ref.rms_m, ref.inliers, np.zeros((3, 3)), np.eye(3), False)
    covariance, weak = pose_uncertainty(ref.information * rc.information_scale, rc.weak_length_m, rc.max_sigma_m)
    # Along a weak direction the data say nothing: keep the search's pose there.
    for v in weak:
        d = d - v * (v @ d) / (v @ v)
    # A match may leave one direction free, the axis of a corridor; one that
    # cannot tell its heading, or two directions, measures too little.
    pinned = len(weak) == 0 or (len(weak) == 1 and abs(weak[0][2]) * rc.weak_length_m < np.hypot(*weak[0][:2]))
    if pinned and unique and rival_elsewhere(search, found, weak, cfg):
        pinned = False  # it still places the scan in local SLAM, but constrains nothing
    if pinned and inside and on_rim(search, found.pose, weak):
        pinned = False
    return Match(submap_id, scan, found.pose + d, found.score, ref.rms_m, ref.inliers, covariance, weak, pinned)


def on_rim(search: CorrelativeSearch, pose: np.ndarray, weak: np.ndarray) -> bool:
    """Whether ``pose`` lies on the rim of the search window, in a direction
    the match pins: the best pose inside the window, not necessarily the
    best there is. When drift has carried the guess further from the truth
    than the window reaches, the window's best is the nearest look-alike (a
    corridor's next stretch), at its rim; a loop from it would be wrong by
    the drift itself."""
    d, limit = search.edge_offsets(pose)
    for v in weak:
        d = d - v * (v @ d) / (v @ v)
    return bool(np.any(np.abs(d) >= limit))


def rival_elsewhere(search: CorrelativeSearch, found, weak: np.ndarray, cfg: SubmapsConfig) -> bool:
    """Whether the scan scores at least ``ambiguity.ratio`` of its best
    somewhere else in the window: beyond ``ambiguity.exclude_m`` and
    ``ambiguity.exclude_deg`` of the best pose, in a direction the match
    pins (along a corridor's free axis every pose fits, and the constraint
    claims nothing there). Repeated doors, racks or pillars make such
    rivals; the match cannot tell them apart, so it is not a constraint."""
    amb = cfg.ambiguity
    exclude_rad = np.radians(amb.exclude_deg)
    rivals = search.rivals(found.pose, amb.ratio * found.score, amb.exclude_m, exclude_rad)
    if len(rivals) == 0:
        return False
    d = rivals - found.pose
    d[:, 2] = wrap_angle(d[:, 2])
    for v in weak:
        d = d - np.outer(d @ v / (v @ v), v)
    return bool(np.any((np.hypot(d[:, 0], d[:, 1]) > amb.exclude_m) | (np.abs(d[:, 2]) > exclude_rad)))


def refine_near(
    points: ScanPoints, poses: np.ndarray, carrier: int, scan: int, guess: np.ndarray, cfg: SubmapsConfig,
    submap_id: int, score: float,
) -> Match | None:
    """Refine ``scan``'s pose ``guess`` in the frame of scan ``carrier``
    against the carrier and its neighbours in the run (one on each side),
    placed by the local ``poses``: a map of three scans carries less drift
    than a whole submap. None when the refinement fails or strays."""
    near = [k for k in (carrier - 1, carrier, carrier + 1) if 0 <= k < len(poses) and k != scan]
    pts, nrm = [], []
    for k in near:
        rel = between(poses[carrier], poses[k])
        pts.append(transform_points(rel, points.points[k]))
        c, s = np.cos(rel[2]), np.sin(rel[2])
        nrm.append(points.normals[k] @ np.array([[c, s], [-s, c]]))
    pts, nrm = np.concatenate(pts), np.concatenate(nrm)
    keep = np.linalg.norm(nrm, axis=1) > 0.5
    rc = cfg.refine
    ref = refine(points.points[scan], point_map(pts[keep], nrm[keep]), guess, rc.max_distance_m,
                 rc.inlier_distance_m, rc.kernel_m, max_points=rc.max_points)
    d = ref.pose - guess
    d[2] = wrap_angle(d[2])
    if not (ref.converged and ref.inliers >= rc.min_inliers and np.hypot(d[0], d[1]) <= rc.max_shift_m
            and abs(d[2]) <= np.radians(rc.max_turn_deg)):
        return None
    covariance, weak = pose_uncertainty(ref.information * rc.information_scale, rc.weak_length_m, rc.max_sigma_m)
    for v in weak:
        d = d - v * (v @ d) / (v @ v)
    pinned = len(weak) == 0 or (len(weak) == 1 and abs(weak[0][2]) * rc.weak_length_m < np.hypot(*weak[0][:2]))
    if not pinned:
        return None
    return Match(submap_id, scan, guess + d, score, ref.rms_m, ref.inliers, covariance, weak, True)


@dataclass(frozen=True)
class LocalStep:
    """What local SLAM did with scan ``scan``: its local ``pose``, the
    ``match`` that placed it (None where the guess did), the submaps it
    went into with its pose in each and the path it added to each
    (``inserted``: (submap, pose, step_m); a submap it starts is among
    them), and the submaps it completed (``finished``)."""

    scan: int
    pose: np.ndarray
    match: Match | None
    inserted: tuple[tuple[int, np.ndarray, float], ...]
    finished: tuple[int, ...]


@dataclass
class LocalResult:
    """Local poses (n, 3) of every scan, the submaps, and per scan the match
    that placed it (None for the first and for scans placed by their guess)."""

    poses: np.ndarray
    submaps: list[Submap]
    matches: list[Match | None]
    time_s: float


def search_windows(step_cov: np.ndarray, cfg: SubmapsConfig) -> tuple[np.ndarray, np.ndarray]:
    """Per step, the linear (m) and angular (rad) windows of the local
    search: three standard deviations of the chain's step covariance
    (n, 3, 3), within the configured least and most."""
    lc = cfg.local
    sd = np.sqrt(np.maximum(np.diagonal(step_cov, axis1=1, axis2=2), 0.0))
    lin = np.clip(3.0 * np.maximum(sd[:, 0], sd[:, 1]), lc.linear_window_m, lc.max_linear_window_m)
    ang = np.clip(3.0 * sd[:, 2], np.radians(lc.angular_window_deg), np.radians(lc.max_angular_window_deg))
    return lin, ang


def run_local_slam(points: ScanPoints, steps: np.ndarray, step_cov: np.ndarray, cfg: SubmapsConfig,
                   progress: bool = False, tell: Callable[[LocalStep | None], None] | None = None) -> LocalResult:
    """Local SLAM over all scans; ``steps`` (n, 3): each scan's motion since
    the previous in the previous one's frame (the dead-reckoning chain),
    ``step_cov`` (n, 3, 3) its covariance (row 0 unused); ``progress``: a
    bar on a terminal. ``tell``: given each scan's :class:`LocalStep` as
    it is done, then None (the submaps still open are complete)."""
    start = time.perf_counter()
    n = len(points)
    poses = np.zeros((n, 3))
    submaps: list[Submap] = [Submap()]
    submaps[0].insert(0, np.zeros(3), 0.0)
    active = [0]
    matches: list[Match | None] = [None]
    if tell is not None:
        tell(LocalStep(0, poses[0].copy(), None, ((0, np.zeros(3), 0.0),), ()))
    lin, ang = search_windows(step_cov, cfg)
    half = 0.5 * cfg.length_m
    bar = progress_bar(n - 1, progress, "submaps")
    for i in range(1, n):
        if bar is not None:
            bar.update()
        predicted = compose(poses[i - 1], steps[i])
        sm_id = active[0]
        sm = submaps[sm_id]
        anchor = poses[sm.anchor]
        m = None
        if len(points.points[i]) >= cfg.min_points:
            m = match_scan(sm, points, i, between(anchor, predicted), cfg, lin[i], ang[i], cfg.local.min_score, sm_id,
                           unique=cfg.ambiguity.enabled)
        poses[i] = compose(anchor, m.pose) if m is not None else predicted
        matches.append(m)
        step_m = float(np.hypot(*between(poses[i - 1], poses[i])[:2]))
        inserted = []
        for k in active:
            s = submaps[k]
            s.insert(i, between(poses[s.anchor], poses[i]), step_m)
            inserted.append((k, s.poses[-1], step_m))
        # A submap is full after length_m of path; a new one starts every half of it.
        newest = submaps[active[-1]]
        if newest.path_m >= half or len(newest.scans) >= cfg.max_scans // 2:
            submaps.append(Submap())
            submaps[-1].insert(i, np.zeros(3), 0.0)
            active.append(len(submaps) - 1)
            inserted.append((active[-1], submaps[-1].poses[-1], 0.0))
        finished = []
        while submaps[active[0]].path_m >= cfg.length_m or len(submaps[active[0]].scans) >= cfg.max_scans:
            submaps[active[0]].finished = True
            finished.append(active.pop(0))
        if tell is not None:
            tell(LocalStep(i, poses[i].copy(), m, tuple(inserted), tuple(finished)))
    if bar is not None:
        bar.close()
    for k in active:
        submaps[k].finished = True
    if tell is not None:
        tell(None)
    return LocalResult(poses, submaps, matches, time.perf_counter() - start)
