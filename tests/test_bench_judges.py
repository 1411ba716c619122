"""The Husky benches' judges of the recording's own faults
(``scripts/bench/judges.py``): they must find a fault the witnesses agree
on, and nothing where the sensors agree."""

from __future__ import annotations

import numpy as np

from scripts.bench.judges import gps_wanders
from slam.recording import Gps, Gyro, Recording, Trajectory


def _straight_run(wander_m: float) -> Recording:
    """120 s east at 1 m/s: gyro still, wheels true, fixes with 0.3 m of
    noise and, over 60-66 s, a sideways wander of up to ``wander_m``."""
    rng = np.random.default_rng(7)
    tg = np.arange(0.0, 120.0, 1 / 30)
    to = np.arange(0.0, 120.0, 0.1)
    tf = np.arange(0.0, 120.0, 0.4)
    side = wander_m * np.clip(1 - np.abs(tf - 63.0) / 3.0, 0.0, None)
    return Recording(
        name="straight",
        gyro=Gyro(t=tg, rate=np.zeros(len(tg))),
        odometry=Trajectory(t=to, x=to.copy(), y=np.zeros(len(to)), yaw=np.zeros(len(to))),
        gps=Gps(t=tf, x=tf + rng.normal(0, 0.3, len(tf)), y=side + rng.normal(0, 0.3, len(tf)),
                sigma=np.full(len(tf), 0.9), status=np.zeros(len(tf), dtype=int)),
    )


def test_gps_wander_is_found_where_the_fixes_leave_the_dead_reckoning():
    wanders = gps_wanders(_straight_run(4.0))
    assert wanders, "a 4 m sideways wander was not found"
    assert all(a < 66.0 and b > 60.0 for a, b in wanders), wanders  # nothing outside it
    assert min(a for a, _ in wanders) > 55.0 and max(b for _, b in wanders) < 71.0


def test_no_wander_where_the_fixes_follow_the_wheels_and_gyro():
    # Noise alone flags the tail of its own distribution (3 robust sds above
    # the median): a few short spans at most, never a long one.
    wanders = gps_wanders(_straight_run(0.0))
    assert sum(b - a for a, b in wanders) < 0.05 * 120.0
