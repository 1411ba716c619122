"""Faults to add to a recording, as ``gslam inject`` takes them:
``KIND@T0:T1[,param=value ...]``, times in seconds from the recording's
start.

======== ===================================================================
kind     what is added (physics in :mod:`slam.commands.inject.physics`)
======== ===================================================================
dipole   a magnetic dipole (steel, a magnet) beside the path: its field on
         the magnetometer, or the heading error it causes on an IMU's
         orientation estimate
laser_cut laser ranges beyond ``range_m`` become "no return" (the open yard)
gyro_bias a step in the gyro's yaw-rate bias
slip     odometry whose increments are scaled (wheels or tracks slipping)
multipath a GPS position bias that rises and falls (a reflected signal)
======== ===================================================================

Each fault is present from T0 to T1. Its true intervals are where its
error is physically beyond the component's nominal noise, by the same
thresholds the simulator labels its faults with (``label_*`` parameters).
"""

from __future__ import annotations

from typing import Annotated, Literal

import pydantic
from pydantic import Field, model_validator

from slam.errors import GslamError
from validation.base import bounds
from validation.base.bounds import within
from validation.base.yamlio import StrictFrozen

# What the faults can physically be: a laser's reach, a slipping wheel, a gyro's measuring range.
_CUT_RANGE_M = within(0.01, 1000.0, "m", "shorter than any laser's minimum range: every beam would be cut",
                      "beyond any laser's reach: no beam would be cut")
_SLIP_SCALE = within(None, 10.0, "", high="a slipping wheel or track reports a few times its travel, not more")
_GYRO_BIAS_DEG_S = within(-2000.0, 2000.0, "deg/s", "beyond any gyro's measuring range (2000 deg/s)",
                          "beyond any gyro's measuring range (2000 deg/s)")
_GYRO_BIAS_LABEL_DEG_S = within(1e-3, 2000.0, "deg/s", "below any gyro's noise: every sample would be a fault",
                                "beyond any gyro's measuring range (2000 deg/s): nothing would be a fault")
# Where a dipole can be: beside the path (not inside the sensor), near enough to be felt.
_DIPOLE_DISTANCE_M = within(1e-2, 1000.0, "m", "closer than a centimetre is inside the sensor",
                            "a dipole a kilometre away is felt nowhere")
_DIPOLE_HEIGHT_M = within(-1000.0, 1000.0, "m", "a dipole a kilometre below is felt nowhere",
                          "a dipole a kilometre above is felt nowhere")
# The Earth's horizontal field is 0 at the magnetic poles and at most about 40 uT.
_EARTH_HORIZONTAL_UT = within(0.1, 100.0, "uT", "no compass finds north in a horizontal field that weak",
                              "more than twice the Earth's strongest horizontal field")


class Fault(StrictFrozen):
    """Common to every fault: the interval it is present in (s from the
    recording's start)."""

    kind: str
    start_s: Annotated[float, bounds.RECORDING_S]
    end_s: Annotated[float, bounds.RECORDING_S]

    @model_validator(mode="after")
    def _ordered(self) -> "Fault":
        if not self.end_s > self.start_s:
            raise ValueError(f"the interval {self.start_s:g}:{self.end_s:g} must end after it starts")
        return self

    def text(self) -> str:
        params = ",".join(f"{k}={v}" for k, v in self.model_dump().items() if k not in ("kind", "start_s", "end_s"))
        return f"{self.kind}@{self.start_s:g}:{self.end_s:g}" + (f",{params}" if params else "")


class DipoleFault(Fault):
    """A point dipole of ``moment_A_m2`` placed ``distance_m`` to the
    ``side`` of the path where the robot is at the interval's middle,
    ``height_m`` below the sensor, its moment horizontal at ``azimuth_deg``
    (counter-clockwise) from the path's heading there. ``target``: the
    ``magnetometer`` field, the ``heading`` of an IMU orientation, or
    ``auto`` (whichever the compass of the recording is). Labelled where the
    compass heading is off by more than ``label_deg``.
    ``earth_horizontal_uT`` is the Earth field's horizontal strength a
    heading target is disturbed against (a magnetometer target uses the
    measured field)."""

    kind: Literal["dipole"] = "dipole"
    moment_A_m2: bounds.DipoleMoment_A_m2 = Field(500.0, gt=0.0)
    distance_m: Annotated[float, _DIPOLE_DISTANCE_M] = Field(2.0, gt=0.0)
    side: Literal["left", "right"] = "left"
    height_m: Annotated[float, _DIPOLE_HEIGHT_M] = 0.0
    azimuth_deg: bounds.Azimuth_deg = 90.0
    target: Literal["auto", "magnetometer", "heading"] = "auto"
    earth_horizontal_uT: Annotated[float, _EARTH_HORIZONTAL_UT] = Field(20.0, gt=0.0)
    label_deg: bounds.HeadingError_deg = Field(5.0, gt=0.0)


