"""Finished submaps by where they lie: a grid of their centres, so that a
scan's search for the submaps near it looks at a few cells rather than at
every submap mapped so far (the work per scan is bounded by what is near,
not by the length of the run)."""

from __future__ import annotations

import numpy as np


class NearSubmaps:
    """The world centres (x, y) of the finished submaps, in square cells of
    ``cell_m``. :meth:`add` one as it finishes; :meth:`place` all again when
    the estimate they hang on moves (after an optimisation).

    The centres and ids are kept in arrays (rows in the order added; room is
    doubled when full, so adding one costs the same however many there are),
    and each cell lists its rows: a query reads only its cells' rows."""

    def __init__(self, cell_m: float):
        self.cell_m = cell_m
        self._ids = np.zeros(0, dtype=int)
        self._xy = np.zeros((0, 2))
        self._count = 0
        self._cells: dict[tuple[int, int], list[int]] = {}

    def _cell(self, x: float, y: float) -> tuple[int, int]:
        return int(np.floor(x / self.cell_m)), int(np.floor(y / self.cell_m))

    def place(self, ids: list[int], xy: np.ndarray) -> None:
        """Every finished submap ``ids`` at its centre ``xy`` (k, 2), replacing what was there."""
        xy = np.asarray(xy, dtype=float).reshape(-1, 2)
        self._ids, self._xy, self._count = np.asarray(ids, dtype=int).reshape(-1), xy.copy(), len(xy)
        # The cells of all at once, the rows sorted by cell (stably: each
        # cell's rows in the order added), cut where the cell changes.
        cells = np.floor(xy / self.cell_m).astype(int)
        rows = np.lexsort((cells[:, 1], cells[:, 0]))
        sorted_cells = cells[rows]
        cuts = np.flatnonzero(np.any(sorted_cells[1:] != sorted_cells[:-1], axis=1)) + 1
        firsts = sorted_cells[np.concatenate([[0], cuts])] if len(rows) else sorted_cells
        self._cells = {(cx, cy): part.tolist() for (cx, cy), part in zip(firsts.tolist(), np.split(rows, cuts))}

    def add(self, sid: int, xy: np.ndarray) -> None:
        x, y = float(xy[0]), float(xy[1])
        row = self._count
        if row == len(self._ids):  # full: twice the room
            room = max(2 * row, 16)
            grown_ids, grown_xy = np.zeros(room, dtype=int), np.zeros((room, 2))
            grown_ids[:row], grown_xy[:row] = self._ids[:row], self._xy[:row]
            self._ids, self._xy = grown_ids, grown_xy
        self._ids[row], self._xy[row] = sid, (x, y)
        self._count += 1
        self._cells.setdefault(self._cell(x, y), []).append(row)

    def within(self, p: np.ndarray, radius_m: float) -> tuple[np.ndarray, np.ndarray]:
        """The submaps whose centre is within ``radius_m`` of ``p`` (x, y),
        nearest first (equal distances in the order they were added), and
        their distances (m)."""
        cx0, cy0 = self._cell(p[0] - radius_m, p[1] - radius_m)
        cx1, cy1 = self._cell(p[0] + radius_m, p[1] + radius_m)
        rows = [r for cx in range(cx0, cx1 + 1) for cy in range(cy0, cy1 + 1) for r in self._cells.get((cx, cy), ())]
        rows = np.sort(np.array(rows, dtype=int))
        if len(rows) == 0:
            return rows, np.zeros(0)
        dist = np.hypot(*(self._xy[rows] - p[:2]).T)
        keep = dist <= radius_m
        rows, dist = rows[keep], dist[keep]
        order = np.argsort(dist, kind="stable")
        return self._ids[rows[order]], dist[order]
