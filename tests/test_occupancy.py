"""The occupancy grid (slam.outputs.occupancy): the vectorised ray casting against a
loop over beams and samples, and the map of a room seen from known poses."""

from __future__ import annotations

import numpy as np
import pytest

from slam.outputs.occupancy import FREE, OCCUPIED, UNKNOWN, GridModel, build_grid, crossed_cells, free_start, logit
from slam.recording import Trajectory

RES = 0.05
ROOM = 2.0  # walls at x, y = +-2 m


def poses(*xyyaw: tuple[float, float, float]) -> Trajectory:
    a = np.array(xyyaw, dtype=float).reshape(-1, 3)
    return Trajectory(np.arange(len(a), dtype=float), a[:, 0], a[:, 1], a[:, 2])


def room_scan(pose: np.ndarray, angles: np.ndarray, half: float = ROOM) -> np.ndarray:
    """Ranges from ``pose`` to the walls of a square room (m)."""
    x, y, yaw = pose
    c, s = np.cos(yaw + angles), np.sin(yaw + angles)
    with np.errstate(divide="ignore"):
        tx = np.where(c > 0, (half - x) / c, np.where(c < 0, (-half - x) / c, np.inf))
        ty = np.where(s > 0, (half - y) / s, np.where(s < 0, (-half - y) / s, np.inf))
    return np.minimum(tx, ty).astype(np.float32)


def cell_centres(grid) -> tuple[np.ndarray, np.ndarray]:
    """World x and y (m) of each cell's centre of a GridMap."""
    rows, cols = grid.cells.shape
    x = grid.origin[0] + (np.arange(cols) + 0.5) * grid.resolution_m
    y = grid.origin[1] + (np.arange(rows) + 0.5) * grid.resolution_m
    return np.meshgrid(x, y)


def test_crossed_cells_match_a_loop_over_beams_and_samples():
    rng = np.random.default_rng(3)
    n, cols = 200, 97
    x0, y0 = rng.uniform(20, 70, n), rng.uniform(20, 70, n)
    heading = rng.uniform(-np.pi, np.pi, n)
    dx, dy = np.cos(heading), np.sin(heading)
    counts = rng.integers(0, 25, n)
    expected = []
    for b in range(n):  # the same float32 arithmetic, one sample at a time
        for j in range(counts[b]):
            col = int(np.float32(x0[b]) + np.float32(j) * np.float32(dx[b]))
            row = int(np.float32(y0[b]) + np.float32(j) * np.float32(dy[b]))
            expected.append(row * cols + col)
    got = crossed_cells(x0, y0, dx, dy, counts, cols)
    assert sorted(got.tolist()) == sorted(expected)
    assert len(got) == counts.sum()


def test_free_start_leaves_no_gap_wider_than_a_cell():
    increment = np.radians(0.5)
    start = free_start(541, increment, RES)
    assert start[0] == 0.0
    reach = RES / increment  # beyond it neighbouring beams are a cell apart: every beam counts
    assert np.all(start <= reach / 2 + 1e-12) and np.all(start[1::2] == pytest.approx(reach / 2))
    # At any range, the beams sampled there lie at most a cell apart.
    for r in (0.3, 1.0, 2.5, 4.0):
        sampled = np.flatnonzero(start <= r)
        assert np.max(np.diff(sampled)) * increment * r <= RES + 1e-12, r


def test_one_beam_frees_its_cells_and_occupies_its_end():
    # Along +x from mid-cell to 1 m on: the end cell is hit once; the cells up
    # to a cell short of it are crossed once each (one sample per cell).
    grid = build_grid(np.array([[1.0]], dtype=np.float32), np.array([0.0]), poses((0.012, 0.012, 0.0)), 0.1, 10.0,
                      GridModel(resolution_m=RES))
    row = int((0.012 - grid.origin[1]) / RES)
    line = grid.log_odds[row]
    col0, col_end = int((0.012 - grid.origin[0]) / RES), int((1.012 - grid.origin[0]) / RES)
    assert col_end - col0 == 20
    assert line[col_end] == pytest.approx(logit(0.7))
    np.testing.assert_allclose(line[col0 : col_end - 1], logit(0.4), rtol=1e-6)
    assert np.count_nonzero(grid.log_odds) == 19 + 1
    assert grid.observed.sum() == 19 + 1


