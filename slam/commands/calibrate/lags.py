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

from slam.commands.calibrate.runs import CalibrationRun
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


Piece = tuple[Stream, Stream, np.ndarray]
"""One run's share: the stream, the reference (both unwrapped) and its learning times (s)."""


def _rms(pieces: Sequence[Piece], offset_s: float) -> float:
    """RMS over every piece of the rate difference about each piece's own
    mean (each run has its own gyro bias), the stream read ``offset_s`` earlier."""
    sq, n = 0.0, 0
    for stream, reference, t in pieces:
        d = _rate(stream, t - offset_s) - _rate(reference, t)
        sq += float(np.sum((d - d.mean()) ** 2))
        n += len(d)
    return float(np.sqrt(sq / n))


def _best(pieces: Sequence[Piece], grid: np.ndarray) -> float:
    """Steps 2-3: the refined offset."""
    rms = np.array([_rms(pieces, o) for o in grid])
    k = int(np.argmin(rms))
    if 0 < k < len(grid) - 1:
        y0, y1, y2 = rms[k - 1] ** 2, rms[k] ** 2, rms[k + 1] ** 2
        curve = y0 - 2.0 * y1 + y2
        step = grid[1] - grid[0]
        shift = 0.5 * (y0 - y2) / curve if curve > 0 else 0.0
        return float(grid[k] + np.clip(shift, -0.5, 0.5) * step)
    return float(grid[k])


def _period(stream: Stream) -> float:
    return float(np.median(np.diff(stream.t))) if len(stream.t) > 1 else np.inf


def estimate_lag(pieces: Sequence[Piece], name: str = "", ref_name: str = "") -> LagEstimate | None:
    """The offset of a stream against a reference (module docstring) over
    ``pieces``, one ``(stream, reference, times)`` per run: one offset for
    all (it is the sensor's); the halves are the first and the second half
    of every run's times. None when fewer than 20 times lie where both
    streams cover every candidate."""
    pieces = [(_unwrapped(s), _unwrapped(r), np.asarray(t, float)) for s, r, t in pieces]
    grid_s = max((max(_period(s), _period(r)) for s, r, _ in pieces), default=np.inf)
    if not np.isfinite(grid_s) or grid_s <= 0:
        return None
    n = int(np.floor(MAX_LAG_S / grid_s))
    grid = np.arange(-n, n + 1) * grid_s
    margin = MAX_LAG_S + RATE_WINDOW_S
    inside = []
    for s, r, t in pieces:
        lo = max(s.t[0], r.t[0]) + margin
        hi = min(s.t[-1], r.t[-1]) - margin
        if (t := t[(t >= lo) & (t <= hi)]).size >= 2:
            inside.append((s, r, t))
    steps = sum(len(t) for _, _, t in inside)
    if steps < 20 or n < 1:
        return None
    offset = _best(inside, grid)
    halves = tuple(_best([(s, r, t[: len(t) // 2] if first else t[len(t) // 2 :]) for s, r, t in inside], grid)
                   for first in (True, False))
    after = np.concatenate([_rate(s, t - offset) for s, _, t in inside])
    ref_rate = np.concatenate([_rate(r, t) for _, r, t in inside])
    corr = float(np.corrcoef(after, ref_rate)[0, 1]) if np.std(after) > 0 and np.std(ref_rate) > 0 else 0.0
    return LagEstimate(name, ref_name, offset, _rms(inside, 0.0), _rms(inside, offset), corr,
                       (float(halves[0]), float(halves[1])), float(grid_s), steps)


def learn_lags(runs: Sequence[CalibrationRun], reference: str = "gyro") -> list[LagEstimate]:
    """The offset of every yaw stream against ``reference`` (an
    ``input.time_offsets_s`` key of a yaw stream) over the learning steps
    of every run that has both: one offset per stream, as the config holds.
    ``reference`` ``none``: none measured."""
    if reference == "none":
        return []
    if reference not in YAW_STREAMS:
        raise GslamError(f"--lag-reference {reference}: expected one of {', '.join(YAW_STREAMS)} or none")
    found: list[LagEstimate] = []
    for name, stream_name in YAW_STREAMS.items():
        if name == reference:
            continue
        pieces = [(run.streams[stream_name], run.streams[YAW_STREAMS[reference]], run.steps.t[run.clean])
                  for run in runs if stream_name in run.streams and YAW_STREAMS[reference] in run.streams]
        if pieces and (est := estimate_lag(pieces, name, reference)) is not None:
            found.append(est)
    return found
