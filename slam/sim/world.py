"""The planar world: wall segments, labelled regions and 2D ray casting.

Walls and obstacle outlines become one array of segments ``(S, 2, 2)`` in
the ENU world frame, metres. Doors cut gaps into the walls they lie on.
Ray casting is vectorised over all beams x all segments near the sensor,
which keeps a 10 Hz laser over a two-hour run within minutes. It and the
distance and region look-ups work in blocks of at most :data:`_BLOCK`
tests, so that their memory does not grow with the world (a block's rows
are computed exactly as the whole array's would be).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from slam.sim.scenario import Door, Region, RegionKind, WorldConfig

log = logging.getLogger(__name__)

_EPS = 1e-12
_BLOCK = 1 << 20
"""Most elementary tests (beam x segment, point x segment, point x corner) of one numpy block."""


def _rows(n: int, width: int) -> range:
    """Starts of the blocks of rows of an (n, width) array of tests."""
    return range(0, n, max(1, _BLOCK // max(width, 1)))


def _cut_doors(segments: list[np.ndarray], doors: list[Door]) -> list[np.ndarray]:
    """Remove the interval ``center +- width/2`` from every segment passing
    within 1 cm of a door's centre."""
    for door in doors:
        c = np.asarray(door.center, dtype=float)
        out: list[np.ndarray] = []
        for seg in segments:
            a, b = seg
            d = b - a
            length = float(np.hypot(*d))
            u = d / length
            s = float(np.dot(c - a, u))
            off = abs(float(u[0] * (c - a)[1] - u[1] * (c - a)[0]))
            if off > 0.01 or s < -door.width_m / 2 or s > length + door.width_m / 2:
                out.append(seg)
                continue
            lo, hi = s - door.width_m / 2, s + door.width_m / 2
            if lo > 1e-6:
                out.append(np.array([a, a + u * lo]))
            if hi < length - 1e-6:
                out.append(np.array([a + u * hi, b]))
        segments = out
    return segments


def point_in_polygon(xy: np.ndarray, polygon: np.ndarray) -> np.ndarray:
    """Even-odd rule for points ``xy`` (n, 2) in ``polygon`` (k, 2): (n,) bool."""
    blocks = _rows(len(xy), len(polygon))
    if len(blocks) > 1:
        return np.concatenate([point_in_polygon(xy[i : i + blocks.step], polygon) for i in blocks])
    x, y = xy[:, 0:1], xy[:, 1:2]
    px, py = polygon[:, 0], polygon[:, 1]
    qx, qy = np.roll(px, -1), np.roll(py, -1)
    crosses = (py > y) != (qy > y)
    with np.errstate(divide="ignore", invalid="ignore"):
        x_at = px + (y - py) * (qx - px) / (qy - py)
    return (np.sum(crosses & (x < x_at), axis=1) % 2) == 1


