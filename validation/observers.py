"""Observers: the paper's Algorithm 3 and unary plausibility checks.

A *relation* observer compares the qualitative trends (Algorithms 1 and 2,
:mod:`validation.trends`) of two streams that should move together, e.g. the
compass yaw and the integrated gyro yaw, at every validation step. A
mismatch counter rises by one on a step where the two symbols differ and
falls by one (not below zero) where they agree; the observation is
``NO_MATCH`` while the counter exceeds the relation's threshold ``th`` and
``MATCH`` otherwise. (The listing's ``count = counter + 1`` is read as the
counter's own increment.) The comparison is strict: ``+`` against ``0`` is a
mismatch. A step where either stream has no data makes no observation and
leaves the counter unchanged; trends are computed over the steps where the
stream has data, so a gap shortens the next windows as at the start; the
relation observes nothing until both streams have had data for a warm-up
time (``RelationConfig.warmup_s``), since trends from truncated windows are
noise.

A *unary* check tests one component against physics (the magnetometer's
field strength and dip against the local Earth field, the GPS receiver's
reported sigma); it says ``IMPLAUSIBLE`` once the deviation has lasted
``hold_s`` and ``PLAUSIBLE`` otherwise.

:func:`observe` runs everything over a whole run; :class:`ObserverBank` does
the same one step at a time, with the same results.
"""

from __future__ import annotations

import logging
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np
import pydantic
from pydantic import BaseModel, ConfigDict, Field, model_validator

from slam.config import load_yaml
from slam.errors import GslamError
from slam.recording import MagneticReference
from validation.errors import ValidationError
from validation.model import Observation, Plausibility, validate_mapping
from validation.streams import (
    ANGULAR_STREAMS,
    STREAM_COMPONENT,
    STREAM_NAMES,
    StepStreams,
    Stream,
    StreamName,
    resample_streams,
)
from validation.trends import Trend, TrendEstimator, trends

logger = logging.getLogger(__name__)

Component = Literal["ODO", "IMU_GYRO", "IMU_YAW", "SM", "GPS"]


# --- configuration ------------------------------------------------------------


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class RelationConfig(_Strict):
    """One relation observer: two streams whose trends should agree.

    ``boundary`` is Algorithm 2's b in stream units per second (rad/s for
    yaw, m/s for distance, m/s^2 for speed); ``boundary_a``/``boundary_b``
    override it per stream. ``window_s`` is Algorithm 1's w; ``threshold``
    is th, in steps. Components default to the streams' own.
    ``warmup_s`` (default ``2 * window_s``): a stream's trend takes part only
    once the stream has had data on every step for that long, since the
    truncated windows after a start or a gap give slopes of noise that the
    keep-previous rule of Algorithm 2 would hold on to.
    ``max_counter`` caps the mismatch counter; None (the paper) leaves it
    unbounded, so a fault that lasted N steps keeps ``NO_MATCH`` for about N
    steps after it ends.
    """

    name: str
    stream_a: StreamName
    stream_b: StreamName
    boundary: float = Field(gt=0.0)
    window_s: float = Field(gt=0.0)
    threshold: int = Field(ge=0)
    max_counter: int | None = Field(None, ge=1)
    warmup_s: float | None = Field(None, ge=0.0)
    boundary_a: float | None = Field(None, gt=0.0)
    boundary_b: float | None = Field(None, gt=0.0)
    component_a: Component | None = None
    component_b: Component | None = None

    @model_validator(mode="after")
    def _two_streams(self) -> "RelationConfig":
        if self.stream_a == self.stream_b:
            raise ValueError(f"relation {self.name!r} compares {self.stream_a!r} with itself")
        if self.max_counter is not None and self.max_counter <= self.threshold:
            raise ValueError(f"relation {self.name!r}: max_counter must exceed threshold")
        return self

    @property
    def streams(self) -> tuple[str, str]:
        return self.stream_a, self.stream_b

    @property
    def boundaries(self) -> tuple[float, float]:
        return (self.boundary_a or self.boundary, self.boundary_b or self.boundary)

    @property
    def warmup(self) -> float:
        return 2.0 * self.window_s if self.warmup_s is None else self.warmup_s

    @property
    def components(self) -> tuple[str, str]:
        return (
            self.component_a or STREAM_COMPONENT[self.stream_a],
            self.component_b or STREAM_COMPONENT[self.stream_b],
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
    _relation("yaw_odo_gyro", "odo_yaw", "gyro_yaw", 0.05, 2.0, 10),
    # GPS speed from 1 Hz fixes is noisy: a longer window, a wider band.
    _relation("speed_gps_odo", "gps_speed", "odo_speed", 0.2, 4.0, 10),
)


