"""Loops listed by the recording (libRSF ``loop t t_other weight``).

Each line says the robot is back at a place, nothing about its heading: the
loop is a position equality between the keyframes nearest the two stamps,
with ``sigma_m / sqrt(weight)`` per axis (a weaker match pulls less) and no
information on the relative yaw. Lines below ``min_weight``, lines whose
stamps fall in the same or adjacent keyframes, and stamps further than
``max_gap_s`` from any keyframe are dropped. False matches are kept: the
loop observer is there to reject them.
"""

from __future__ import annotations

import numpy as np

from slam.config.loops import FileLoopsConfig
from validation.loops.constraint import LoopConstraint
from slam.recording import PlaceMatches


def _nearest(keyframe_t: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    idx = np.clip(np.searchsorted(keyframe_t, t), 1, len(keyframe_t) - 1)
    prev_closer = np.abs(keyframe_t[idx - 1] - t) <= np.abs(keyframe_t[idx] - t)
    idx = np.where(prev_closer, idx - 1, idx)
    return idx, np.abs(keyframe_t[idx] - t)


def file_loops(matches: PlaceMatches, keyframe_t: np.ndarray, config: FileLoopsConfig, max_gap_s: float) -> list[LoopConstraint]:
    """Loop constraints of the listed matches, in the order of the lines."""
    if len(keyframe_t) < 2:
        return []
    a, gap_a = _nearest(keyframe_t, matches.t)
    b, gap_b = _nearest(keyframe_t, matches.t_other)
    i, j = np.minimum(a, b), np.maximum(a, b)
    keep = (matches.weight >= config.min_weight) & (j - i > 1) & (gap_a <= max_gap_s) & (gap_b <= max_gap_s)
    keep &= matches.weight > 0
    loops = []
    for k in np.flatnonzero(keep):
        precision = matches.weight[k] / config.sigma_m**2
        info = np.diag([precision, precision, 0.0])
        quality = {"weight": round(float(matches.weight[k]), 4)}
        loops.append(LoopConstraint(len(loops), int(i[k]), int(j[k]), np.zeros(3), info, "file", quality))
    return loops