def distance_to_segments(xy: np.ndarray, segments: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Distance (n,) m of each point to the nearest segment, and the unit
    vector (n, 2) from that nearest point towards the query point."""
    if len(segments) == 0:
        return np.full(len(xy), np.inf), np.zeros((len(xy), 2))
    blocks = _rows(len(xy), len(segments))
    if len(blocks) > 1:
        parts = [distance_to_segments(xy[i : i + blocks.step], segments) for i in blocks]
        return np.concatenate([p[0] for p in parts]), np.concatenate([p[1] for p in parts])
    a, b = segments[:, 0], segments[:, 1]
    d = b - a
    dd = np.maximum(np.sum(d * d, axis=1), _EPS)
    rel = xy[:, None, :] - a[None]
    s = np.clip(np.sum(rel * d[None], axis=2) / dd[None], 0.0, 1.0)
    near = a[None] + s[..., None] * d[None]
    diff = xy[:, None, :] - near
    dist = np.hypot(diff[..., 0], diff[..., 1])
    k = np.argmin(dist, axis=1)
    rows = np.arange(len(xy))
    best = dist[rows, k]
    away = diff[rows, k] / np.maximum(best, _EPS)[:, None]
    return best, away


def wall_segments(cfg: WorldConfig) -> np.ndarray:
    """The walls' and obstacles' segments (S, 2, 2) m, doors not cut, none of zero length."""
    segs: list[np.ndarray] = []
    for line in cfg.walls:
        p = np.asarray(line, dtype=float)
        segs += [p[i : i + 2] for i in range(len(p) - 1)]
    for poly in cfg.obstacles:
        p = np.asarray(poly, dtype=float)
        p = np.vstack([p, p[:1]])
        segs += [p[i : i + 2] for i in range(len(p) - 1)]
    return np.asarray([s for s in segs if np.hypot(*(s[1] - s[0])) > 1e-9], dtype=float).reshape(-1, 2, 2)


@dataclass
class World:
    """Segments ``(S, 2, 2)`` m, their unit normals ``(S, 2)``, the regions
    and the region used outside all of them."""

    segments: np.ndarray
    normals: np.ndarray
    regions: list[Region]
    default_region: Region

    @classmethod
    def from_config(cls, cfg: WorldConfig) -> "World":
        segs = _cut_doors(list(wall_segments(cfg)), cfg.doors)
        segments = np.asarray(segs, dtype=float).reshape(-1, 2, 2)
        d = segments[:, 1] - segments[:, 0]
        normals = np.column_stack([-d[:, 1], d[:, 0]])
        normals /= np.maximum(np.hypot(normals[:, 0], normals[:, 1]), _EPS)[:, None]
        log.debug("world: %d segments, %d regions", len(segments), len(cfg.regions))
        return cls(segments, normals, list(cfg.regions), cfg.default_region)

    def region_index(self, xy: np.ndarray) -> np.ndarray:
        """Index into ``regions`` of each point (n,), -1 for the default region
        (the first listed region wins where regions overlap)."""
        idx = np.full(len(xy), -1)
        for i in reversed(range(len(self.regions))):
            inside = point_in_polygon(xy, np.asarray(self.regions[i].polygon, dtype=float))
            idx[inside] = i
        return idx

    def slip(self, xy: np.ndarray) -> np.ndarray:
        """Terrain slip fraction at each point (n,)."""
        table = np.array([r.slip for r in self.regions] + [self.default_region.slip])
        return table[self.region_index(xy)]

    def track_slip(self, xy: np.ndarray, turn_rate: np.ndarray, turn_slip_per_rad_s: float) -> np.ndarray:
        """Track slip fraction (n,): the terrain's slip plus a part growing
        with |turn rate| rad/s (skid-steer tracks scrub sideways in turns)."""
        return self.slip(xy) + turn_slip_per_rad_s * np.abs(turn_rate)

    def indoor(self, xy: np.ndarray) -> np.ndarray:
        """Whether each point (n,) lies in an indoor region."""
        kinds = [r.kind is RegionKind.INDOOR for r in self.regions + [self.default_region]]
        table = np.array(kinds)
        return table[self.region_index(xy)]

    def distance_to_indoor(self, xy: np.ndarray) -> np.ndarray:
        """Distance (n,) m to the nearest indoor region (0 inside one)."""
        edges = []
        for r in self.regions:
            if r.kind is RegionKind.INDOOR:
                p = np.asarray(r.polygon, dtype=float)
                edges.append(np.stack([p, np.roll(p, -1, axis=0)], axis=1))
        if not edges:
            return np.full(len(xy), np.inf)
        dist, _ = distance_to_segments(xy, np.concatenate(edges))
        return np.where(self.indoor(xy), 0.0, dist)

    def cast(
        self, origin: np.ndarray, angles: np.ndarray, max_range: float
    ) -> tuple[np.ndarray, np.ndarray]:
        """Cast rays from ``origin`` (2,) along world ``angles`` (B,) rad.

        Returns the exact range (B,) m to the first segment hit (``inf`` when
        nothing is hit within ``max_range``) and the index (B,) of the hit
        segment (-1 for none).
        """
        segs = self._near(origin, max_range)
        rng = np.full(len(angles), np.inf)
        hit = np.full(len(angles), -1)
        if len(segs) == 0:
            return rng, hit
        a = self.segments[segs, 0] - origin  # (S, 2) relative to the sensor
        e = self.segments[segs, 1] - self.segments[segs, 0]
        blocks = _rows(len(angles), len(segs))
        for i in blocks:
            rng[i : i + blocks.step], hit[i : i + blocks.step] = _first_hits(a, e, segs, angles[i : i + blocks.step],
                                                                             max_range)
        return rng, hit

    def _near(self, origin: np.ndarray, radius: float) -> np.ndarray:
        """Indices of segments that come within ``radius`` of ``origin``."""
        if len(self.segments) == 0:
            return np.zeros(0, dtype=int)
        return np.flatnonzero(_segment_distances(origin, self.segments) <= radius)


def _first_hits(a: np.ndarray, e: np.ndarray, segs: np.ndarray, angles: np.ndarray,
                max_range: float) -> tuple[np.ndarray, np.ndarray]:
    """Range (B,) m and segment index (B,) of the first of the segments
    ``segs`` (starts ``a`` relative to the sensor, directions ``e``, (S, 2))
    hit along each of ``angles`` (B,) rad; inf and -1 for none."""
    rng = np.full(len(angles), np.inf)
    hit = np.full(len(angles), -1)
    dx, dy = np.cos(angles)[:, None], np.sin(angles)[:, None]  # (B, 1)
    # Solve origin + t*d = a + u*e for t >= 0, u in [0, 1] (Cramer's rule).
    den = dx * e[None, :, 1] - dy * e[None, :, 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (a[None, :, 0] * e[None, :, 1] - a[None, :, 1] * e[None, :, 0]) / den
        u = (a[None, :, 0] * dy - a[None, :, 1] * dx) / den
    valid = (np.abs(den) > _EPS) & (t > 0.0) & (u >= 0.0) & (u <= 1.0)
    t = np.where(valid, t, np.inf)
    k = np.argmin(t, axis=1)
    best = t[np.arange(len(angles)), k]
    ok = best <= max_range
    rng[ok] = best[ok]
    hit[ok] = segs[k[ok]]
    return rng, hit


def segments_near_count(segments: np.ndarray, points: np.ndarray, radius: float) -> float:
    """How many of ``segments`` (S, 2, 2) lie within ``radius`` m of
    ``points`` (n, 2), on average: the segments a laser of that range casts
    its beams against there."""
    if len(segments) == 0 or len(points) == 0:
        return 0.0
    return float(np.mean([np.count_nonzero(_segment_distances(p, segments) <= radius) for p in points]))


def _segment_distances(p: np.ndarray, segments: np.ndarray) -> np.ndarray:
    """Distance (S,) m of one point ``p`` (2,) to each segment."""
    a, b = segments[:, 0], segments[:, 1]
    d = b - a
    s = np.clip(np.sum((p - a) * d, axis=1) / np.maximum(np.sum(d * d, axis=1), _EPS), 0, 1)
    near = a + s[:, None] * d
    return np.hypot(*(p - near).T)


def scan_constraint(
    ranges: np.ndarray, hit: np.ndarray, beam_yaw: np.ndarray, normals: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Number of returns (n,), smallest eigenvalue (n,) of the normalised
    point-to-line information matrix of each scan and its unit eigenvector
    (n, 3) (world x, world y, turn), as :mod:`slam.sim.faults` defines them.

    ``ranges`` (n, B) noise-free m (inf without a return); ``hit`` (n, B)
    indices of the segments hit; ``beam_yaw`` (n, B) world angle of each
    beam, rad; ``normals`` (S, 2) unit wall normals, world frame. The
    eigenvalues do not depend on the frame, so everything stays in the world.
    """
    ok = np.isfinite(ranges) & (hit >= 0)
    count = ok.sum(axis=1)
    r = np.where(ok, ranges, 0.0)
    px, py = r * np.cos(beam_yaw), r * np.sin(beam_yaw)
    n = normals[np.where(ok, hit, 0)]
    scale = np.where(count > 0, r.sum(axis=1) / np.maximum(count, 1), 1.0)
    rot = (px * n[..., 1] - py * n[..., 0]) / scale[:, None]
    rows = np.stack([n[..., 0], n[..., 1], rot], axis=-1) * ok[..., None]
    info = np.einsum("nbi,nbj->nij", rows, rows) / ranges.shape[1]
    values, vectors = np.linalg.eigh(info)
    return count, values[:, 0], vectors[:, :, 0]
