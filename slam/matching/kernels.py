"""The matching toolbox's inner loops, compiled (numba).

The likelihood field and the branch-and-bound search
(:mod:`slam.matching.grid`, :mod:`slam.matching.search`) spend their time
in loops over cells, points and tree nodes; as numpy they were a sequence
of temporary arrays per tree level, here each is one pass. The refinement's
point-to-line terms (:mod:`slam.matching.icp`) were a dozen small numpy
operations per iteration, here one call. (The pyramid's
max-pooling stays numpy: its maxima of uint8 rows run wider there.) Every
kernel computes exactly what the numpy version in ``tests/test_kernels.py``
computes, bit for bit: the same float32 products and maxima, integer sums
of the uint8 levels (exact, so their order does not matter) divided as
numpy's mean divides, and no fast-math (no reassociation, no fused
multiply-add).

The module is imported on the first search, so a command that matches no
scans does not pay numba's import. Compiled code is cached beside the
module, else in the user's cache folder (numba's own fallback); where
neither can be written, each process compiles once (about 3 s) instead.
"""

from __future__ import annotations

import numpy as np

from slam.matching.jit import import_numba

numba = import_numba()

SCALE = 1.0 / 255
"""A level's value in 255ths to a field value (:data:`slam.matching.grid.LEVELS`)."""


def _jit(fn):
    try:
        return numba.njit(cache=True, nogil=True)(fn)
    except RuntimeError:  # no folder to cache in (a read-only install and home)
        return numba.njit(nogil=True)(fn)


# -- the likelihood field -------------------------------------------------------------


@_jit
def spread_hits(hits: np.ndarray, g: np.ndarray, x0: int, x1: int, y0: int, y1: int, field: np.ndarray) -> None:
    """Into ``field[x0:x1, y0:y1]``: ``max_k g[k] * in[x + k - r, y]`` after
    the same along y, ``in`` the hits of that box as 0 and 1 (none beyond
    it) and ``r = (len(g) - 1) / 2``: the separable max-product convolution
    of :func:`slam.matching.grid.likelihood_field`. Spread from the nonzero
    cells, the only ones that can raise a maximum: the products are those of
    the gather, and maxima commute."""
    reach = (len(g) - 1) // 2
    along_y = np.zeros((x1 - x0, y1 - y0), dtype=np.float32)
    for x in range(x0, x1):
        for y in range(y0, y1):
            if hits[x, y]:
                for k in range(len(g)):
                    t = y - (k - reach)  # the target whose gather reads (x, y) with g[k]
                    if y0 <= t < y1:
                        v = g[k] * np.float32(1.0)
                        if v > along_y[x - x0, t - y0]:
                            along_y[x - x0, t - y0] = v
    for x in range(x0, x1):
        for y in range(y0, y1):
            s = along_y[x - x0, y - y0]
            if s > 0:
                for k in range(len(g)):
                    t = x - (k - reach)
                    if x0 <= t < x1:
                        v = g[k] * s
                        if v > field[t, y]:
                            field[t, y] = v


# -- the branch-and-bound search ------------------------------------------------------


@_jit
def point_cells(c: np.ndarray, s: np.ndarray, pts: np.ndarray, guess: np.ndarray, origin: np.ndarray,
                resolution_m: float, w: int, hi: int, nx: int, ny: int) -> np.ndarray:
    """Flat cell indices (yaws, n) int32 of points (n, 2) turned by each
    yaw (cosines ``c``, sines ``s``) and placed at ``guess``, for the
    window's lowest offset (``-w`` cells), clipped so that offsets up to
    ``hi`` stay in the grid."""
    out = np.empty((len(c), len(pts)), dtype=np.int32)
    for i in range(len(c)):
        for j in range(len(pts)):
            x = c[i] * pts[j, 0] - s[i] * pts[j, 1] + guess[0]
            y = s[i] * pts[j, 0] + c[i] * pts[j, 1] + guess[1]
            ix = np.int32(np.floor((x - origin[0]) / resolution_m)) - np.int32(w)
            iy = np.int32(np.floor((y - origin[1]) / resolution_m)) - np.int32(w)
            ix = min(max(ix, 0), nx - 1 - hi)
            iy = min(max(iy, 0), ny - 1 - hi)
            out[i, j] = np.int32(np.int64(ix) * ny + iy)
    return out


@_jit
def _score(level: np.ndarray, cells: np.ndarray, shift: int) -> float:
    total = 0
    for j in range(len(cells)):
        total += np.int64(level[cells[j] + shift])
    return total / len(cells) * SCALE


@_jit
def block_scores(levels: np.ndarray, level: int, ny: int, base: np.ndarray, a: np.ndarray, ox: np.ndarray,
                 oy: np.ndarray) -> np.ndarray:
    """Mean of ``levels[level]`` (levels, nx * ny) over the points of yaws
    ``a`` shifted by (``ox``, ``oy``) cells, as a field value."""
    out = np.empty(len(a), dtype=np.float64)
    for k in range(len(a)):
        out[k] = _score(levels[level], base[a[k]], ox[k] * ny + oy[k])
    return out