def test_a_room_seen_from_a_dozen_poses_is_walls_around_free_space():
    angles = np.radians(np.arange(-135.0, 135.25, 0.25))
    rng = np.random.default_rng(1)
    xyyaw = np.column_stack([rng.uniform(-1.5, 1.5, (12, 2)), rng.uniform(-np.pi, np.pi, 12)])
    ranges = np.array([room_scan(p, angles) for p in xyyaw])
    grid = build_grid(ranges, angles, poses(*map(tuple, xyyaw)), 0.1, 10.0, GridModel(resolution_m=RES)).classify()
    x, y = cell_centres(grid)
    inside = np.maximum(np.abs(x), np.abs(y))
    wall = np.abs(inside - ROOM) <= RES / 2 + 1e-9  # the two rings of cells the walls' line divides
    occupied = grid.cells == OCCUPIED
    # Hits only on the walls, and all round them: every cell's length of
    # wall (away from the corners) has an occupied cell across it.
    assert np.sum(occupied & ~wall) == 0
    for coord, other in ((x, y), (y, x)):
        for sign in (1.0, -1.0):
            band = (np.abs(sign * coord - ROOM) <= RES / 2 + 1e-9) & (np.abs(other) < ROOM - RES)
            along = np.round(other[band] / RES).astype(int)
            covered = set(along[occupied[band]].tolist())
            assert len(covered) / len(set(along.tolist())) > 0.97, (sign, len(covered))
    # Free inside, a cell clear of the walls; nothing known beyond them.
    assert np.mean(grid.cells[inside < ROOM - 2 * RES] == FREE) > 0.99
    assert np.all(grid.cells[inside > ROOM + RES] == UNKNOWN)


def test_beams_without_a_return_free_only_up_to_the_cap():
    angles = np.radians(np.arange(-90.0, 90.5, 0.5))
    ranges = np.full((1, len(angles)), np.inf, dtype=np.float32)
    ranges[0, :10] = 12.0  # at or beyond the scanner's range: no return either
    ranges[0, 10:20] = np.nan  # invalid: says nothing
    grid = build_grid(ranges, angles, poses((0.0, 0.0, 0.0)), 0.1, 10.0, GridModel(resolution_m=RES, no_return_m=3.0))
    classified = grid.classify(free_below=0.45)  # one crossing (p = 0.4) counts as free here
    cells = classified.cells
    x, y = cell_centres(classified)
    r, bearing = np.hypot(x, y), np.degrees(np.arctan2(y, x))
    assert not np.any(cells == OCCUPIED)
    assert np.all(cells[r > 3.0 + 2 * RES] == UNKNOWN)
    assert np.mean(cells[(r > 0.5) & (r < 2.9) & (np.abs(bearing) < 80)] == FREE) > 0.95
    assert np.mean(cells[(r > 0.5) & (r < 2.9) & (bearing > -89.5) & (bearing < -86.0)] == FREE) > 0.9  # beams at 12 m
    # The middle of the NaN beams' sector, where no other beam reaches.
    assert np.all(cells[(r > 2.0) & (r < 2.9) & (np.abs(bearing + 82.75) < 1.0)] == UNKNOWN)


def test_the_grid_does_not_depend_on_the_order_of_the_scans():
    angles = np.radians(np.arange(-135.0, 135.25, 0.5))
    rng = np.random.default_rng(0)
    xyyaw = np.column_stack([rng.uniform(-1.5, 1.5, (12, 2)), rng.uniform(-np.pi, np.pi, 12)])
    ranges = np.array([room_scan(p, angles) for p in xyyaw])
    a = build_grid(ranges, angles, poses(*map(tuple, xyyaw)), 0.1, 10.0, GridModel())
    order = rng.permutation(12)
    b = build_grid(ranges[order], angles, poses(*map(tuple, xyyaw[order])), 0.1, 10.0, GridModel())
    np.testing.assert_array_equal(a.log_odds, b.log_odds)
    np.testing.assert_array_equal(a.origin, b.origin)


def test_a_grid_too_large_is_not_built(caplog):
    angles = np.array([0.0])
    traj = poses((0.0, 0.0, 0.0), (5000.0, 5000.0, 0.0))
    assert build_grid(np.ones((2, 1), dtype=np.float32), angles, traj, 0.1, 10.0, GridModel()) is None
    assert "output.grid_resolution_m" in caplog.text