class MagnetometerCheckConfig(_Strict):
    """Field strength and dip against the local Earth field; the reference
    comes from the recording unless ``strength_T``/``dip_deg`` are given."""

    enabled: bool = True
    name: str = "mag_plausible"
    component: Component = "IMU_YAW"
    strength_T: float | None = Field(None, gt=0.0)
    dip_deg: float | None = Field(None, ge=-90.0, le=90.0)
    tolerance_T: float = Field(5e-6, gt=0.0)
    tolerance_dip_deg: float = Field(5.0, gt=0.0)
    hold_s: float = Field(1.0, ge=0.0)


class GpsCheckConfig(_Strict):
    """The receiver's reported horizontal sigma against a maximum."""

    enabled: bool = True
    name: str = "gps_plausible"
    component: Component = "GPS"
    max_sigma_m: float = Field(5.0, gt=0.0)
    hold_s: float = Field(0.0, ge=0.0)


class ObserversConfig(_Strict):
    """All observers; ``max_gap_s`` is the largest gap (s) between samples a
    step may be interpolated across, ``stream_max_gap_s`` overrides it."""

    relations: tuple[RelationConfig, ...] = DEFAULT_RELATIONS
    magnetometer: MagnetometerCheckConfig = MagnetometerCheckConfig()
    gps: GpsCheckConfig = GpsCheckConfig()
    max_gap_s: float = Field(0.5, gt=0.0)
    stream_max_gap_s: dict[str, float] = Field(default_factory=lambda: {"gps_speed": 2.5, "gps_sigma": 2.5})
    gps_speed_window_s: float = Field(5.0, gt=0.0)

    @model_validator(mode="after")
    def _names(self) -> "ObserversConfig":
        names = [r.name for r in self.relations] + [self.magnetometer.name, self.gps.name]
        dupes = sorted({n for n in names if names.count(n) > 1})
        if dupes:
            raise ValueError(f"observer name {dupes[0]!r} used twice")
        for key in self.stream_max_gap_s:
            if key not in STREAM_NAMES:
                raise ValueError(f"stream_max_gap_s: unknown stream {key!r}")
        return self


def observers_config(data: Mapping, source: str = "observers") -> ObserversConfig:
    """Validate a mapping (e.g. a YAML section) as :class:`ObserversConfig`.

    An unknown key is reported before anything else: a misspelt required key
    is also a missing one, and the misspelling is what the user must see.
    """
    try:
        return ObserversConfig.model_validate(data)
    except pydantic.ValidationError as e:
        for err in e.errors():
            if err["type"] == "extra_forbidden":
                loc = ".".join(str(p) for p in err["loc"])
                raise ValidationError(f"{source}: unknown key '{loc}'") from None
    return validate_mapping(ObserversConfig, data, source)


def load_observers_config(path: str | Path) -> ObserversConfig:
    """Read an :class:`ObserversConfig` from a YAML file."""
    try:
        data = load_yaml(path)
    except GslamError as e:
        raise ValidationError(str(e)) from None
    return observers_config(data, str(path))

_HOLD_EPS_S = 1e-9  # step times are sums of floats; 0.1 * 10 may land below 1.0


# --- Algorithm 3 ------------------------------------------------------------


