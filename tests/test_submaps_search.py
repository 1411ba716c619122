"""Score grids and the branch-and-bound search (slam.matching.grid, .search):
against brute force and the obvious reference versions."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.ndimage import distance_transform_edt

from slam.matching.grid import likelihood_field, max_pool_stack, score_pyramid
from slam.matching.search import CorrelativeSearch, angular_step, branch_and_bound


def walls(spacing: float = 0.02) -> np.ndarray:
    """A room of 8 x 6 m with a short wall inside: points along each wall."""
    def line(a, b):
        n = int(np.hypot(*(np.subtract(b, a))) / spacing)
        t = np.linspace(0.0, 1.0, n)[:, None]
        return np.asarray(a) + t * (np.subtract(b, a))

    return np.concatenate([line((-4, -3), (4, -3)), line((4, -3), (4, 0)), line((-4, 3), (4, 3)),
                           line((-4, -3), (-4, 3)), line((0, 1), (2, 1))])


def scan_of(points: np.ndarray, pose: np.ndarray, n: int, rng) -> np.ndarray:
    """``n`` of the map points seen from ``pose`` (in its frame), with noise."""
    pick = points[rng.choice(len(points), n, replace=False)] + rng.normal(0.0, 0.01, (n, 2))
    c, s = np.cos(pose[2]), np.sin(pose[2])
    return (pick - pose[:2]) @ np.array([[c, -s], [s, c]])


def test_likelihood_field_is_the_gaussian_of_the_distance_to_the_nearest_hit():
    rng = np.random.default_rng(1)
    hits = rng.random((70, 90)) < 0.01
    got = likelihood_field(hits, 0.1, 0.1)
    d = distance_transform_edt(~hits) * 0.1
    within = d <= 0.3 + 1e-9  # 3 sigma
    np.testing.assert_allclose(got[within], np.exp(-0.5 * (d[within] / 0.1) ** 2), atol=1e-6)
    assert np.all(got[~within] < np.exp(-0.5 * 9.0) + 1e-6)  # only the box's corners beyond 3 sigma
    assert likelihood_field(np.zeros((5, 5), bool), 0.1, 0.1).max() == 0.0


def test_max_pool_levels_hold_the_maximum_of_each_block():
    rng = np.random.default_rng(2)
    field = rng.random((23, 17)).astype(np.float32)
    levels = max_pool_stack(field, 3)
    for h, level in enumerate(levels):
        size = 1 << h
        for x, y in [(0, 0), (5, 3), (22, 16), (20, 10), (11, 15)]:
            assert level[x, y] == field[x : x + size, y : y + size].max()


@pytest.mark.slow
@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_branch_and_bound_finds_the_brute_force_optimum(seed):
    rng = np.random.default_rng(seed)
    pts = walls()
    pyr = score_pyramid(pts, 0.05, 0.05, 6, 0.3, pad_cells=30)
    true = np.array([rng.uniform(-1, 1), rng.uniform(-1, 1), rng.uniform(-0.3, 0.3)])
    scan = scan_of(pts, true, 120, rng)
    guess = true + np.array([0.2, -0.15, 0.1])
    window, turn = 0.5, np.radians(15)
    found = branch_and_bound(pyr, scan, guess, window, turn)
    # Every pose of the same space, scored one by one.
    step = angular_step(scan, pyr.resolution_m)
    n_yaw = int(np.ceil(turn / step))
    w = int(np.ceil(window / pyr.resolution_m))
    best = -1.0
    for yaw in guess[2] + step * np.arange(-n_yaw, n_yaw + 1):
        c, s = np.cos(yaw), np.sin(yaw)
        rotated = scan @ np.array([[c, -s], [s, c]]).T
        for dx in range(-w, w + 1):
            for dy in range(-w, w + 1):
                best = max(best, pyr.score(rotated + guess[:2] + pyr.resolution_m * np.array([dx, dy])))
    assert found.score == pytest.approx(best, abs=1e-6)
    assert np.hypot(*(found.pose[:2] - true[:2])) < 0.08 and abs(found.pose[2] - true[2]) < np.radians(1.0)


def test_no_pose_above_the_minimum_score_gives_none():
    rng = np.random.default_rng(4)
    pyr = score_pyramid(walls(), 0.05, 0.05, 5, 0.3, pad_cells=20)
    far = rng.uniform(20, 30, (50, 2))  # points nowhere near a wall
    assert branch_and_bound(pyr, far, np.zeros(3), 0.5, 0.1, min_score=0.2) is None


def test_a_window_larger_than_the_padding_is_refused():
    pyr = score_pyramid(walls(), 0.05, 0.05, 4, 0.3, pad_cells=4)
    with pytest.raises(ValueError, match="padded"):
        CorrelativeSearch(pyr, walls()[:10], np.zeros(3), 2.0, 0.1)


def corridor_with_doors(spacing_m: float) -> np.ndarray:
    """Two walls 2 m apart along x with a door recess every ``spacing_m``."""
    x = np.arange(-20.0, 20.0, 0.02)
    upper = np.column_stack([x, np.full_like(x, 1.0)])
    lower = np.column_stack([x, np.full_like(x, -1.0)])
    recess = []
    for x0 in np.arange(-20.0, 20.0, spacing_m):
        y = np.arange(1.0, 1.3, 0.02)
        recess += [np.column_stack([np.full_like(y, x0), y]), np.column_stack([np.full_like(y, x0 + 0.9), y])]
    return np.concatenate([upper, lower, *recess])


def test_repeated_doors_are_rivals_and_a_unique_room_has_none():
    rng = np.random.default_rng(5)
    doors = corridor_with_doors(2.0)
    pyr = score_pyramid(doors, 0.1, 0.1, 6, 0.3, pad_cells=60)
    scan = scan_of(doors[np.abs(doors[:, 0]) < 4.0], np.zeros(3), 150, rng)
    search = CorrelativeSearch(pyr, scan, np.array([0.3, 0.0, 0.0]), 3.0, np.radians(5))
    best = search.best()
    rivals = search.rivals(best.pose, 0.9 * best.score, 0.5, np.radians(5))
    # The same doors two metres on fit as well.
    assert np.any(np.abs(np.abs(rivals[:, 0] - best.pose[0]) - 2.0) < 0.3)

    room = walls()
    pyr = score_pyramid(room, 0.1, 0.1, 6, 0.3, pad_cells=60)
    scan = scan_of(room, np.zeros(3), 150, rng)
    search = CorrelativeSearch(pyr, scan, np.array([0.3, -0.2, 0.05]), 3.0, np.radians(20))
    best = search.best()
    assert len(search.rivals(best.pose, 0.9 * best.score, 0.5, np.radians(5))) == 0


def test_a_guess_further_off_than_the_window_reaches_ends_on_its_rim():
    from slam.submaps.local import on_rim

    rng = np.random.default_rng(6)
    room = walls()
    pyr = score_pyramid(room, 0.05, 0.05, 6, 0.3, pad_cells=60)
    scan = scan_of(room, np.zeros(3), 150, rng)
    # The truth within the window: its best pose is inside, where the truth is.
    near = CorrelativeSearch(pyr, scan, np.array([0.3, -0.2, 0.05]), 0.6, np.radians(10))
    best = near.best()
    assert np.hypot(*best.pose[:2]) < 0.08 and not on_rim(near, best.pose, np.zeros((0, 3)))
    # A guess 1.2 m off with a 0.6 m window: the window's best is on its rim.
    far = CorrelativeSearch(pyr, scan, np.array([1.2, 0.1, 0.0]), 0.6, np.radians(10))
    best = far.best()
    assert on_rim(far, best.pose, np.zeros((0, 3)))
    # Along a direction the match leaves free the rim says nothing.
    assert not on_rim(far, np.array([0.6, 0.1, 0.0]), np.array([[1.0, 0.0, 0.0]]))
