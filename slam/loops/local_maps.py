"""The laser points of each keyframe, and local maps around a keyframe.

A local map is the union of the scans of the keyframes within a stretch of
path around a keyframe, each placed by the current estimate and expressed
in the frame of the centre keyframe, thinned to one point per voxel. Its
point map (points, normals, k-d tree) and likelihood field are cached: a keyframe
far enough back to be a loop candidate has all its neighbours' estimates
fixed.
"""

from __future__ import annotations

import numpy as np

from validation.base.geometry import between
from slam.config.loops import RegistrationConfig
from slam.matching.grid import ScorePyramid, score_pyramid
from slam.matching.points import PointMap, point_map, scan_normals, voxel_first
from slam.recording import Scans


class KeyframePoints:
    """Planar points (in the laser frame) of every keyframe's scan, with a
    normal and a linearity each (slam.matching.points.scan_normals).

    ``scan_index`` (K,): the scan of each keyframe; beams outside
    [``min_range``, ``max_range``) are dropped; normals come from the
    beams' neighbours before each scan is thinned to ``voxel_m``.
    """

    def __init__(self, scans: Scans, scan_index: np.ndarray, min_range: float, max_range: float, voxel_m: float,
                 registration: RegistrationConfig):
        from slam.frontend.kiss import ScanProjector

        project = ScanProjector(scans.angles, min_range, min(max_range, scans.range_max))
        pts, row = project.planar_points(scans.ranges[scan_index])
        # All scans at once: a stretch that crosses from one scan into the
        # next is cut like a gap.
        normals, linearity = scan_normals(pts, registration.normal_half_window, registration.normal_max_gap_m, row)
        bounds = np.searchsorted(row, np.arange(len(scan_index) + 1))
        self.points, self.normals, self.linear = [], [], []
        for a, b in zip(bounds[:-1], bounds[1:]):
            keep = a + voxel_first(pts[a:b], voxel_m)
            self.points.append(pts[keep])
            self.normals.append(normals[keep])
            self.linear.append(linearity[keep] >= registration.min_linearity)
        self.voxel_m = voxel_m

    def __len__(self) -> int:
        return len(self.points)

    def gather(self, centre: int, keyframes: np.ndarray, poses: np.ndarray, lines_only: bool = False):
        """Points and normals of ``keyframes`` in the frame of keyframe
        ``centre``, placed by ``poses`` (K, 3), thinned to one per voxel;
        ``lines_only``: only points on a straight stretch."""
        ks = np.asarray(keyframes)
        rel = between(np.repeat(poses[centre][None], len(ks), axis=0), poses[ks])
        pts, nrm = [], []
        for k, (x, y, yaw) in zip(ks, rel):
            p, n = self.points[k], self.normals[k]
            if lines_only:
                p, n = p[self.linear[k]], n[self.linear[k]]
            if len(p):
                c, s = np.cos(yaw), np.sin(yaw)
                rot = np.array([[c, -s], [s, c]])
                pts.append(p @ rot.T + (x, y))
                nrm.append(n @ rot.T)
        if not pts:
            return np.zeros((0, 2)), np.zeros((0, 2))
        p, n = np.concatenate(pts), np.concatenate(nrm)
        keep = voxel_first(p, self.voxel_m)
        return p[keep], n[keep]


def window(path_m: np.ndarray, k: int, before_m: float, after_m: float, max_scans: int) -> np.ndarray:
    """Keyframes within ``before_m`` of path before keyframe ``k`` and
    ``after_m`` after it, ``k`` included, evenly thinned to ``max_scans``."""
    lo = int(np.searchsorted(path_m, path_m[k] - before_m, side="left"))
    hi = int(np.searchsorted(path_m, path_m[k] + after_m, side="right"))
    ks = np.arange(min(lo, k), max(hi, k + 1))
    if len(ks) > max_scans:
        ks = np.unique(np.concatenate([ks[np.linspace(0, len(ks) - 1, max_scans).round().astype(int)], [k]]))
    return ks


class LocalMaps:
    """Cached local maps of places: points, point map and score grid, each
    built once, when first needed."""

    def __init__(self, points: KeyframePoints, path_m: np.ndarray, half_m: float, max_scans: int,
                 registration: RegistrationConfig, grid_margin_m: float):
        self.points = points
        self.path_m = path_m
        self.half_m = half_m
        self.max_scans = max_scans
        self.registration = registration
        self.grid_margin_m = grid_margin_m
        self._maps: dict[int, PointMap] = {}
        self._grids: dict[tuple[int, float, float], ScorePyramid] = {}
        self._points: dict[int, np.ndarray] = {}

    def _window(self, k: int) -> np.ndarray:
        return window(self.path_m, k, self.half_m, self.half_m, self.max_scans)

    def local_points(self, k: int, poses: np.ndarray) -> np.ndarray:
        """All points of the local map around keyframe ``k``, in its frame."""
        pts = self._points.get(k)
        if pts is None:
            pts = self._points[k] = self.points.gather(k, self._window(k), poses)[0]
        return pts

    def point_map(self, k: int, poses: np.ndarray) -> PointMap:
        """The point map (points on straight stretches, with normals) around
        keyframe ``k``, in its frame."""
        pm = self._maps.get(k)
        if pm is None:
            pts, nrm = self.points.gather(k, self._window(k), poses, lines_only=True)
            pm = self._maps[k] = point_map(pts, nrm)
        return pm

    def score_pyramid(self, k: int, poses: np.ndarray, resolution_m: float, window_m: float) -> ScorePyramid:
        """The likelihood field around keyframe ``k``, in its frame, on cells
        of ``resolution_m``, with the pyramid a branch-and-bound search of
        ``window_m`` needs (one per keyframe, resolution and window)."""
        key = (k, round(resolution_m, 6), round(window_m, 6))
        grid = self._grids.get(key)
        if grid is None:
            w = int(np.ceil(window_m / resolution_m))
            depth = max(int(np.ceil(np.log2(2 * w + 1))), 0)
            grid = self._grids[key] = score_pyramid(self.local_points(k, poses), resolution_m, resolution_m, depth,
                                                    self.grid_margin_m, 2 * w)
        return grid