def compare_trends(
    symbol_a: np.ndarray,
    symbol_b: np.ndarray,
    threshold: int,
    valid: np.ndarray | None = None,
    max_counter: int | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Algorithm 3 over whole sequences: ``(counter, no_match)`` per step.

    ``counter_k = counter_{k-1} + 1`` on a mismatch (symbols differ),
    ``max(0, counter_{k-1} - 1)`` on a match, unchanged where ``valid`` is
    false; ``no_match = valid and counter > threshold``. Without a cap the
    recursion is Lindley's, whose closed form ``S_k - min(0, min_{j<=k} S_j)``
    over the running sum ``S`` of the +-1 steps needs no loop.
    """
    a = np.asarray(symbol_a)
    b = np.asarray(symbol_b)
    valid = np.ones(len(a), dtype=bool) if valid is None else np.asarray(valid, dtype=bool)
    step = np.where(valid, np.where(a != b, 1, -1), 0).astype(np.int64)
    if max_counter is None:
        s = np.cumsum(step)
        counter = s - np.minimum.accumulate(np.minimum(s, 0)) if len(s) else s
    else:
        # Reflected at both ends: no simple closed form, and one pass is cheap.
        counter = np.empty(len(step), dtype=np.int64)
        c = 0
        for k, x in enumerate(step.tolist()):
            c = min(max_counter, max(0, c + x))
            counter[k] = c
    return counter, valid & (counter > threshold)


class MismatchCounter:
    """Algorithm 3 one step at a time."""

    def __init__(self, threshold: int, max_counter: int | None = None) -> None:
        self.threshold = threshold
        self.max_counter = max_counter
        self.counter = 0

    def update(self, symbol_a: int, symbol_b: int, valid: bool = True) -> Observation | None:
        """Count one step; the observation, or None where there is no data."""
        if not valid:
            return None
        self.counter = self.counter + 1 if symbol_a != symbol_b else max(0, self.counter - 1)
        if self.max_counter is not None:
            self.counter = min(self.counter, self.max_counter)
        return Observation.NO_MATCH if self.counter > self.threshold else Observation.MATCH


# --- unary checks -------------------------------------------------------------


@dataclass(frozen=True)
class MagnetometerCheck:
    """Field strength (T) and dip (rad, positive down) against the Earth field."""

    name: str
    component: str
    strength_T: float
    dip_rad: float
    tolerance_T: float
    tolerance_dip_rad: float
    hold_s: float
    streams: tuple[str, ...] = ("mag_strength", "mag_dip")

    def deviant(self, values: Mapping[str, np.ndarray]) -> np.ndarray:
        """True where the field differs from the reference beyond a tolerance."""
        return (np.abs(values["mag_strength"] - self.strength_T) > self.tolerance_T) | (
            np.abs(values["mag_dip"] - self.dip_rad) > self.tolerance_dip_rad
        )


@dataclass(frozen=True)
class GpsQualityCheck:
    """The receiver's horizontal sigma (m) against a maximum."""

    name: str
    component: str
    max_sigma_m: float
    hold_s: float
    streams: tuple[str, ...] = ("gps_sigma",)

    def deviant(self, values: Mapping[str, np.ndarray]) -> np.ndarray:
        """True where the reported sigma exceeds the maximum."""
        return np.asarray(values["gps_sigma"]) > self.max_sigma_m


UnaryCheck = MagnetometerCheck | GpsQualityCheck


def unary_checks(config: ObserversConfig, reference: MagneticReference | None = None) -> list[UnaryCheck]:
    """The enabled unary checks; the magnetometer check needs a reference
    field (config values first, then ``reference``) and is skipped without."""
    checks: list[UnaryCheck] = []
    mag = config.magnetometer
    if mag.enabled:
        strength, dip = (reference.strength_T, reference.dip_rad) if reference is not None else (None, None)
        if mag.strength_T is not None:
            strength = mag.strength_T
        if mag.dip_deg is not None:
            dip = np.radians(mag.dip_deg)
        if strength is None or dip is None:
            logger.warning("no magnetic reference field: the magnetometer check is off")
        else:
            checks.append(
                MagnetometerCheck(
                    mag.name, mag.component, float(strength), float(dip),
                    mag.tolerance_T, float(np.radians(mag.tolerance_dip_deg)), mag.hold_s,
                )
            )
    if config.gps.enabled:
        g = config.gps
        checks.append(GpsQualityCheck(g.name, g.component, g.max_sigma_m, g.hold_s))
    return checks


def held(t: np.ndarray, deviant: np.ndarray, hold_s: float) -> np.ndarray:
    """True where ``deviant`` has been true on every step for at least ``hold_s``
    (measured from the first step of the run; ``hold_s = 0`` flags at once)."""
    n = len(t)
    idx = np.arange(n)
    starts = deviant & ~np.concatenate(([False], deviant[:-1]))
    run_start = np.maximum.accumulate(np.where(starts, idx, 0)) if n else idx
    return deviant & (t - t[run_start] >= hold_s - _HOLD_EPS_S)


# --- the log ------------------------------------------------------------------


@dataclass
class RelationTrace:
    """One relation observer over all steps (arrays of length m)."""

    relation: RelationConfig
    symbol_a: np.ndarray
    symbol_b: np.ndarray
    valid: np.ndarray
    counter: np.ndarray
    no_match: np.ndarray

    def observation(self, k: int) -> Observation | None:
        if not self.valid[k]:
            return None
        return Observation.NO_MATCH if self.no_match[k] else Observation.MATCH


@dataclass
class UnaryTrace:
    """One unary check over all steps."""

    name: str
    component: str
    valid: np.ndarray
    deviant: np.ndarray
    implausible: np.ndarray

    def plausibility(self, k: int) -> Plausibility | None:
        if not self.valid[k]:
            return None
        return Plausibility.IMPLAUSIBLE if self.implausible[k] else Plausibility.PLAUSIBLE


@dataclass
class ObserverLog:
    """Per-step trends, counters and observations of every observer."""

    t: np.ndarray
    relations: dict[str, RelationTrace]
    unary: dict[str, UnaryTrace]

    def observations(self, k: int) -> dict[str, Observation | Plausibility]:
        """The observations made at step ``k`` (observers without data left out)."""
        out: dict[str, Observation | Plausibility] = {}
        for name, r in self.relations.items():
            if (obs := r.observation(k)) is not None:
                out[name] = obs
        for name, u in self.unary.items():
            if (p := u.plausibility(k)) is not None:
                out[name] = p
        return out

    def columns(self) -> dict[str, np.ndarray]:
        """Flat named columns (for the per-step CSV log)."""
        cols: dict[str, np.ndarray] = {"t": self.t}
        for name, r in self.relations.items():
            cols[f"{name}.trend_a"] = r.symbol_a
            cols[f"{name}.trend_b"] = r.symbol_b
            cols[f"{name}.valid"] = r.valid
            cols[f"{name}.counter"] = r.counter
            cols[f"{name}.no_match"] = r.no_match
        for name, u in self.unary.items():
            cols[f"{name}.valid"] = u.valid
            cols[f"{name}.implausible"] = u.implausible
        return cols


# --- batch ----------------------------------------------------------------------


def _trend_key(relation: RelationConfig, side: int) -> tuple[str, float, float]:
    stream = relation.streams[side]
    return stream, relation.window_s, relation.boundaries[side]


def observe_steps(
    steps: StepStreams, relations: Sequence[RelationConfig], unary: Sequence[UnaryCheck] = ()
) -> ObserverLog:
    """Run every observer over streams already resampled onto the steps."""
    m = len(steps.t)
    missing = np.zeros(m, dtype=bool)
    cache: dict[tuple[str, float, float], np.ndarray] = {}

    def symbols(key: tuple[str, float, float]) -> tuple[np.ndarray, np.ndarray]:
        name, window_s, boundary = key
        if name not in steps.values:
            return np.zeros(m, dtype=np.int8), missing
        valid = steps.valid[name]
        if key not in cache:
            sym = np.zeros(m, dtype=np.int8)
            sym[valid] = trends(
                steps.t[valid], steps.values[name][valid], window_s, boundary, steps.angular[name]
            ).symbol
            cache[key] = sym
        return cache[key], valid

    rel_traces: dict[str, RelationTrace] = {}
    for rel in relations:
        sym_a, valid_a = symbols(_trend_key(rel, 0))
        sym_b, valid_b = symbols(_trend_key(rel, 1))
        valid = held(steps.t, valid_a, rel.warmup) & held(steps.t, valid_b, rel.warmup)
        counter, no_match = compare_trends(sym_a, sym_b, rel.threshold, valid, rel.max_counter)
        rel_traces[rel.name] = RelationTrace(rel, sym_a, sym_b, valid, counter, no_match)
        logger.debug("%s: no_match on %d of %d valid steps", rel.name, int(no_match.sum()), int(valid.sum()))

    unary_traces: dict[str, UnaryTrace] = {}
    for check in unary:
        if not all(s in steps.values for s in check.streams):
            valid = missing
            deviant = np.zeros(m, dtype=bool)
        else:
            valid = np.logical_and.reduce([steps.valid[s] for s in check.streams])
            with np.errstate(invalid="ignore"):
                deviant = valid & check.deviant({s: steps.values[s] for s in check.streams})
        unary_traces[check.name] = UnaryTrace(
            check.name, check.component, valid, deviant, held(steps.t, deviant, check.hold_s)
        )
    return ObserverLog(steps.t, rel_traces, unary_traces)


def observe(
    streams: Mapping[str, Stream],
    relations: Sequence[RelationConfig],
    step_times: np.ndarray,
    unary: Sequence[UnaryCheck] = (),
    max_gap_s: float = 0.5,
    stream_max_gap_s: Mapping[str, float] | None = None,
) -> ObserverLog:
    """Resample ``streams`` onto ``step_times`` (s) and run every observer."""
    steps = resample_streams(streams, step_times, max_gap_s, stream_max_gap_s)
    return observe_steps(steps, relations, unary)


# --- online -----------------------------------------------------------------------


@dataclass(frozen=True)
class StepObservations:
    """What the observers say at one step."""

    t: float
    symbols: dict[str, tuple[Trend, Trend]]
    counters: dict[str, int]
    observations: dict[str, Observation | Plausibility | None]


class ObserverBank:
    """Every observer, one validation step at a time (causal).

    Streams with equal (name, window, boundary) share one trend estimator,
    as in :func:`observe_steps`, whose results this reproduces.
    """

    def __init__(
        self,
        relations: Sequence[RelationConfig],
        unary: Sequence[UnaryCheck] = (),
        angular: Mapping[str, bool] | None = None,
    ) -> None:
        """``angular`` says which streams are angles (default: the yaw streams)."""
        self.relations = tuple(relations)
        self.angular = dict(angular) if angular is not None else {n: n in ANGULAR_STREAMS for n in STREAM_NAMES}
        self.unary = tuple(unary)
        self._estimators: dict[tuple[str, float, float], TrendEstimator] = {}
        self._counters = {r.name: MismatchCounter(r.threshold, r.max_counter) for r in self.relations}
        self._run_start: dict[str, float | None] = {c.name: None for c in self.unary}
        self._present_since: dict[str, float | None] = {s: None for r in self.relations for s in r.streams}

    def update(self, t: float, values: Mapping[str, float | None]) -> StepObservations:
        """Process step ``t`` (s). ``values`` maps a stream to its value at the
        step; a missing, None or NaN value means no data at this step."""

        def present(name: str) -> bool:
            v = values.get(name)
            return v is not None and bool(np.isfinite(v))

        # 1. Trends of every stream with data at this step.
        current: dict[tuple[str, float, float], Trend] = {}
        for rel in self.relations:
            for side in (0, 1):
                key = _trend_key(rel, side)
                if key in current or not present(key[0]):
                    continue
                est = self._estimators.get(key)
                if est is None:
                    est = self._estimators[key] = TrendEstimator(key[1], key[2], self.angular.get(key[0], False))
                current[key] = est.update(t, float(values[key[0]])).symbol

        # 2. Relations (Algorithm 3), once both streams are warm.
        for name, since in self._present_since.items():
            self._present_since[name] = (t if since is None else since) if present(name) else None

        def warm(name: str, warmup_s: float) -> bool:
            since = self._present_since[name]
            return since is not None and t - since >= warmup_s - _HOLD_EPS_S

        symbols, counters, observations = {}, {}, {}
        for rel in self.relations:
            ka, kb = _trend_key(rel, 0), _trend_key(rel, 1)
            valid = warm(ka[0], rel.warmup) and warm(kb[0], rel.warmup)
            sym = (current.get(ka, Trend.ZERO), current.get(kb, Trend.ZERO))
            counter = self._counters[rel.name]
            observations[rel.name] = counter.update(int(sym[0]), int(sym[1]), valid)
            symbols[rel.name] = sym
            counters[rel.name] = counter.counter

        # 3. Unary checks with their hold time.
        for check in self.unary:
            if not all(present(s) for s in check.streams):
                self._run_start[check.name] = None
                observations[check.name] = None
                continue
            if bool(check.deviant({s: float(values[s]) for s in check.streams})):
                start = self._run_start[check.name]
                if start is None:
                    start = self._run_start[check.name] = t
                bad = t - start >= check.hold_s - _HOLD_EPS_S
            else:
                self._run_start[check.name] = None
                bad = False
            observations[check.name] = Plausibility.IMPLAUSIBLE if bad else Plausibility.PLAUSIBLE
        return StepObservations(t, symbols, counters, observations)
