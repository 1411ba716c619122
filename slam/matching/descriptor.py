"""A place descriptor of 2D local maps, after Scan Context (Kim and Kim,
IROS 2018), for a planar laser.

The points of a local map, in the frame of its keyframe, are binned into
``rings`` x ``sectors`` polar cells up to ``max_radius_m``; a cell is 1 when
it holds a point (a planar scanner has no height to store, and occupancy
does not depend on how many scans the local map holds). The *ring key*, the
occupied fraction of each ring, does not change when the robot turns in
place: it is the key for a fast nearest-neighbour search. Two descriptors
are compared over every circular shift of the sectors (the robot may come
back facing another way): the distance is 1 - the mean cosine similarity of
the sector columns that hold anything, at the best shift, and that shift
gives the relative yaw.
"""

from __future__ import annotations

import numpy as np


def scan_context(points: np.ndarray, rings: int, sectors: int, max_radius_m: float) -> np.ndarray:
    """Occupancy (rings, sectors) of planar points (n, 2) around the origin;
    sector 0 starts at yaw -pi, counter-clockwise."""
    out = np.zeros((rings, sectors))
    if len(points) == 0:
        return out
    r = np.hypot(points[:, 0], points[:, 1])
    keep = r < max_radius_m
    ring = (r[keep] / max_radius_m * rings).astype(np.int64)
    angle = np.arctan2(points[keep, 1], points[keep, 0])
    sector = np.minimum(((angle + np.pi) / (2 * np.pi) * sectors).astype(np.int64), sectors - 1)
    out[ring, sector] = 1.0
    return out


def ring_key(context: np.ndarray) -> np.ndarray:
    """Occupied fraction per ring (rings,): invariant to the robot's yaw."""
    return context.mean(axis=-1)


def context_distance(a: np.ndarray, b: np.ndarray) -> tuple[float, float]:
    """Scan Context distance of ``b`` to ``a`` in [0, 1] and the yaw (rad)
    of ``b``'s frame in ``a``'s at the best sector shift."""
    rings, sectors = a.shape
    # All circular shifts of b's columns at once: (sectors shifts, rings, sectors).
    idx = (np.arange(sectors)[None, :] - np.arange(sectors)[:, None]) % sectors
    shifted = b[:, idx].transpose(1, 0, 2)
    dot = np.einsum("rs,krs->ks", a, shifted)
    na = np.linalg.norm(a, axis=0)
    nb = np.linalg.norm(shifted, axis=1)
    both = (na[None, :] > 0) & (nb > 0)
    cos = np.where(both, dot / np.where(both, na[None, :] * nb, 1.0), 0.0)
    used = np.maximum(both.sum(axis=1), 1)
    similarity = cos.sum(axis=1) / used
    best = int(np.argmax(similarity))
    # b's column s - best matches a's column s: what a sees at angle phi, b
    # sees at phi - best sectors, so b's frame is turned by +best sectors.
    yaw = best * 2.0 * np.pi / sectors
    yaw = (yaw + np.pi) % (2.0 * np.pi) - np.pi
    return float(1.0 - similarity[best]), float(yaw)
