"""Coarse correlative search of a scan pose over a window (Olson 2009), to
bring a loop candidate into the basin of point-to-line ICP.

A candidate's local map becomes a score grid: each cell holds
``exp(-d^2 / (2 sigma^2))`` with ``d`` its distance to the nearest map point
(sigma = the grid resolution; cells more than two cells from any point
hold 0). The query points are tried at every yaw of the
angular window and every translation of the linear window, on the grid's
resolution, and scored by the mean of the cells they fall in, times a
Gaussian prior around the guess whose standard deviations are the windows
(as Cartographer's real-time matcher weighs its candidates): a look-alike
stretch of corridor far from the guess must fit clearly better to win. The best pose is the start for ICP. All poses of one yaw are scored in one array operation.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class ScoreGrid:
    """Scores (nx, ny) on cells of ``resolution_m`` whose corner (0, 0) is at ``origin`` (2,)."""

    scores: np.ndarray
    origin: np.ndarray
    resolution_m: float


def score_grid(points: np.ndarray, resolution_m: float, margin_m: float) -> ScoreGrid:
    """The score grid of planar map points (n, 2), ``margin_m`` around them."""
    if len(points) == 0:
        return ScoreGrid(np.zeros((1, 1)), np.zeros(2), resolution_m)
    origin = points.min(axis=0) - margin_m
    size = np.ceil((points.max(axis=0) + margin_m - origin) / resolution_m).astype(int) + 1
    # Each point raises the cells around it to its score there (a maximum,
    # so the cell keeps the score of its nearest point).
    pos = (points - origin) / resolution_m
    cells = np.floor(pos).astype(int)
    scores = np.zeros(size, dtype=np.float32)
    for dx in range(-2, 3):
        for dy in range(-2, 3):
            cx, cy = cells[:, 0] + dx, cells[:, 1] + dy
            d2 = (cx + 0.5 - pos[:, 0]) ** 2 + (cy + 0.5 - pos[:, 1]) ** 2
            np.maximum.at(scores, (cx, cy), np.exp(-0.5 * d2).astype(np.float32))
    return ScoreGrid(scores, origin, resolution_m)


def correlative_search(
    query: np.ndarray,
    grid: ScoreGrid,
    guess: np.ndarray,
    linear_window_m: float,
    angular_window_rad: float,
    angular_step_rad: float,
) -> tuple[np.ndarray, float]:
    """The best pose (x, y, yaw) of ``query`` points (n, 2) within the
    windows around ``guess``, and its score in [0, 1] (without the prior)."""
    res = grid.resolution_m
    steps = max(int(np.ceil(linear_window_m / res)), 0)
    offsets = np.arange(-steps, steps + 1)
    shift = np.stack(np.meshgrid(offsets, offsets, indexing="ij"), axis=-1).reshape(-1, 2)
    n_yaw = max(int(np.ceil(angular_window_rad / angular_step_rad)), 0)
    yaws = guess[2] + angular_step_rad * np.arange(-n_yaw, n_yaw + 1)
    nx, ny = grid.scores.shape
    flat = grid.scores.ravel()
    sigma_t = max(linear_window_m, res)
    sigma_yaw = max(angular_window_rad, angular_step_rad)
    prior_t = np.exp(-0.5 * ((shift * res) ** 2).sum(axis=1) / sigma_t**2)
    best_weighted, best_score, best = -1.0, 0.0, np.asarray(guess, dtype=float).copy()
    for yaw in yaws:
        c, s = np.cos(yaw), np.sin(yaw)
        pts = query @ np.array([[c, -s], [s, c]]).T + guess[:2]
        base = np.floor((pts - grid.origin) / res).astype(np.int64)
        ix = base[None, :, 0] + shift[:, 0:1]
        iy = base[None, :, 1] + shift[:, 1:2]
        inside = (ix >= 0) & (ix < nx) & (iy >= 0) & (iy < ny)
        values = np.where(inside, flat[np.where(inside, ix * ny + iy, 0)], 0.0)
        score = values.mean(axis=1)
        weighted = score * prior_t * np.exp(-0.5 * ((yaw - guess[2]) / sigma_yaw) ** 2)
        k = int(np.argmax(weighted))
        if weighted[k] > best_weighted:
            best_weighted, best_score = float(weighted[k]), float(score[k])
            best = np.array([guess[0] + shift[k, 0] * res, guess[1] + shift[k, 1] * res, yaw])
    return best, best_score