class LaserCutFault(Fault):
    """Every range beyond ``range_m`` is no return. Scan matching is
    labelled where a cut scan keeps fewer than ``label_min_returns`` returns
    or its geometry leaves a direction unconstrained (smallest eigenvalue of
    its point-to-line information below ``label_min_eigenvalue``), per
    modality as the simulator does (:mod:`slam.sim.faults`)."""

    kind: Literal["laser_cut"] = "laser_cut"
    range_m: Annotated[float, _CUT_RANGE_M] = Field(4.0, gt=0.0)
    label_min_returns: bounds.Count = Field(20, ge=3)
    label_min_eigenvalue: bounds.ScanMinEigenvalue = Field(0.03, ge=0.0)


class GyroBiasFault(Fault):
    """``bias_deg_s`` added to the yaw rate; labelled over its whole
    interval when it exceeds ``label_deg_s`` (the simulator's gyro bias
    threshold, 0.01 rad/s)."""

    kind: Literal["gyro_bias"] = "gyro_bias"
    bias_deg_s: Annotated[float, _GYRO_BIAS_DEG_S] = 2.0
    label_deg_s: Annotated[float, _GYRO_BIAS_LABEL_DEG_S] = Field(0.57, gt=0.0)


class SlipFault(Fault):
    """The odometry's distance increments times ``scale`` and its turns
    times ``yaw_scale``; labelled (``ODO_DIST``, ``ODO_YAW``) where the
    added error exceeds ``label_slip`` of the motion (the simulator's 0.12)."""

    kind: Literal["slip"] = "slip"
    scale: Annotated[float, _SLIP_SCALE] = Field(1.5, ge=0.0)
    yaw_scale: Annotated[float, _SLIP_SCALE] = Field(1.0, ge=0.0)
    label_slip: bounds.SlipFraction = Field(0.12, gt=0.0)


class MultipathFault(Fault):
    """A GPS bias towards ``azimuth_deg`` (counter-clockwise from east) that
    rises from 0 to ``bias_m`` at the interval's middle and falls back;
    labelled where it exceeds ``label_sigmas`` times the fix's own sigma."""

    kind: Literal["multipath"] = "multipath"
    bias_m: bounds.Multipath_m = Field(8.0, ge=0.0)
    azimuth_deg: bounds.Azimuth_deg = 0.0
    label_sigmas: bounds.KSigma = Field(3.0, gt=0.0)


KINDS: dict[str, type[Fault]] = {
    "dipole": DipoleFault,
    "laser_cut": LaserCutFault,
    "gyro_bias": GyroBiasFault,
    "slip": SlipFault,
    "multipath": MultipathFault,
}


def no_sample(fault: Fault, sample: str) -> str:
    """The error of a fault whose interval holds no sample it could change."""
    return (f"--fault {fault.text()}: no {sample} between {fault.start_s:g} and {fault.end_s:g} s, so the fault "
            "would change nothing; give an interval the recording has data in")


def parse_fault(text: str) -> Fault:
    """``KIND@T0:T1[,param=value ...]`` -> a typed fault; one-line
    :class:`GslamError` naming the ``--fault`` and what is wrong."""
    where = f"--fault {text}"
    head, _, rest = text.partition(",")
    kind, at, span = head.partition("@")
    kind = kind.strip()
    if kind not in KINDS:
        raise GslamError(f"{where}: unknown fault kind '{kind}'; expected one of {', '.join(KINDS)}")
    start, colon, end = span.partition(":")
    if not at or not colon:
        raise GslamError(f"{where}: expected KIND@T0:T1[,param=value ...], e.g. {kind}@120:140")
    data: dict[str, object] = {"kind": kind, "start_s": start.strip(), "end_s": end.strip()}
    for item in filter(None, (p.strip() for p in rest.split(","))):
        key, eq, value = item.partition("=")
        if not eq or not key.strip():
            raise GslamError(f"{where}: expected param=value, got '{item}'")
        if key.strip() in data:  # the last would win in silence, over the interval's own too
            given = " (KIND@T0:T1 gives it)" if key.strip() in ("kind", "start_s", "end_s") else ""
            raise GslamError(f"{where}: '{key.strip()}' given twice{given}")
        data[key.strip()] = value.strip()
    model = KINDS[kind]
    try:
        return model.model_validate(data)
    except pydantic.ValidationError as e:
        err = e.errors()[0]
        key = ".".join(str(p) for p in err["loc"])
        if err["type"] == "extra_forbidden":
            known = ", ".join(k for k in model.model_fields if k not in ("kind", "start_s", "end_s"))
            raise GslamError(f"{where}: unknown parameter '{key}' of {kind} (known: {known})") from None
        msg = err["msg"].removeprefix("Value error, ")
        raise GslamError(f"{where}: {key + ': ' if key else ''}{msg}") from None
