"""True fault intervals: helpers shared by the simulator and the pipeline.

The simulator labels each sensor from physics (slam.sim.faults). Scan
matching is a special case: the simulator can say when the scan geometry
cannot constrain a pose, but not what KISS-ICP makes of it (after a blind
stretch its local map is wrong for a while, even once walls are back in
range). So where ground truth exists, the pipeline adds the times where the
front-end's output is wrong: its motion over ``window_s`` differs from the
true motion by more than ``max_trans_m`` or ``max_yaw_deg``, far beyond its
nominal error (millimetres and hundredths of a degree per scan here).
"""

from __future__ import annotations

import numpy as np

from slam.recording import Interval, Trajectory


def intervals_from_mask(t: np.ndarray, mask: np.ndarray, merge_gap_s: float, min_duration_s: float) -> list[Interval]:
    """Runs of True in ``mask`` over times ``t`` (s) as merged intervals."""
    if not np.any(mask):
        return []
    m = np.concatenate([[False], mask.astype(bool), [False]])
    starts = np.flatnonzero(~m[:-1] & m[1:])
    ends = np.flatnonzero(m[:-1] & ~m[1:]) - 1
    merged: list[list[float]] = []
    for a, b in zip(t[starts], t[ends]):
        if merged and a - merged[-1][1] <= merge_gap_s:
            merged[-1][1] = float(b)
        else:
            merged.append([float(a), float(b)])
    return [(round(a, 6), round(b, 6)) for a, b in merged if b - a >= min_duration_s]


def union_intervals(*lists: list[Interval]) -> list[Interval]:
    """Union of interval lists, sorted and merged where they overlap."""
    spans = sorted(iv for lst in lists for iv in lst)
    out: list[list[float]] = []
    for a, b in spans:
        if out and a <= out[-1][1]:
            out[-1][1] = max(out[-1][1], b)
        else:
            out.append([a, b])
    return [(a, b) for a, b in out]


def scan_matching_output_faults(
    sm: Trajectory,
    groundtruth: Trajectory,
    window_s: float = 1.0,
    max_trans_m: float = 0.15,
    max_yaw_deg: float = 3.0,
    merge_gap_s: float = 1.0,
    min_duration_s: float = 0.5,
) -> list[Interval]:
    """Times (s) where the scan matcher's motion over ``window_s`` is wrong.

    A scan is marked when the relative pose from the scan ``window_s``
    earlier differs from the true one by more than the limits; the marks are
    merged into intervals (module docstring).
    """
    from slam.measurements import interpolate_poses, relative_poses

    t = sm.t
    est = np.column_stack([sm.x, sm.y, sm.yaw])
    true = interpolate_poses(groundtruth, t)
    prev = np.searchsorted(t, t - window_s)
    valid = (t - window_s >= t[0]) & (t >= groundtruth.t[0]) & (t <= groundtruth.t[-1])
    e = relative_poses(est[prev], est) - relative_poses(true[prev], true)
    e[:, 2] = np.angle(np.exp(1j * e[:, 2]))
    wrong = valid & ((np.hypot(e[:, 0], e[:, 1]) > max_trans_m) | (np.abs(e[:, 2]) > np.radians(max_yaw_deg)))
    # A wrong window implicates every scan in it, from its start.
    marked = wrong.copy()
    for i in np.flatnonzero(wrong):
        marked[prev[i] : i] = True
    return intervals_from_mask(t, marked, merge_gap_s, min_duration_s)