@_jit
def dive(levels: np.ndarray, ny: int, base: np.ndarray, a: int, ox: int, oy: int, best: float, depth: int,
         hi: int):
    """From the block (``a``, ``ox``, ``oy``) on level ``depth``, scoring
    ``best``, the best child (the first of the best) level by level down to
    a pose: its score and how many blocks were scored."""
    evaluated = 0
    for level in range(depth, 0, -1):
        half = 1 << (level - 1)
        kx, ky, first = ox, oy, True
        for c in range(4):
            cx = ox + (half if c & 1 else 0)
            cy = oy + (half if c >= 2 else 0)
            if cx > hi or cy > hi:
                continue
            evaluated += 1
            sc = _score(levels[level - 1], base[a], cx * ny + cy)
            if first or sc > best:
                best, kx, ky, first = sc, cx, cy, False
        ox, oy = kx, ky
    return best, evaluated


@_jit
def _outside(level: int, a, ox, oy, near_yaw, bx: int, by: int, r: int) -> np.ndarray:
    size = (1 << level) - 1
    keep = np.empty(len(a), dtype=np.bool_)
    for k in range(len(a)):
        keep[k] = not (near_yaw[a[k]] and ox[k] >= bx - r and ox[k] + size <= bx + r
                       and oy[k] >= by - r and oy[k] + size <= by + r)
    return keep


@_jit
def sweep(levels: np.ndarray, ny: int, base: np.ndarray, a: np.ndarray, ox: np.ndarray, oy: np.ndarray,
          sc: np.ndarray, bound: float, depth: int, hi: int, excluding: bool, near_yaw: np.ndarray,
          bx: int, by: int, r: int):
    """Every pose whose score reaches ``bound``, from the blocks (``a``,
    ``ox``, ``oy``) of level ``depth`` with scores ``sc``, children in the
    order (0, 0), (h, 0), (0, h), (h, h); with ``excluding``, only the
    blocks that reach outside the box of ``r`` cells around (``bx``,
    ``by``) at the yaws ``near_yaw``. Returns the poses' yaw indices,
    offsets and scores, and how many blocks were scored."""
    keep = sc >= bound
    a, ox, oy, sc = a[keep], ox[keep], oy[keep], sc[keep]
    evaluated = 0
    for level in range(depth, 0, -1):
        if excluding:
            keep = _outside(level, a, ox, oy, near_yaw, bx, by, r)
            a, ox, oy = a[keep], ox[keep], oy[keep]
        half = 1 << (level - 1)
        na = np.empty(4 * len(a), dtype=a.dtype)
        nx_ = np.empty(4 * len(a), dtype=ox.dtype)
        ny_ = np.empty(4 * len(a), dtype=oy.dtype)
        nsc = np.empty(4 * len(a), dtype=np.float64)
        m = 0
        below = levels[level - 1]
        for p in range(len(a)):
            row = base[a[p]]
            for c in range(4):
                cx = ox[p] + (half if c & 1 else 0)
                cy = oy[p] + (half if c >= 2 else 0)
                if cx > hi or cy > hi:
                    continue
                evaluated += 1
                s = _score(below, row, cx * ny + cy)
                if s >= bound:
                    na[m], nx_[m], ny_[m], nsc[m] = a[p], cx, cy, s
                    m += 1
        a, ox, oy, sc = na[:m], nx_[:m], ny_[:m], nsc[:m]
    if excluding:
        keep = _outside(0, a, ox, oy, near_yaw, bx, by, r)
        a, ox, oy, sc = a[keep], ox[keep], oy[keep], sc[keep]
    return a, ox, oy, sc, evaluated


# -- nearest map points -----------------------------------------------------------------


@_jit
def cell_index(points: np.ndarray, cell_m: float):
    """Points (m, 2) sorted into square cells of ``cell_m``: the grid's
    corner (2,), its size in cells (nx, ny), the point indices ``order``
    (m,) by cell (x * ny + y) and where each cell's run starts in it
    (nx * ny + 1,)."""
    lo = np.empty(2)
    lo[0], lo[1] = points[:, 0].min(), points[:, 1].min()
    cx = np.floor((points[:, 0] - lo[0]) / cell_m).astype(np.int64)
    cy = np.floor((points[:, 1] - lo[1]) / cell_m).astype(np.int64)
    nx, ny = cx.max() + 1, cy.max() + 1
    starts = np.zeros(nx * ny + 1, dtype=np.int64)
    for j in range(len(points)):
        starts[cx[j] * ny + cy[j] + 1] += 1
    for k in range(nx * ny):
        starts[k + 1] += starts[k]
    fill = starts[:-1].copy()
    order = np.empty(len(points), dtype=np.int64)
    for j in range(len(points)):
        key = cx[j] * ny + cy[j]
        order[fill[key]] = j
        fill[key] += 1
    return lo, nx, ny, order, starts


