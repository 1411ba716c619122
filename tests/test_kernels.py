"""The compiled kernels (slam.matching.kernels) against the numpy versions
they replace, which are kept here as the obviously-correct references: the
same numbers to the last bit, so that maps stay byte-identical."""

from __future__ import annotations

import numpy as np
import pytest

from slam.matching.grid import LEVELS, likelihood_field, max_pool_stack, score_pyramid
from slam.matching.points import point_map
from slam.matching.search import CorrelativeSearch


# -- the numpy references ------------------------------------------------------------------


def reference_field(hits: np.ndarray, resolution_m: float, sigma_m: float) -> np.ndarray:
    """Two passes of shifted maxima over the box of rows and columns within reach of a hit."""
    field = np.zeros(hits.shape, dtype=np.float32)
    if not hits.any():
        return field
    reach = int(np.ceil(3.0 * sigma_m / resolution_m))
    g = np.exp(-0.5 * (np.arange(-reach, reach + 1) * resolution_m / sigma_m) ** 2).astype(np.float32)
    rows = np.nonzero(hits.any(axis=1))[0]
    cols = np.nonzero(hits.any(axis=0))[0]
    x0, x1 = max(rows[0] - reach, 0), min(rows[-1] + reach + 1, hits.shape[0])
    y0, y1 = max(cols[0] - reach, 0), min(cols[-1] + reach + 1, hits.shape[1])
    h = hits[x0:x1, y0:y1].astype(np.float32)
    for axis in (1, 0):  # out[x, y] = max_k g[k] * in[x, y + k - reach], then along x
        src, out = h, np.zeros_like(h)
        n = src.shape[axis]
        for k, w in enumerate(g):
            shift = k - reach
            lo, hi = max(0, -shift), min(n, n - shift)
            if lo >= hi:
                continue
            dst = [slice(None), slice(None)]
            from_ = [slice(None), slice(None)]
            dst[axis], from_[axis] = slice(lo, hi), slice(lo + shift, hi + shift)
            np.maximum(out[tuple(dst)], w * src[tuple(from_)], out=out[tuple(dst)])
        h = out
    field[x0:x1, y0:y1] = h
    return field


def reference_levels(field: np.ndarray, depth: int) -> list[np.ndarray]:
    levels = [field]
    for h in range(1, depth + 1):
        prev, half = levels[-1], 1 << (h - 1)
        cur = prev.copy()
        np.maximum(cur[:-half], prev[half:], out=cur[:-half])
        nxt = cur.copy()
        np.maximum(nxt[:, :-half], cur[:, half:], out=nxt[:, :-half])
        levels.append(nxt)
    return levels


def reference_base(search: CorrelativeSearch, points: np.ndarray, guess: np.ndarray) -> np.ndarray:
    pyr, w, hi = search.pyr, search.w, search.hi
    c, s = np.cos(search.yaws), np.sin(search.yaws)
    x = c[:, None] * points[None, :, 0] - s[:, None] * points[None, :, 1] + guess[0]
    y = s[:, None] * points[None, :, 0] + c[:, None] * points[None, :, 1] + guess[1]
    nx, ny = pyr.field.shape
    cells = pyr.cells(np.stack([x, y], axis=-1)) - w
    ix = np.clip(cells[..., 0], 0, nx - 1 - hi)
    iy = np.clip(cells[..., 1], 0, ny - 1 - hi)
    return (ix.astype(np.int64) * ny + iy).astype(np.int32)


