"""Nearest-neighbour search among planar points within a fixed radius, on a
uniform grid: numpy only.

The points are bucketed into square cells of side ``radius_m``; any point
within ``radius_m`` of a query lies in the query's cell or one of its eight
neighbours. Each cell's points sit in a padded row of a (cells, capacity)
table, so a batch of queries is answered with one gather of 9 x capacity
candidates each and an argmin. Used for ICP correspondences and normals,
where the radius is small against the map (a few tenths of a metre).
"""

from __future__ import annotations

import numpy as np


class GridIndex:
    """Points (n, 2) indexed for neighbour queries up to ``radius_m``."""

    def __init__(self, points: np.ndarray, radius_m: float):
        self.points = np.asarray(points, dtype=np.float64)
        self.radius_m = radius_m
        n = len(self.points)
        if n == 0:
            self.origin = np.zeros(2)
            self.shape = (1, 1)
            self.table = np.full((1, 1), -1, dtype=np.int64)
            return
        self.origin = self.points.min(axis=0) - radius_m
        cells = np.floor((self.points - self.origin) / radius_m).astype(np.int64)
        self.shape = (int(cells[:, 0].max()) + 2, int(cells[:, 1].max()) + 2)
        key = cells[:, 0] * self.shape[1] + cells[:, 1]
        order = np.argsort(key, kind="stable")
        sorted_key = key[order]
        start = np.searchsorted(sorted_key, sorted_key, side="left")
        slot = np.arange(n) - start
        capacity = int(slot.max()) + 1
        self.table = np.full((self.shape[0] * self.shape[1], capacity), -1, dtype=np.int64)
        self.table[sorted_key, slot] = order

    def _candidates(self, queries: np.ndarray) -> np.ndarray:
        """Indices (m, 9 * capacity) of the points in the 3 x 3 cells around
        each query; -1 where there is none."""
        cells = np.floor((queries - self.origin) / self.radius_m).astype(np.int64)
        out = []
        for dx in (-1, 0, 1):
            for dy in (-1, 0, 1):
                cx, cy = cells[:, 0] + dx, cells[:, 1] + dy
                inside = (cx >= 0) & (cx < self.shape[0]) & (cy >= 0) & (cy < self.shape[1])
                rows = np.where(inside, cx * self.shape[1] + cy, 0)
                block = self.table[rows]
                out.append(np.where(inside[:, None], block, -1))
        return np.concatenate(out, axis=1)

    def nearest(self, queries: np.ndarray, max_distance_m: float) -> tuple[np.ndarray, np.ndarray]:
        """Distance (m,) to the nearest point within ``max_distance_m``
        (<= ``radius_m``) and its index; ``inf`` and -1 where there is none."""
        q = np.asarray(queries, dtype=np.float64)
        if len(self.points) == 0 or len(q) == 0:
            return np.full(len(q), np.inf), np.full(len(q), -1, dtype=np.int64)
        cand = self._candidates(q)
        pts = self.points[np.maximum(cand, 0)]
        d2 = ((pts - q[:, None, :]) ** 2).sum(axis=2)
        d2 = np.where(cand >= 0, d2, np.inf)
        best = np.argmin(d2, axis=1)
        rows = np.arange(len(q))
        dist = np.sqrt(d2[rows, best])
        idx = cand[rows, best]
        far = dist > max_distance_m
        return np.where(far, np.inf, dist), np.where(far, -1, idx)

    def k_nearest(self, queries: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
        """The ``k`` nearest points within ``radius_m`` of each query:
        indices (m, k), -1 where fewer exist, and the number found (m,)."""
        q = np.asarray(queries, dtype=np.float64)
        cand = self._candidates(q)
        pts = self.points[np.maximum(cand, 0)]
        d2 = ((pts - q[:, None, :]) ** 2).sum(axis=2)
        d2 = np.where((cand >= 0) & (d2 <= self.radius_m**2), d2, np.inf)
        k = min(k, d2.shape[1])
        part = np.argpartition(d2, k - 1, axis=1)[:, :k]
        found = np.isfinite(np.take_along_axis(d2, part, axis=1))
        idx = np.where(found, np.take_along_axis(cand, part, axis=1), -1)
        return idx, found.sum(axis=1)