@_jit
def nearest_within(queries: np.ndarray, points: np.ndarray, lo: np.ndarray, nx: int, ny: int, cell_m: float,
                   order: np.ndarray, starts: np.ndarray, within_m: float, rtol: float):
    """For each query (q, 2), the index of the nearest of ``points`` (m, 2)
    closer than ``within_m`` (no more than ``cell_m``), -1 for none, from
    the cells around the query's (:func:`cell_index`); and whether that
    answer is unsure: a second point within ``rtol`` (relative) as near, or
    the nearest within ``rtol`` of ``within_m``, where the last bit of a
    distance decides."""
    bound = within_m * within_m
    idx = np.full(len(queries), -1, dtype=np.int64)
    unsure = np.zeros(len(queries), dtype=np.bool_)
    for i in range(len(queries)):
        qx, qy = queries[i, 0], queries[i, 1]
        fx = np.floor((qx - lo[0]) / cell_m)
        fy = np.floor((qy - lo[1]) / cell_m)
        if not (-2.0 < fx < nx + 1.0 and -2.0 < fy < ny + 1.0):
            continue  # no cell within reach
        x0, y0 = max(np.int64(fx) - 1, 0), max(np.int64(fy) - 1, 0)
        x1, y1 = min(np.int64(fx) + 1, nx - 1), min(np.int64(fy) + 1, ny - 1)
        best, second, k = np.inf, np.inf, -1
        for x in range(x0, x1 + 1):
            for y in range(y0, y1 + 1):
                key = x * ny + y
                for r in range(starts[key], starts[key + 1]):
                    j = order[r]
                    dx, dy = qx - points[j, 0], qy - points[j, 1]
                    d = dx * dx + dy * dy
                    if d < best:
                        best, second, k = d, best, j
                    elif d < second:
                        second = d
        if k < 0:
            continue
        unsure[i] = second <= best * (1.0 + rtol) or abs(best - bound) <= rtol * bound
        if best < bound:
            idx[i] = k
    return idx, unsure


@_jit
def line_terms(qw: np.ndarray, rq: np.ndarray, idx: np.ndarray, points: np.ndarray, normals: np.ndarray):
    """The point-to-line terms of :func:`slam.matching.icp.refine` for
    queries ``qw`` (q, 2) (``rq`` (q, 2): the same points turned but not
    moved) matched to map points ``idx`` (q,) (-1: none): which have a
    match (q,), and for those the residual along the map point's normal
    (k,) and its Jacobian (k, 3) in x, y and yaw. The numpy version's
    arithmetic (products summed left to right, no fused multiply-add)."""
    ok = idx >= 0
    k = 0
    for i in range(len(idx)):
        if ok[i]:
            k += 1
    res = np.empty(k)
    jac = np.empty((k, 3))
    k = 0
    for i in range(len(idx)):
        j = idx[i]
        if j < 0:
            continue
        n0, n1 = normals[j, 0], normals[j, 1]
        d0 = qw[i, 0] - points[j, 0]
        d1 = qw[i, 1] - points[j, 1]
        res[k] = n0 * d0 + n1 * d1
        jac[k, 0] = n0
        jac[k, 1] = n1
        jac[k, 2] = n1 * rq[i, 0] - n0 * rq[i, 1]
        k += 1
    return ok, res, jac


def load() -> None:
    """Compile every kernel, or load it from the cache, for the types the
    matching calls it with: the first call of the first kernel sets up
    numba's compiler (about 0.4 s, cached or not). A caller with time to
    spare, waiting for the front-end, can take that out of the first
    search."""
    field = np.zeros((4, 4), dtype=np.float32)
    spread_hits(np.ones((4, 4), dtype=np.bool_), np.ones(3, dtype=np.float32), 0, 4, 0, 4, field)
    one, some = np.zeros(1), np.zeros((1, 2))
    base = point_cells(one, one, some, np.zeros(3), np.zeros(2), 1.0, 0, 0, 4, 4)
    levels = np.zeros((1, 16), dtype=np.uint8)
    blocks = np.zeros(1, dtype=np.int64)
    sc = block_scores(levels, 0, 4, base, blocks, blocks, blocks)
    dive(levels, 4, base, 0, 0, 0, 0.0, 0, 0)
    sweep(levels, 4, base, blocks, blocks, blocks, sc, 0.0, 0, 0, False, np.zeros(1, dtype=np.bool_), 0, 0, 0)
    grid = cell_index(some, 1.0)
    idx, _ = nearest_within(some, some, *grid[:3], 1.0, *grid[3:], 1.0, 1e-9)
    line_terms(some, some, idx, some, some)