class ReferenceSearch:
    """The level-by-level numpy search over a compiled search's space."""

    def __init__(self, search: CorrelativeSearch):
        self.s, self.evaluated = search, 0

    def scores(self, level, a, ox, oy):
        self.evaluated += len(a)
        pyr, base = self.s.pyr, self.s.base
        ny = pyr.levels[level].shape[1]
        flat = base[a] + (ox * ny + oy).astype(np.int32)[:, None]
        return pyr.lookup_flat(level, flat).mean(axis=1) * (1.0 / LEVELS)

    def children(self, level, a, ox, oy):
        half = 1 << (level - 1)
        ca = np.repeat(a, 4)
        cx = np.repeat(ox, 4) + np.tile([0, half, 0, half], len(a))
        cy = np.repeat(oy, 4) + np.tile([0, 0, half, half], len(a))
        keep = (cx <= self.s.hi) & (cy <= self.s.hi)
        return ca[keep], cx[keep], cy[keep]

    def top(self):
        stride = 1 << self.s.depth
        offs = np.arange(0, self.s.hi + 1, stride)
        n = len(self.s.yaws)
        a = np.repeat(np.arange(n), len(offs) ** 2)
        ox = np.tile(np.repeat(offs, len(offs)), n)
        oy = np.tile(offs, n * len(offs))
        return a, ox, oy, self.scores(self.s.depth, a, ox, oy)

    def dive(self, a, ox, oy, sc):
        k = int(np.argmax(sc))
        a, ox, oy, best = a[k : k + 1], ox[k : k + 1], oy[k : k + 1], float(sc[k])
        for level in range(self.s.depth, 0, -1):
            a, ox, oy = self.children(level, a, ox, oy)
            child = self.scores(level - 1, a, ox, oy)
            k = int(np.argmax(child))
            a, ox, oy, best = a[k : k + 1], ox[k : k + 1], oy[k : k + 1], float(child[k])
        return best

    def sweep(self, blocks, bound, outside=None):
        a, ox, oy, sc = blocks
        keep = sc >= bound
        a, ox, oy, sc = a[keep], ox[keep], oy[keep], sc[keep]
        for level in range(self.s.depth, 0, -1):
            if outside is not None:
                keep = outside(level, a, ox, oy)
                a, ox, oy = a[keep], ox[keep], oy[keep]
            a, ox, oy = self.children(level, a, ox, oy)
            sc = self.scores(level - 1, a, ox, oy)
            keep = sc >= bound
            a, ox, oy, sc = a[keep], ox[keep], oy[keep], sc[keep]
        if outside is not None:
            keep = outside(0, a, ox, oy)
            a, ox, oy, sc = a[keep], ox[keep], oy[keep], sc[keep]
        return a, ox, oy, sc

    def outside(self, near_yaw, bx, by, r):
        def keep(level, a, ox, oy):
            size = (1 << level) - 1
            return ~(near_yaw[a] & (ox >= bx - r) & (ox + size <= bx + r) & (oy >= by - r) & (oy + size <= by + r))
        return keep


# -- the comparisons ----------------------------------------------------------------------


def room(rng, n_walls: int = 6) -> np.ndarray:
    """Points along random walls, 2 cm apart, within 6 m."""
    parts = []
    for _ in range(n_walls):
        a, b = rng.uniform(-6, 6, 2), rng.uniform(-6, 6, 2)
        t = np.linspace(0.0, 1.0, max(int(np.hypot(*(b - a)) / 0.02), 2))[:, None]
        parts.append(a + t * (b - a))
    return np.concatenate(parts)


@pytest.mark.parametrize("seed", range(6))
def test_the_field_and_its_pyramid_are_the_references_to_the_bit(seed):
    rng = np.random.default_rng(seed)
    shape = tuple(rng.integers(5, 120, 2))
    hits = rng.random(shape) < rng.choice([0.0, 0.002, 0.02, 0.3])
    res = rng.choice([0.05, 0.1])
    sigma = res * rng.choice([1.0, 1.5, 2.0])
    field = likelihood_field(hits, res, sigma)
    assert field.dtype == np.float32
    np.testing.assert_array_equal(field, reference_field(hits, res, sigma))
    quantised = np.rint(field * LEVELS).astype(np.uint8)
    depth = int(rng.integers(0, 7))
    stack = max_pool_stack(quantised, depth)
    assert stack.shape == (depth + 1,) + quantised.shape
    for got, want in zip(stack, reference_levels(quantised, depth), strict=True):
        np.testing.assert_array_equal(got, want)


@pytest.mark.parametrize("seed", range(8))
def test_the_search_scores_the_same_blocks_as_the_reference(seed):
    rng = np.random.default_rng(seed)
    pts = room(rng)
    res = rng.choice([0.05, 0.1])
    window = float(rng.uniform(0.05, 1.0))
    w = int(np.ceil(window / res))
    pyr = score_pyramid(pts, res, res, 7, 3 * res, 2 * w + 4)
    true = np.array([rng.uniform(-1, 1), rng.uniform(-1, 1), rng.uniform(-0.5, 0.5)])
    c, s = np.cos(true[2]), np.sin(true[2])
    scan = (pts[rng.choice(len(pts), 150, replace=False)] - true[:2]) @ np.array([[c, -s], [s, c]])
    scan += rng.normal(0.0, 0.02, scan.shape)
    guess = true + rng.normal(0.0, [0.3 * window, 0.3 * window, 0.05])
    search = CorrelativeSearch(pyr, scan, guess, window, float(rng.uniform(0.0, 0.4)))
    np.testing.assert_array_equal(search.base, reference_base(search, scan, guess))
    ref = ReferenceSearch(search)

    blocks, ref_blocks = search.top(), ref.top()
    for got, want in zip(blocks, ref_blocks, strict=True):
        np.testing.assert_array_equal(got, want)
    best = search.dive(*blocks)
    assert best == ref.dive(*ref_blocks)
    bound = best - 0.05
    for got, want in zip(search.sweep(blocks, bound), ref.sweep(ref_blocks, bound), strict=True):
        np.testing.assert_array_equal(got, want)
    # Excluding a box around the best pose, as the rivals are looked for.
    a, ox, oy, _ = search.sweep(blocks, best)
    ref.sweep(ref_blocks, best)
    near_yaw = np.abs(search.yaws - search.yaws[a[0]]) <= 0.05
    box = (near_yaw, int(ox[0]), int(oy[0]), int(rng.integers(0, 6)))
    for got, want in zip(search.sweep(blocks, 0.5 * best, box), ref.sweep(ref_blocks, 0.5 * best, ref.outside(*box)),
                         strict=True):
        np.testing.assert_array_equal(got, want)
    assert search.evaluated == ref.evaluated


