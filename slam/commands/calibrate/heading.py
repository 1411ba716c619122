"""The compass's heading against the GPS course: the mounting yaw.

A heading from a magnetometer or an orientation estimate is the sensor's,
not the robot's: mounted turned, or referenced to another north (an AHRS
whose yaw is not the compass's), it stands a constant angle off the
robot's heading. Where the robot drives straight and fast enough, the GPS
course (:mod:`validation.streams.course`) is the robot's heading, from
another sensor. Over the learning steps where both exist:

1. the offset is the circular mean of ``compass - course``; its steadiness
   the mean resultant length ``R`` (1: always the same offset);
2. the same on each half of the steps;
3. it is proposed (added to ``input.compass.mounting_yaw_deg``, the runs
   read again) when ``R >= MIN_STEADINESS``, the offset exceeds
   ``MIN_OFFSET_DEG`` and the halves agree within ``HALVES_DEG``.

Without GPS the offset cannot be known, and a relation of changes does not
need it.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from slam.commands.calibrate.runs import CalibrationRun

MIN_STEADINESS = 0.5
MIN_OFFSET_DEG = 2.0
HALVES_DEG = 5.0
MIN_STEPS = 50


@dataclass(frozen=True)
class HeadingOffset:
    """The compass heading minus the GPS course: ``offset_rad`` (circular
    mean), its mean resultant length, the offset on each half of the steps
    and how many steps."""

    offset_rad: float
    steadiness: float
    halves_rad: tuple[float, float]
    steps: int

    @property
    def proposed(self) -> bool:
        return not self.why_not()

    def why_not(self) -> str:
        """Why the offset is not proposed ('' when it is)."""
        if self.steadiness < MIN_STEADINESS:
            return f"the difference is not steady (mean resultant length {self.steadiness:.2f} < {MIN_STEADINESS:g})"
        if abs(np.degrees(self.offset_rad)) <= MIN_OFFSET_DEG:
            return f"it is within {MIN_OFFSET_DEG:g} deg"
        spread = abs(np.degrees(np.angle(np.exp(1j * (self.halves_rad[0] - self.halves_rad[1])))))
        if spread > HALVES_DEG:
            return f"the halves of the steps differ by {spread:.1f} deg (at most {HALVES_DEG:g})"
        return ""


def _mean(d: np.ndarray) -> tuple[float, float]:
    z = np.mean(np.exp(1j * d))
    return float(np.angle(z)), float(np.abs(z))


def learn_heading_offset(runs: Sequence[CalibrationRun]) -> HeadingOffset | None:
    """The offset of the module docstring over the learning steps of every
    run that has both the compass and the GPS course; None with fewer than
    ``MIN_STEPS`` such steps."""
    diffs = []
    for run in runs:
        s = run.steps
        if "compass_yaw" not in s.valid or "gps_course" not in s.valid:
            continue
        both = s.valid["compass_yaw"] & s.valid["gps_course"] & run.clean
        diffs.append(s.values["compass_yaw"][both] - s.values["gps_course"][both])
    d = np.concatenate(diffs) if diffs else np.zeros(0)
    if len(d) < MIN_STEPS:
        return None
    offset, steadiness = _mean(d)
    half = len(d) // 2
    return HeadingOffset(offset, steadiness, (_mean(d[:half])[0], _mean(d[half:])[0]), len(d))
