"""Finished submaps by where they lie: a grid of their centres, so that a
scan's search for the submaps near it looks at a few cells rather than at
every submap mapped so far (the work per scan is bounded by what is near,
not by the length of the run)."""

from __future__ import annotations

import numpy as np


class NearSubmaps:
    """The world centres (x, y) of the finished submaps, in square cells of
    ``cell_m``. :meth:`add` one as it finishes; :meth:`place` all again when
    the estimate they hang on moves (after an optimisation)."""

    def __init__(self, cell_m: float):
        self.cell_m = cell_m
        self.ids: list[int] = []
        self.xy: list[tuple[float, float]] = []
        self._cells: dict[tuple[int, int], list[int]] = {}

    def _cell(self, x: float, y: float) -> tuple[int, int]:
        return int(np.floor(x / self.cell_m)), int(np.floor(y / self.cell_m))

    def place(self, ids: list[int], xy: np.ndarray) -> None:
        """Every finished submap ``ids`` at its centre ``xy`` (k, 2), replacing what was there."""
        self.ids, self.xy, self._cells = [], [], {}
        for sid, centre in zip(ids, xy):
            self.add(sid, centre)

    def add(self, sid: int, xy: np.ndarray) -> None:
        x, y = float(xy[0]), float(xy[1])
        self._cells.setdefault(self._cell(x, y), []).append(len(self.ids))
        self.ids.append(sid)
        self.xy.append((x, y))

    def within(self, p: np.ndarray, radius_m: float) -> tuple[np.ndarray, np.ndarray]:
        """The submaps whose centre is within ``radius_m`` of ``p`` (x, y),
        nearest first (equal distances in the order they were added), and
        their distances (m)."""
        cx0, cy0 = self._cell(p[0] - radius_m, p[1] - radius_m)
        cx1, cy1 = self._cell(p[0] + radius_m, p[1] + radius_m)
        rows = [r for cx in range(cx0, cx1 + 1) for cy in range(cy0, cy1 + 1) for r in self._cells.get((cx, cy), ())]
        rows = np.array(sorted(rows), dtype=int)
        if len(rows) == 0:
            return rows, np.zeros(0)
        dist = np.hypot(*(np.array([self.xy[r] for r in rows]) - p[:2]).T)
        keep = dist <= radius_m
        rows, dist = rows[keep], dist[keep]
        order = np.argsort(dist, kind="stable")
        return np.array([self.ids[r] for r in rows[order]], dtype=int), dist[order]