@pytest.mark.parametrize("seed", range(6))
def test_the_pyramid_pooled_over_its_crop_is_the_whole_grid_pooled(seed):
    rng = np.random.default_rng(seed)
    pts = room(rng, int(rng.integers(1, 4)))
    res, depth, pad = float(rng.choice([0.05, 0.1])), int(rng.integers(0, 7)), int(rng.integers(0, 30))
    pyr = score_pyramid(pts, res, res, depth, 3 * res, pad)
    hits = np.zeros(pyr.field.shape, dtype=bool)
    cells = pyr.cells(pts)
    hits[cells[:, 0], cells[:, 1]] = True
    field = reference_field(hits, res, res)
    p = pyr.pad
    field[:p], field[:, :p], field[-p - 1 :], field[:, -p - 1 :] = 0.0, 0.0, 0.0, 0.0
    for got, want in zip(pyr.stack, reference_levels(np.rint(field * LEVELS).astype(np.uint8), depth), strict=True):
        np.testing.assert_array_equal(got, want)


@pytest.mark.parametrize("seed", range(6))
def test_the_nearest_points_are_the_k_d_trees(seed):
    rng = np.random.default_rng(seed)
    pts = room(rng)[:: int(rng.integers(1, 4))]
    pmap = point_map(pts, np.zeros_like(pts))
    for within in (0.3, 0.15, 0.1, 0.3, 5.0):
        queries = pts[rng.choice(len(pts), 300)] + rng.normal(0.0, within, (300, 2))
        dist, want = pmap.tree.query(queries, distance_upper_bound=within)
        np.testing.assert_array_equal(pmap.nearest(queries, within), np.where(np.isfinite(dist), want, -1))


def test_the_nearest_point_of_a_tie_or_at_the_reach_is_the_k_d_trees():
    # Points on a lattice: queries halfway between two, or at the reach of one.
    pts = np.array([[x, y] for x in np.arange(0.0, 1.0, 0.25) for y in np.arange(0.0, 1.0, 0.25)])
    pmap = point_map(np.concatenate([pts, pts[:3]]), np.zeros((len(pts) + 3, 2)))
    queries = np.concatenate([pts + [0.125, 0.0], pts + [0.0, 0.125], pts + [0.125, 0.125], pts[:3],
                              pts + [0.1, 0.0], [[5.0, 5.0]]])
    for within in (0.1, 0.125, 0.2):
        dist, want = pmap.tree.query(queries, distance_upper_bound=within)
        np.testing.assert_array_equal(pmap.nearest(queries, within), np.where(np.isfinite(dist), want, -1))


def reference_linearise(q, pmap, pose, gate_m):
    """slam.matching.icp's point-to-line terms as numpy."""
    from validation.base.geometry import rotation

    rq = q @ rotation(pose[2]).T
    qw = rq + pose[:2]
    idx = pmap.nearest(qw, gate_m)
    ok = idx >= 0
    idx = idx[ok]
    n = pmap.normals[idx]
    res = np.einsum("ij,ij->i", n, qw[ok] - pmap.points[idx])
    r = rq[ok]
    jac = np.column_stack([n[:, 0], n[:, 1], n[:, 1] * r[:, 0] - n[:, 0] * r[:, 1]])
    return ok, res, jac


@pytest.mark.parametrize("seed", range(6))
def test_the_point_to_line_terms_are_the_references_to_the_bit(seed):
    from slam.matching.icp import _linearise

    rng = np.random.default_rng(200 + seed)
    pts = room(rng)
    normals = rng.normal(size=pts.shape)
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    pmap = point_map(pts, normals)
    q = pts[rng.choice(len(pts), 300, replace=False)] + rng.normal(0.0, 0.1, (300, 2))
    pose = np.array([rng.normal(0, 0.2), rng.normal(0, 0.2), rng.normal(0, 0.1)])
    for gate in (0.05, 0.3, 1.0):
        for got, want in zip(_linearise(q, pmap, pose, gate), reference_linearise(q, pmap, pose, gate), strict=True):
            assert got.dtype == want.dtype and got.shape == want.shape
            np.testing.assert_array_equal(got, want)
