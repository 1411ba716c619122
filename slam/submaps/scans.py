"""The laser points of every scan, with the normal of the wall each lies on."""

from __future__ import annotations

import numpy as np

from slam.matching.points import voxel_first
from slam.matching.points import scan_normals
from slam.matching.search import angular_step
from slam.recording import Scans


class ScanPoints:
    """Planar points (m, 2) of each scan in the laser frame, thinned to one
    per ``voxel_m`` cell, and the unit normal of each (zero where the beams
    around it do not lie on a line: corners, clutter, the scan's ends).

    ``search``: the same points thinned to ``search_voxel_m`` (the
    correlative search's cells; its score is a mean, which a few points per
    cell estimate as well as many). Beams outside [``min_range``,
    ``max_range``) are dropped. A normal is
    fitted to the ``half_window`` beams on each side, when none of them is
    more than ``max_gap_m`` from the next and the stretch's linearity is at
    least ``min_linearity``.
    """

    def __init__(self, scans: Scans, min_range: float, max_range: float, voxel_m: float,
                 half_window: int = 2, max_gap_m: float = 0.3, min_linearity: float = 0.8,
                 index: np.ndarray | None = None, search_voxel_m: float | None = None):
        from slam.frontend.kiss import ScanProjector

        index = np.arange(len(scans)) if index is None else np.asarray(index)
        project = ScanProjector(scans.angles, min_range, min(max_range, scans.range_max))
        pts, row = project.planar_points(scans.ranges[index])
        normals, linearity = scan_normals(pts, half_window, max_gap_m, row)
        normals[linearity < min_linearity] = 0.0
        bounds = np.searchsorted(row, np.arange(len(index) + 1))
        self.points: list[np.ndarray] = []
        self.normals: list[np.ndarray] = []
        self.search: list[np.ndarray] = []
        self._steps: dict[tuple[int, float], float] = {}
        for a, b in zip(bounds[:-1], bounds[1:]):
            keep = a + voxel_first(pts[a:b], voxel_m)
            self.points.append(pts[keep])
            self.normals.append(normals[keep])
            coarse = self.points[-1] if search_voxel_m is None else pts[a + voxel_first(pts[a:b], search_voxel_m)]
            self.search.append(coarse)

    def search_step(self, scan: int, resolution_m: float) -> float:
        """The correlative search's yaw step (rad) for ``scan``'s ``search``
        points in cells of ``resolution_m``
        (:func:`slam.matching.search.angular_step`): worked out once per
        scan, which is searched for in several submaps."""
        key = (scan, resolution_m)
        if key not in self._steps:
            self._steps[key] = angular_step(np.ascontiguousarray(self.search[scan], dtype=np.float64), resolution_m)
        return self._steps[key]

    def leave_out(self, scans: np.ndarray) -> None:
        """Empty the points of ``scans`` (indices into this list): they are
        then neither matched nor inserted anywhere."""
        for i in scans:
            self.points[i] = self.points[i][:0]
            self.normals[i] = self.normals[i][:0]
            self.search[i] = self.search[i][:0]
        self._steps.clear()

    def __len__(self) -> int:
        return len(self.points)
