"""Time offsets between streams, learnt from their yaw rates.

A stream stamped early or late against the others turns before or after
them, so every turn onset is a mismatch of the relations that compare
them. For each yaw stream (odometry, compass, scan matching) and the
reference stream (the gyro unless the user names another), the offset o
that makes the stream's rate, read at ``t - o``, closest to the
reference's at ``t``:

1. Both yaws (unwrapped) give rates over ``RATE_WINDOW_S`` at the
   learning steps; a candidate offset moves where the stream is read.
2. Offsets on a grid of the coarser stream's sample period over
   +-``MAX_LAG_S``; each scored by the RMS of the rates' difference about
   its mean (a gyro bias or an AHRS drift moves the mean, not the fit).
3. The grid's best offset refined by a parabola through it and its two
   neighbours.
4. The same on each half of the learning steps: an offset is proposed
   (:attr:`LagEstimate.proposed`) only when the RMS falls by more than
   ``MIN_GAIN`` of its value at the configured offset and the halves
   agree within one grid step.

The offset found is added to the stream's ``input.time_offsets_s`` (stamp +
offset = the time the sample was taken).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from slam.calibrate.runs import CalibrationRun
from slam.errors import GslamError
from validation.streams import Stream

RATE_WINDOW_S = 0.5
MAX_LAG_S = 0.5
MIN_GAIN = 0.10
"""An offset is proposed only when it lowers the RMS of the rate difference by more than this share."""
MIN_CORRELATION = 0.5
"""Below this correlation of the two rates the run has too little turning to date one stream by the other."""

YAW_STREAMS: dict[str, str] = {"gyro": "gyro_yaw", "odometry": "odo_yaw", "compass": "compass_yaw", "scan": "sm_yaw"}
"""The input stream (``input.time_offsets_s`` key) of each yaw validation stream."""


@dataclass
class LagEstimate:
    """One stream's offset against the reference: ``offset_s`` to add to its
    stamps (on top of the configured one), the RMS of the rate difference
    (rad/s) at the configured offset and at the new one, the correlation of
    the two rates there, and the offset found on each half of the steps."""

    stream: str
    reference: str
    offset_s: float
    rms_before: float
    rms_after: float
    correlation: float
    halves_s: tuple[float, float]
    grid_s: float
    steps: int

    @property
    def gain(self) -> float:
        """Share by which the offset lowers the RMS."""
        return 1.0 - self.rms_after / self.rms_before if self.rms_before > 0 else 0.0

    @property
    def consistent(self) -> bool:
        return abs(self.halves_s[0] - self.halves_s[1]) <= self.grid_s

    @property
    def moving(self) -> bool:
        return self.correlation >= MIN_CORRELATION

    @property
    def proposed(self) -> bool:
        return self.moving and self.consistent and self.gain > MIN_GAIN

    def why_not(self) -> str:
        """Why no offset is proposed ('' when one is)."""
        if not self.moving:
            return f"the rates correlate by {self.correlation:.2f} only (< {MIN_CORRELATION:g}): too little turning"
        if not self.consistent:
            return (f"the halves disagree ({self.halves_s[0]:+.3f} s and {self.halves_s[1]:+.3f} s, "
                    f"more than one step of {self.grid_s:.3g} s)")
        if self.gain <= MIN_GAIN:
            return f"the RMS changes by {-100 * self.gain:+.0f} % (a fall of more than {100 * MIN_GAIN:.0f} % is needed)"
        return ""


def _unwrapped(stream: Stream) -> Stream:
    return Stream(stream.t, np.unwrap(stream.values) if stream.angular else stream.values, False)


def _rate(stream: Stream, t: np.ndarray) -> np.ndarray:
    half = 0.5 * RATE_WINDOW_S
    return (np.interp(t + half, stream.t, stream.values) - np.interp(t - half, stream.t, stream.values)) / RATE_WINDOW_S


def _rms(a: np.ndarray, b: np.ndarray) -> float:
    d = a - b
    return float(np.sqrt(np.mean((d - d.mean()) ** 2)))


def _best(stream: Stream, ref_rate: np.ndarray, t: np.ndarray, grid: np.ndarray) -> tuple[float, np.ndarray]:
    """Steps 2-3: the refined offset and the RMS at each grid offset."""
    rms = np.array([_rms(_rate(stream, t - o), ref_rate) for o in grid])
    k = int(np.argmin(rms))
    if 0 < k < len(grid) - 1:
        y0, y1, y2 = rms[k - 1] ** 2, rms[k] ** 2, rms[k + 1] ** 2
        curve = y0 - 2.0 * y1 + y2
        step = grid[1] - grid[0]
        shift = 0.5 * (y0 - y2) / curve if curve > 0 else 0.0
        return float(grid[k] + np.clip(shift, -0.5, 0.5) * step), rms
    return float(grid[k]), rms


def _period(stream: Stream) -> float:
    return float(np.median(np.diff(stream.t))) if len(stream.t) > 1 else np.inf


def estimate_lag(stream: Stream, reference: Stream, t: np.ndarray, name: str = "", ref_name: str = "") -> LagEstimate | None:
    """The offset of ``stream`` against ``reference`` (module docstring) over
    the times ``t`` (s); None when fewer than 20 times lie where both
    streams cover every candidate."""
    stream, reference = _unwrapped(stream), _unwrapped(reference)
    grid_s = max(_period(stream), _period(reference))
    if not np.isfinite(grid_s) or grid_s <= 0:
        return None
    n = int(np.floor(MAX_LAG_S / grid_s))
    grid = np.arange(-n, n + 1) * grid_s
    margin = MAX_LAG_S + RATE_WINDOW_S
    lo = max(stream.t[0], reference.t[0]) + margin
    hi = min(stream.t[-1], reference.t[-1]) - margin
    t = t[(t >= lo) & (t <= hi)]
    if len(t) < 20 or n < 1:
        return None
    ref_rate = _rate(reference, t)
    offset, rms = _best(stream, ref_rate, t, grid)
    mid = len(t) // 2
    halves = tuple(_best(stream, _rate(reference, part), part, grid)[0] for part in (t[:mid], t[mid:]))
    after = _rate(stream, t - offset)
    corr = float(np.corrcoef(after, ref_rate)[0, 1]) if np.std(after) > 0 and np.std(ref_rate) > 0 else 0.0
    return LagEstimate(name, ref_name, offset, _rms(_rate(stream, t), ref_rate), _rms(after, ref_rate), corr,
                       (float(halves[0]), float(halves[1])), float(grid_s), len(t))


def learn_lags(runs: Sequence[CalibrationRun], reference: str = "gyro") -> list[LagEstimate]:
    """The offset of every yaw stream against ``reference`` (an
    ``input.time_offsets_s`` key of a yaw stream) over the learning steps
    of the first run that has both (the config holds one offset per
    stream). ``reference`` ``none``: none measured."""
    if reference == "none":
        return []
    if reference not in YAW_STREAMS:
        raise GslamError(f"--lag-reference {reference}: expected one of {', '.join(YAW_STREAMS)} or none")
    found: list[LagEstimate] = []
    for name, stream_name in YAW_STREAMS.items():
        if name == reference:
            continue
        for run in runs:
            ref, own = run.streams.get(YAW_STREAMS[reference]), run.streams.get(stream_name)
            if ref is None or own is None:
                continue
            est = estimate_lag(own, ref, run.steps.t[run.clean], name, reference)
            if est is not None:
                found.append(est)
                break
    return found
