"""How well one 2D scan constrains a planar pose: its returns and the
conditioning of its point-to-line information matrix.

For each return i at point p_i (laser frame, m) on a local line with unit
normal n_i, point-to-line registration has the Jacobian row
J_i = (n_x, n_y, (p_i x n_i) / L), L the scan's mean range so the three
columns are unitless; ``sum_i(J_i^T J_i) / B`` (B the number of beams, so a
scan with few returns is weak too) is its information matrix. Its smallest
eigenvalue measures how well the worst direction is held and its
eigenvector (forward, left, turn) says which direction that is (Zhang,
Kaess and Singh, "On degeneracy of optimization-based state estimation
problems", ICRA 2016). A corridor leaves the forward motion free and gives
0; a furnished room gives 0.1-0.3. The simulator labels scan-matching
faults by the same matrix with the true wall normals (:mod:`slam.sim.faults`);
here the normals are estimated from the scan itself.
"""

from __future__ import annotations

import numpy as np


def scan_geometry(ranges: np.ndarray, angles: np.ndarray, range_min: float, range_max: float,
                  neighbours: int = 2, max_spread_m: float = 0.5) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Returns (n,), smallest eigenvalue (n,) of the normalised point-to-line
    information matrix and its unit eigenvector (n, 3) (forward, left, turn)
    of scans ``ranges`` (n, B) m at beam ``angles`` (B,) rad; a return is a
    finite range in (``range_min``, ``range_max``). Each return's normal is
    that of the line through it and its neighbours within ``neighbours``
    beams and ``max_spread_m``."""
    r = np.asarray(ranges, dtype=np.float64)
    with np.errstate(invalid="ignore"):
        ok = np.isfinite(r) & (r > range_min) & (r < range_max)
    r = np.where(ok, r, 0.0)
    px, py = r * np.cos(angles), r * np.sin(angles)
    s = {k: np.zeros_like(px) for k in ("n", "x", "y", "xx", "xy", "yy")}
    for d in range(-neighbours, neighbours + 1):
        qx, qy, qok = (np.roll(a, d, axis=1) for a in (px, py, ok))
        if d > 0:
            qok[:, :d] = False
        elif d < 0:
            qok[:, d:] = False
        near = ok & qok & (np.hypot(qx - px, qy - py) <= max_spread_m)
        for key, v in (("n", 1.0), ("x", qx), ("y", qy), ("xx", qx * qx), ("xy", qx * qy), ("yy", qy * qy)):
            s[key] += np.where(near, v, 0.0)
    n = np.maximum(s["n"], 1.0)
    mx, my = s["x"] / n, s["y"] / n
    cxx, cxy, cyy = s["xx"] / n - mx * mx, s["xy"] / n - mx * my, s["yy"] / n - my * my
    line = 0.5 * np.arctan2(2.0 * cxy, cxx - cyy)  # direction of the major axis
    nx, ny = -np.sin(line), np.cos(line)
    used = ok & (s["n"] >= 3)
    count = ok.sum(axis=1)
    scale = np.where(count > 0, r.sum(axis=1) / np.maximum(count, 1), 1.0)
    rot = (px * ny - py * nx) / scale[:, None]
    rows = np.stack([nx, ny, rot], axis=-1) * used[..., None]
    info = np.einsum("nbi,nbj->nij", rows, rows) / r.shape[1]
    values, vectors = np.linalg.eigh(info)
    return count, values[:, 0], vectors[:, :, 0]


def range_ceiling(ranges: np.ndarray, range_min: float, range_max: float,
                  near: float = 0.1) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """How much scans ``ranges`` (n, B) m look cut off at a range ceiling:
    the share of beams without a return (n,), the number of returns that
    border a run of beams without one (n,), the share of those edges
    within ``near`` (a fraction) of the scan's farthest return (n,) and that
    farthest return (n,) m, the ceiling.

    A laser that sees nothing beyond some distance R (a cut, or an open yard
    beyond its reach) loses every surface past R: its scan ends in gaps whose
    edges all lie just short of R, the farthest return it has. Indoors a gap
    (an open door, glass, a far hall) is bordered by returns at any range,
    rarely all near the scan's farthest one."""
    r = np.asarray(ranges, dtype=np.float64)
    with np.errstate(invalid="ignore"):
        ok = np.isfinite(r) & (r > range_min) & (r < range_max)
    r = np.where(ok, r, 0.0)
    farthest = r.max(axis=1, initial=0.0)
    no_return = ~ok
    before = np.pad(no_return[:, :-1], ((0, 0), (1, 0)))
    after = np.pad(no_return[:, 1:], ((0, 0), (0, 1)))
    edge = ok & (before | after)
    edges = edge.sum(axis=1)
    at_ceiling = (edge & (r >= (1.0 - near) * farthest[:, None])).sum(axis=1)
    share = np.where(edges > 0, at_ceiling / np.maximum(edges, 1), 0.0)
    return no_return.mean(axis=1), edges, share, farthest
