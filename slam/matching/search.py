"""Branch-and-bound correlative search of a scan's pose in a submap.

The search space is every yaw of an angular window (steps small enough that
the farthest point moves by at most one cell) times every cell offset of a
square translation window around a guessed pose. A pose's score is the mean
likelihood-field value at the scan's points (:mod:`slam.matching.grid`). The
best pose is found exactly, without scoring every pose, by branch and bound
over the field's max-pooled pyramid (Hess et al. 2016, Sec. V): a block of
``2^h x 2^h`` offsets at one yaw scores at most its mean on level ``h``.

The search runs level by level rather than node by node (compiled:
:mod:`slam.matching.kernels`):

1. *dive*: from the best coarsest block, take the best child down to a
   single pose; its score is a lower bound on the optimum;
2. *sweep*: every block whose bound beats that score (less a tie
   tolerance) is split into its children, all at once, level by level down
   to single poses; the best of those is the optimum.

Of the poses that score within ``tie_tolerance`` of the optimum, the one
nearest the guess is returned: along a corridor, where the scan fits
equally well anywhere, the search does not wander off the guess.

Frames: the scan's points in its own frame; the guess and the result are
the scan frame's pose (x, y, yaw; m, rad) in the submap's frame.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from slam.matching.grid import ScorePyramid


@dataclass(frozen=True)
class SearchResult:
    """The best pose (x, y, yaw) and its score in [0, 1]; ``evaluated``:
    how many blocks and poses were scored."""

    pose: np.ndarray
    score: float
    evaluated: int


def angular_step(points: np.ndarray, resolution_m: float) -> float:
    """The yaw step (rad) that moves the scan's farthest points (the 95th
    percentile of the ranges, so that one stray return does not set it) by
    one cell (Hess et al. 2016, Eq. 7)."""
    r = np.hypot(points[:, 0], points[:, 1])
    d = max(float(np.percentile(r, 95)) if len(r) else 1.0, 2.0 * resolution_m)
    return float(np.arccos(1.0 - resolution_m**2 / (2.0 * d * d)))


class CorrelativeSearch:
    """The search space of one scan in one grid: every yaw of the angular
    window (``yaws``) times every cell offset of the linear window, with the
    points' cells precomputed per yaw; see the module docstring."""

    def __init__(self, pyr: ScorePyramid, points: np.ndarray, guess: np.ndarray, linear_window_m: float,
                 angular_window_rad: float, angular_step_rad: float | None = None):
        pts = np.ascontiguousarray(points, dtype=np.float64)
        self.pyr, self.guess = pyr, np.asarray(guess, dtype=float)
        res = pyr.resolution_m
        self.step = angular_step_rad if angular_step_rad is not None else angular_step(pts, res)
        n_yaw = int(np.ceil(angular_window_rad / self.step)) if angular_window_rad > 0 else 0
        self.yaws = guess[2] + self.step * np.arange(-n_yaw, n_yaw + 1)
        self.linear_window_m, self.angular_window_rad = linear_window_m, angular_window_rad
        self.w = w = int(np.ceil(linear_window_m / res))
        self.depth = min(pyr.depth, max(int(np.ceil(np.log2(2 * w + 1))), 0))
        self.hi = hi = 2 * w  # offsets run over [0, 2w]
        if pyr.pad < hi + (1 << self.depth):
            raise ValueError(f"a window of {w} cells needs a grid padded by {hi + (1 << self.depth)} cells, not {pyr.pad}")
        # The points' cells at every yaw, for the window's lowest offset (-w, -w).
        from slam.matching import kernels

        self._kernels = kernels
        nx, ny = pyr.field.shape
        self._levels = pyr.stack.reshape(len(pyr.stack), -1)
        self._ny = ny
        self.base = kernels.point_cells(np.cos(self.yaws), np.sin(self.yaws), pts, np.asarray(guess, dtype=np.float64),
                                        np.asarray(pyr.origin, dtype=np.float64), float(res), w, hi, nx, ny)
        self.evaluated = 0

    def scores(self, level: int, a: np.ndarray, ox: np.ndarray, oy: np.ndarray) -> np.ndarray:
        """Scores of the blocks of ``level`` at yaw indices ``a`` and offsets
        (``ox``, ``oy``) (k,): their mean on that level, a bound on every
        pose inside."""
        self.evaluated += len(a)
        return self._kernels.block_scores(self._levels, level, self._ny, self.base, a, ox, oy)

    def top(self):
        """The coarsest blocks (yaw index, x and y offsets) and their bounds."""
        stride = 1 << self.depth
        offs = np.arange(0, self.hi + 1, stride)
        a = np.repeat(np.arange(len(self.yaws)), len(offs) ** 2)
        ox = np.tile(np.repeat(offs, len(offs)), len(self.yaws))
        oy = np.tile(offs, len(self.yaws) * len(offs))
        return a, ox, oy, self.scores(self.depth, a, ox, oy)

    def dive(self, a, ox, oy, sc) -> float:
        """The score of the pose reached from the best block by always taking the best child."""
        k = int(np.argmax(sc))
        best, evaluated = self._kernels.dive(self._levels, self._ny, self.base, int(a[k]), int(ox[k]), int(oy[k]),
                                             float(sc[k]), self.depth, self.hi)
        self.evaluated += evaluated
        return best

    def sweep(self, blocks, bound: float, exclude: tuple[np.ndarray, int, int, int] | None = None):
        """Every pose whose score reaches ``bound``, from the blocks given;
        ``exclude`` (near_yaw, bx, by, r), if given, keeps only the blocks
        that reach outside the box of ``r`` cells around offset (bx, by) at
        the yaws ``near_yaw`` (bool per yaw)."""
        a, ox, oy, sc = blocks
        near_yaw, bx, by, r = exclude if exclude is not None else (np.zeros(0, dtype=bool), 0, 0, 0)
        a, ox, oy, sc, evaluated = self._kernels.sweep(self._levels, self._ny, self.base, a, ox, oy, sc, float(bound),
                                                       self.depth, self.hi, exclude is not None, near_yaw, bx, by, r)
        self.evaluated += evaluated
        return a, ox, oy, sc

    def poses(self, a: np.ndarray, ox: np.ndarray, oy: np.ndarray) -> np.ndarray:
        """Poses (k, 3) of yaw indices and offsets."""
        res = self.pyr.resolution_m
        return np.column_stack([self.guess[0] + (ox - self.w) * res, self.guess[1] + (oy - self.w) * res, self.yaws[a]])

    def best(self, min_score: float = 0.0, tie_tolerance: float = 0.0) -> SearchResult | None:
        """The best pose (of the near-ties within ``tie_tolerance``, the one
        nearest the guess, in window units); None below ``min_score``."""
        blocks = self.top()
        bound = max(self.dive(*blocks), min_score) - tie_tolerance
        a, ox, oy, sc = self.sweep(blocks, bound)
        if len(sc) == 0 or sc.max() < min_score:
            return None
        top = float(sc.max())
        tie = sc >= top - tie_tolerance
        cand = self.poses(a[tie], ox[tie], oy[tie])
        d = cand - self.guess
        far = (np.hypot(d[:, 0], d[:, 1]) / max(self.linear_window_m, self.pyr.resolution_m)
               + np.abs(d[:, 2]) / max(self.angular_window_rad, self.step))
        k = int(np.argmin(far))
        return SearchResult(cand[k], float(sc[tie][k]), self.evaluated)

    def edge_offsets(self, pose: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``pose``'s offset from the guess (x, y, yaw) and the largest offset
        that is not on the window's rim (a cell, a yaw step inside it); the
        rim is infinite in a dimension the window does not search."""
        res = self.pyr.resolution_m
        d = np.asarray(pose, dtype=float) - self.guess
        d[2] = (d[2] + np.pi) % (2.0 * np.pi) - np.pi
        n_yaw = (len(self.yaws) - 1) // 2
        lin = (self.w - 1) * res if self.w >= 2 else np.inf
        ang = (n_yaw - 1) * self.step if n_yaw >= 2 else np.inf
        return d, np.array([lin, lin, ang])

    def rivals(self, pose: np.ndarray, bound: float, exclude_m: float, exclude_rad: float) -> np.ndarray:
        """Poses (k, 3) that score ``bound`` or more outside the box of
        ``exclude_m`` and ``exclude_rad`` around ``pose``: other places the
        scan fits about as well (a repeated door, the next stretch of a
        corridor)."""
        res = self.pyr.resolution_m
        bx = int(round((pose[0] - self.guess[0]) / res)) + self.w
        by = int(round((pose[1] - self.guess[1]) / res)) + self.w
        r = int(np.floor(exclude_m / res))
        near_yaw = np.abs(self.yaws - pose[2]) <= exclude_rad
        a, ox, oy, _ = self.sweep(self.top(), bound, (near_yaw, bx, by, r))
        return self.poses(a, ox, oy)


def branch_and_bound(
    pyr: ScorePyramid,
    points: np.ndarray,
    guess: np.ndarray,
    linear_window_m: float,
    angular_window_rad: float,
    min_score: float = 0.0,
    tie_tolerance: float = 0.0,
    angular_step_rad: float | None = None,
) -> SearchResult | None:
    """The best pose of ``points`` (n, 2) within the windows around
    ``guess``; None when no pose scores ``min_score`` or more. See the
    module docstring."""
    if len(points) == 0:
        return None
    search = CorrelativeSearch(pyr, points, guess, linear_window_m, angular_window_rad, angular_step_rad)
    return search.best(min_score, tie_tolerance)
