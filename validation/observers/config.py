"""Configuration of the observers: relations, unary checks and their defaults.

:class:`RelationConfig` describes one relation observer (Algorithm 3,
:mod:`validation.observers.relations`); :class:`MagnetometerCheckConfig`,
:class:`FieldGyroCheckConfig`, :class:`GpsCheckConfig` and
:class:`ScanCheckConfig` the unary checks (:mod:`validation.observers.checks`);
:class:`ObserversConfig` nests them all with the resampling gaps, and
:func:`observers_config` / :func:`load_observers_config` validate a mapping
or a YAML file into it with one-line errors.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from pathlib import Path
from typing import Annotated, Literal

import numpy as np
import pydantic
from pydantic import Field, field_validator, model_validator

from validation.base import bounds
from validation.base.errors import ValidationError
from validation.streams import is_stream_name, stream_component
from validation.trends import Rule, Window
from validation.base.yamlio import StrictFrozen, load_yaml, unknown_key, validate_mapping

Component = str
"""A component of the system model (checked against the model's list)."""


# --- configuration ------------------------------------------------------------


class RelationConfig(StrictFrozen):
    """One relation observer: two streams that should move together.

    ``kind: trend`` (the paper's) compares their qualitative trends:
    ``boundary`` is Algorithm 1's b in stream units per second (rad/s for
    yaw, m/s for distance, m/s^2 for speed), ``boundary_a``/``boundary_b``
    override it per stream, and ``window_s`` is Algorithm 2's w.

    ``kind: residual`` is quantitative: over a window of ``window_s``
    (centred or trailing, as the trends') stream b should change by ``gain``
    times stream a's change plus ``rate_offset`` (stream b's units per
    second) times the window; a step is a mismatch where the residual
    ``db - gain * da - rate_offset * window_s`` exceeds ``k_sigma`` times
    ``sqrt(sigma_floor^2 + (sigma_rel * da)^2)`` (stream b's units). It sees what trend symbols
    cannot: a scan matcher reporting 20 m/s while the odometry says 0.4 m/s
    has the same ``+`` trend.

    ``window_travel`` (residual and cusum): the window spans this much of
    stream a's travel, the sum of its absolute changes (m for a distance,
    rad for a yaw), rather than ``window_s`` of time; ``window_s`` is then
    the longest the window may last (a robot standing still makes no
    window). A scale error shows the same over every metre of travel, however
    slowly the robot moves and however seldom its sensors report, so a
    window of travel holds the same evidence at every speed.

    ``kind: cusum`` takes the residual relation's normalised residual and
    accumulates it in a two-sided CUSUM that forgets ``cusum_drift`` sds a
    step; a step is a mismatch while the sum exceeds ``k_sigma`` (its
    decision limit, in sds; :mod:`validation.observers.sequential`). It sees a
    standing error smaller than a residual relation's band.

    ``kind: offset`` compares the streams themselves: ``b - gain * a`` must
    stay within ``k_sigma * sigma_floor`` of its median over
    ``level_window_s`` (an absolute heading against an integrated one,
    whose offset drifts slowly; :mod:`validation.observers.quantitative`), or, with
    ``level_window_s: null``, of 0 (two absolute streams calibrated against
    each other: a compass, after its mounting yaw, against the GPS course).
    An angular difference is wrapped to (-pi, pi] there. ``level_max_rate``
    (stream b's units per second) holds the level: it is learnt from the
    steps before each one, in either pass, and moves no faster than that,
    the most the reference may drift (a gyro's bias). A compass that walks
    off faster stays off until it comes back, however long it stands there.

    ``mismatch_margin`` (trend only; null, the default, is the paper's
    Algorithm 3, which compares the symbols alone): two symbols that differ
    count as a mismatch only where the two slopes, each in units of its
    boundary, differ by more than this. Slopes of 0.9 b and 1.1 b have
    symbols ``0`` and ``+`` yet agree to a fifth of b; with a margin of 1
    the streams must part by at least b, the smallest change the relation
    is meant to see, before the counter climbs.

    All feed Algorithm 3: ``threshold`` is th, in steps. Components default
    to the streams' own.
    ``warmup_s`` (default ``2 * window_s``): a stream's trend takes part only
    once the stream has had data on every step for that long, since the
    truncated windows after a start or a gap give slopes of noise that the
    keep-previous rule of Algorithm 2 would hold on to.
    ``max_counter`` caps the mismatch counter; None (the paper) leaves it
    unbounded, so a fault that lasted N steps keeps ``NO_MATCH`` for about N
    steps after it ends.
    """

    name: str
    kind: Literal["trend", "residual", "cusum", "offset"] = "trend"
    stream_a: str
    stream_b: str
    boundary: Annotated[float, bounds.BOUNDARY] | None = Field(None, gt=0.0)
    window_s: bounds.Window_s = Field(gt=0.0)
    window_travel: Annotated[float, bounds.TRAVEL] | None = Field(None, gt=0.0)
    gain: Annotated[float, bounds.GAIN] = 1.0
    rate_offset: Annotated[float, bounds.STREAM_RATE] = 0.0
    sigma_floor: Annotated[float, bounds.SIGMA_FLOOR] | None = Field(None, gt=0.0)
    sigma_rel: Annotated[float, bounds.SIGMA_REL] = Field(0.0, ge=0.0)
    k_sigma: Annotated[float, bounds.K_SIGMA] = Field(3.0, gt=0.0)
    cusum_drift: Annotated[float, bounds.CUSUM_DRIFT] = Field(0.5, ge=0.0)
    level_window_s: bounds.Window_s | None = Field(60.0, gt=0.0)
    level_max_rate: Annotated[float, bounds.STREAM_RATE] | None = Field(None, gt=0.0)
    threshold: bounds.Count = Field(ge=0)
    max_counter: bounds.Count | None = Field(None, ge=1)
    warmup_s: Annotated[float, bounds.SPAN_S] | None = Field(None, ge=0.0)
    boundary_a: Annotated[float, bounds.BOUNDARY] | None = Field(None, gt=0.0)
    boundary_b: Annotated[float, bounds.BOUNDARY] | None = Field(None, gt=0.0)
    mismatch_margin: Annotated[float, bounds.MARGIN] | None = Field(None, gt=0.0)
    component_a: Component | None = None
    component_b: Component | None = None

    @field_validator("stream_a", "stream_b")
    @classmethod
    def _known_stream(cls, value: str) -> str:
        if not is_stream_name(value):
            raise ValueError(f"unknown stream {value!r} (validation.streams lists them; a further odometry "
                             "source's are NAME_yaw, NAME_distance, NAME_forward, NAME_lateral, NAME_speed, "
                             "NAME_fix_speed)")
        return value

    @model_validator(mode="after")
    def _two_streams(self) -> "RelationConfig":
        if self.stream_a == self.stream_b:
            raise ValueError(f"relation {self.name!r} compares {self.stream_a!r} with itself")
        if self.max_counter is not None and self.max_counter <= self.threshold:
            raise ValueError(f"relation {self.name!r}: max_counter must exceed threshold")
        if self.kind == "trend" and self.boundary is None:
            raise ValueError(f"relation {self.name!r}: a trend relation needs a boundary")
        if self.kind != "trend" and self.sigma_floor is None:
            raise ValueError(f"relation {self.name!r}: a {self.kind} relation needs sigma_floor")
        if self.mismatch_margin is not None and self.kind != "trend":
            raise ValueError(f"relation {self.name!r}: mismatch_margin is for trend relations only")
        if self.window_travel is not None and self.kind not in ("residual", "cusum"):
            raise ValueError(f"relation {self.name!r}: window_travel is for residual and cusum relations only")
        if self.window_travel is not None and self.rate_offset != 0.0:
            raise ValueError(f"relation {self.name!r}: rate_offset needs a window of time, not window_travel")
        if self.level_max_rate is not None and (self.kind != "offset" or self.level_window_s is None):
            raise ValueError(f"relation {self.name!r}: level_max_rate needs an offset relation with a level_window_s")
        return self

    @property
    def streams(self) -> tuple[str, str]:
        return self.stream_a, self.stream_b

    def compact(self) -> dict:
        """Its name, kind and streams, then every value that differs from
        the default (a None shown where the default is not: an offset
        relation's level of 0), JSON-ready: what a config file needs."""
        data = self.model_dump(mode="json")
        default = {k: f.default for k, f in type(self).model_fields.items()}
        return {k: v for k, v in data.items()
                if k in ("name", "kind", "stream_a", "stream_b")
                or (v != default.get(k) and (v is not None or default.get(k) is not None))}

    @property
    def boundaries(self) -> tuple[float, float]:
        return (self.boundary_a or self.boundary, self.boundary_b or self.boundary)

    def compared(self, symbol_a, symbol_b, slope_a, slope_b):
        """Stream b's symbols as Algorithm 3 compares them: with a
        ``mismatch_margin``, a's symbol where the two slopes agree within it."""
        if self.mismatch_margin is None:
            return symbol_b
        ba, bb = self.boundaries
        close = np.abs(np.asarray(slope_a) / ba - np.asarray(slope_b) / bb) <= self.mismatch_margin
        return np.where(close, symbol_a, symbol_b).astype(np.asarray(symbol_b).dtype)

    @property
    def warmup(self) -> float:
        return 2.0 * self.window_s if self.warmup_s is None else self.warmup_s

    @property
    def components(self) -> tuple[str, str]:
        return (
            self.component_a or stream_component(self.stream_a),
            self.component_b or stream_component(self.stream_b),
        )


def _relation(name: str, a: str, b: str, boundary: float, window_s: float, threshold: int) -> RelationConfig:
    return RelationConfig(
        name=name, stream_a=a, stream_b=b, boundary=boundary, window_s=window_s, threshold=threshold
    )


# Thresholds are in steps: 10 is 1 s at the default 10 Hz validation rate,
# about twice the longest mismatch a clean turn gives (noise moves the
# instant either stream's slope crosses b).
DEFAULT_RELATIONS: tuple[RelationConfig, ...] = (
    # The paper's three yaw relations, pairwise.
    _relation("yaw_compass_gyro", "compass_yaw", "gyro_yaw", 0.05, 2.0, 10),
    _relation("yaw_compass_sm", "compass_yaw", "sm_yaw", 0.05, 2.0, 10),
    _relation("yaw_gyro_sm", "gyro_yaw", "sm_yaw", 0.05, 2.0, 10),
    _relation("distance_odo_sm", "odo_distance", "sm_distance", 0.05, 2.0, 10),
    _relation("lateral_odo_sm", "odo_lateral", "sm_lateral", 0.05, 2.0, 10),
    _relation("yaw_odo_gyro", "odo_yaw", "gyro_yaw", 0.05, 2.0, 10),
    # GPS speed from 1 Hz fixes is noisy: a longer window, a wider band.
    _relation("speed_gps_odo", "gps_speed", "odo_speed", 0.2, 4.0, 10),
)


class MagnetometerCheckConfig(StrictFrozen):
    """Field strength and dip against the local Earth field; the reference
    comes from the recording unless ``strength_T``/``dip_deg`` are given."""

    enabled: bool = True
    name: str = "mag_plausible"
    component: Component = "IMU_YAW"
    strength_T: Annotated[float | None, bounds.EARTH_FIELD_T] = Field(None, gt=0.0)
    dip_deg: float | None = Field(None, ge=-90.0, le=90.0)
    tolerance_T: bounds.FieldTolerance_T = Field(5e-6, gt=0.0)
    # gslam calibrate writes at least 0.001 deg (a noise-free simulated field).
    tolerance_dip_deg: Annotated[float, bounds.within(1e-3, 180.0, "deg", "below any magnetometer's noise: every "
                                                      "sample would deviate", "a dip is within +-90 deg: no "
                                                      "deviation would count")] = Field(5.0, gt=0.0)
    hold_s: Annotated[float, bounds.HOLD_S] = Field(1.0, ge=0.0)


class FieldGyroCheckConfig(StrictFrozen):
    """The field's change over ``window_s`` that the gyro's turn does not
    explain, each end averaged over ``smooth_s``, against ``tolerance_T``
    (:mod:`validation.streams.field_gyro`). Off unless enabled: it needs the
    magnetometer's field and a gyro on one clock."""

    enabled: bool = False
    name: str = "mag_field_gyro"
    component: Component = "IMU_YAW"
    window_s: bounds.Window_s = Field(1.0, gt=0.0)
    smooth_s: bounds.Window_s = Field(0.1, gt=0.0)
    tolerance_T: bounds.FieldTolerance_T = Field(5e-6, gt=0.0)
    hold_s: Annotated[float, bounds.HOLD_S] = Field(0.0, ge=0.0)


class GpsCheckConfig(StrictFrozen):
    """The receiver's reported horizontal sigma against a maximum."""

    enabled: bool = True
    name: str = "gps_plausible"
    component: Component = "GPS"
    max_sigma_m: Annotated[float, bounds.SIGMA_M] = Field(5.0, gt=0.0)
    hold_s: Annotated[float, bounds.HOLD_S] = Field(0.0, ge=0.0)


SCAN_AXES = ("dist", "lat", "yaw")
"""The scan check's axes, in the order of the scan's (forward, left, turn)."""


class ScanCheckConfig(StrictFrozen):
    """Scan degeneracy: one check per scan-matching modality, named
    ``{name}_dist``, ``{name}_lat`` and ``{name}_yaw`` (components
    ``components``). A scan is implausible for all three with fewer than
    ``min_returns`` returns, and for a modality when the smallest eigenvalue
    of its point-to-line information is below ``min_eigenvalue`` and that
    eigenvector's forward, left or turn part exceeds ``min_share`` in size
    (:mod:`slam.frontend.scan_geometry`); the defaults are the simulator's fault
    definition (:mod:`slam.sim.faults`). Off unless enabled: the front-end
    then computes the figures."""

    enabled: bool = False
    name: str = "scan_degenerate"
    components: tuple[Component, Component, Component] = ("SM_DIST", "SM_LAT", "SM_YAW")
    min_returns: bounds.Count = Field(20, ge=1)
    min_eigenvalue: Annotated[float, bounds.SCAN_MIN_EIGENVALUE] = Field(0.03, ge=0.0)
    min_share: float = Field(0.5, gt=0.0, lt=1.0)
    hold_s: Annotated[float, bounds.HOLD_S] = Field(0.0, ge=0.0)

    @property
    def names(self) -> tuple[str, str, str]:
        return tuple(f"{self.name}_{axis}" for axis in SCAN_AXES)


class ScanCeilingConfig(StrictFrozen):
    """A laser that sees too little: a scan cut off at a range ceiling
    (:func:`slam.frontend.scan_geometry.range_ceiling`) is implausible for
    the whole scan matcher (``component``, a sensor of the model). A scan is
    cut off when at least ``min_no_return`` of its beams have no return and
    at least ``min_edge_share`` of its ``min_edges`` or more gap edges lie
    within a tenth of its farthest return, and that return, the ceiling, is
    at most ``max_ceiling_m`` away: a laser that sees 25 m of a hall still
    holds the matcher, one that sees 3 m of it does not (the laser blind
    altogether is the scan check's, ``scan.min_returns``). A cut is a ceiling
    short of the laser's reach, so the ceiling must also be at most
    ``reach_share`` of the farthest a return may lie (the laser's range, or
    the front-end's ``max_range_m`` if nearer): a 10 m laser in an open yard
    ends in gaps at 10 m and sees what it can. A range limit does not come and go
    from scan to scan: scans between two cut-off ones at most ``fill_s``
    apart count as cut off too. Nor does the scan matcher recover at once
    when the laser sees again: its local map still holds the cut scans'
    points, placed by registrations that could not hold, so the scans of the
    ``settle_s`` after a cut count too, if the cut lasted ``settle_after_s``
    or more (one scan cut off by a wall in front of the laser leaves the map
    whole). Off unless enabled."""

    enabled: bool = False
    name: str = "scan_ceiling"
    component: Component = "SM"
    min_no_return: float = Field(0.1, gt=0.0, le=1.0)
    min_edges: bounds.Count = Field(2, ge=1)
    min_edge_share: float = Field(0.5, gt=0.0, le=1.0)
    max_ceiling_m: Annotated[float, bounds.LASER_RANGE_M] = Field(10.0, gt=0.0)
    reach_share: float = Field(0.9, gt=0.0, le=1.0)
    fill_s: Annotated[float, bounds.SPAN_S] = Field(0.0, ge=0.0)
    settle_s: Annotated[float, bounds.SPAN_S] = Field(0.0, ge=0.0)
    settle_after_s: Annotated[float, bounds.SPAN_S] = Field(0.0, ge=0.0)
    hold_s: Annotated[float, bounds.HOLD_S] = Field(0.0, ge=0.0)


class ObserversConfig(StrictFrozen):
    """All observers. ``max_gap_s`` is the largest gap (s) between samples a
    step may be interpolated across; a sparse stream may bridge up to
    ``gap_periods`` of its own median sample period instead (null: never),
    and ``stream_max_gap_s`` sets a stream's gap outright
    (:func:`validation.streams.stream_max_gap`).

    ``min_coverage``: an observer with a valid observation on a smaller
    share of the steps is reported with a warning that says why
    (:mod:`validation.observers.coverage`).

    ``window``: the trend windows of Algorithm 2, ``centred`` on each sample
    (the paper's; it needs the samples after it, so offline validation only)
    or ``trailing`` (causal); null takes the one of ``validation.pass``.
    ``rule``: Algorithm 1's rule inside the band, ``paper`` as listed or the
    ``project``'s (:mod:`validation.trends`).

    ``gps_speed_window_s``: the regression window of ``gps_speed``,
    ``odo_fix_speed`` and ``gps_course``; the course counts where the speed
    is at least ``gps_course_min_speed_mps`` (the travel over the window
    several times the fixes' noise) and the odometry turns by at most
    ``gps_course_max_turn_deg`` over the window (:mod:`validation.streams.course`).
    """

    window: Window | None = None
    rule: Rule = "paper"
    relations: tuple[RelationConfig, ...] = DEFAULT_RELATIONS
    magnetometer: MagnetometerCheckConfig = MagnetometerCheckConfig()
    field_gyro: FieldGyroCheckConfig = FieldGyroCheckConfig()
    gps: GpsCheckConfig = GpsCheckConfig()
    scan: ScanCheckConfig = ScanCheckConfig()
    scan_ceiling: ScanCeilingConfig = ScanCeilingConfig()
    max_gap_s: bounds.Window_s = Field(0.5, gt=0.0)
    gap_periods: Annotated[float, bounds.GAP_PERIODS] | None = Field(3.0, gt=0.0)
    stream_max_gap_s: dict[str, Annotated[float, Field(gt=0.0), bounds.WINDOW_S]] = Field(default_factory=lambda: {"gps_speed": 2.5, "gps_sigma": 2.5})
    min_coverage: float = Field(0.25, ge=0.0, le=1.0)
    gps_speed_window_s: bounds.Window_s = Field(5.0, gt=0.0)
    gps_course_min_speed_mps: Annotated[float, bounds.within(None, 100.0, "m/s", high="no ground robot drives "
                                                             "faster: no course would be taken")] = Field(0.5, gt=0.0)
    gps_course_max_turn_deg: Annotated[float, bounds.within(None, 360.0, "deg", high="a turn is at most a full "
                                                            "one")] = Field(15.0, gt=0.0)

    @model_validator(mode="after")
    def _names(self) -> "ObserversConfig":
        names = [r.name for r in self.relations] + [
            self.magnetometer.name, self.field_gyro.name, self.gps.name, *self.scan.names,
            self.scan_ceiling.name,
        ]
        dupes = sorted({n for n in names if names.count(n) > 1})
        if dupes:
            raise ValueError(f"observer name {dupes[0]!r} used twice")
        for key in self.stream_max_gap_s:
            if not is_stream_name(key):
                raise ValueError(f"stream_max_gap_s: unknown stream {key!r}")
        return self


def field_gyro_stream(config: ObserversConfig) -> tuple[float, float] | None:
    """``(window_s, smooth_s)`` of ``mag_field_change`` when its check is on."""
    fg = config.field_gyro
    return (fg.window_s, fg.smooth_s) if fg.enabled else None


def gps_course_limits(config: ObserversConfig) -> tuple[float, float]:
    """``(min_speed_mps, max_turn_rad)`` of the ``gps_course`` stream."""
    return config.gps_course_min_speed_mps, math.radians(config.gps_course_max_turn_deg)


def observers_config(data: Mapping, source: str = "observers", section: bool = False) -> ObserversConfig:
    """Validate a mapping (e.g. a YAML section) as :class:`ObserversConfig`.

    An unknown key is reported before anything else: a misspelt required key
    is also a missing one, and the misspelling is what the user must see.
    """
    try:
        return ObserversConfig.model_validate(data)
    except pydantic.ValidationError as e:
        for err in e.errors():
            if err["type"] == "extra_forbidden":
                raise ValidationError(unknown_key(source, tuple(err["loc"]), section, ObserversConfig)) from None
    return validate_mapping(ObserversConfig, data, source, section)


def load_observers_config(path: str | Path) -> ObserversConfig:
    """Read an :class:`ObserversConfig` from a YAML file."""
    return observers_config(load_yaml(path), str(path))
