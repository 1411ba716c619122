"""The system model a set of sensors suggests, from physics alone.

The paper leaves open "how models of sensor relations can be obtained in
general" (Section 6). For the streams a robot records, the structure
follows from what each stream measures; only the parameters need data
(``gslam calibrate`` learns them, and drops the relations the data do not
support). :func:`propose_model` writes the structure:

1. **Components**, one per modality as in the paper's Table 1: ``IMU_GYRO``
   (a gyro's yaw rate), ``IMU_YAW`` (a heading: a magnetometer's or an
   orientation estimate's), ``ODO_DIST`` and ``ODO_YAW`` (the odometry's
   distance and turn), ``SM_DIST``, ``SM_LAT``, ``SM_YAW`` (scan matching
   along, across and about the heading), ``GPS``; each further odometry
   source ``vo`` its own ``VO_DIST`` and ``VO_YAW``; ``LOOP`` with a laser.
2. **Sensors** group the modalities of one source (``ODO``, ``SM``, ``VO``):
   one fault that takes all of them (tracks lifted, a blind scan matcher).
3. **Relations**, what physics ties together, each with the observers
   that fit it:

   - *heading change*: every pair of yaw streams of different sensors
     (gyro, compass, every odometry source, scan matching): the paper's
     trend observer and a residual observer of the size of the turns;
     an absolute heading (the compass) against an integrated one also an
     offset observer, which sees a heading that stands off;
   - *travel*: every pair of odometry-like sources (odometry, further
     odometry, scan matching): their forward travel by a trend and a
     residual (not the path length, which a standing scan matcher's jitter
     lengthens); their sideways travel (none on wheels or tracks: two flat
     streams, whose trends would be noise) by a residual;
   - *speed over ground*: the GPS speed against each odometry-like
     source's speed derived the same way (a trend);
   - *absolute heading*: the compass against the GPS course, where the
     course is the heading (an offset with a level of 0; it needs the
     odometry to tell when).
4. **Plausibility checks** where the stream allows them: a magnetometer's
   field strength and dip (and its turn against a gyro's, whose observer is
   off unless enabled), the GPS receiver's sigma, a laser scan's returns and
   geometry, the loop closures' consistency.

A stream that shares its quantity with no other sensor's can be used but
not validated; :attr:`ModelProposal.unvalidated` says which and why, and
:meth:`ModelProposal.nothing_to_validate` why no relation at all is left
(one stream, or streams with no physical relation).

The observers' starting parameters are generic (the sparser stream's
sample period sets the shortest window); ``gslam calibrate`` replaces them.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, Literal

from validation.diagnosis.model import SystemModel
from validation.observers.config import RelationConfig
from validation.streams.names import source_component, source_stream

SourceKind = Literal["gyro", "compass", "odometry", "scan", "gps"]

STEP_PAIR_S = 0.2
"""Windows are whole numbers of this (two steps at the default 10 Hz)."""
MIN_SAMPLES = 4
"""A window holds at least this many samples of its sparser stream."""

# Starting parameters per quantity: (kind, boundary or sigma_floor, sigma_rel, window_s, threshold).
_TREND_YAW = 0.05          # rad/s
_TREND_DISTANCE = 0.1      # m/s
_TREND_SPEED = 0.2         # m/s per s
_RES_YAW = (0.03, 0.05)    # rad, share of the turn
_RES_FORWARD = (0.05, 0.05)
_RES_LATERAL = (0.05, 0.0)
_OFF_YAW = 0.05            # rad about the running level
_OFF_COURSE = 0.2          # rad about 0
_WINDOW_S = 2.0
_SPEED_WINDOW_S = 4.0
_TREND_TH, _QUANT_TH, _HEADROOM = 10, 5, 20

# Prior fault probabilities (they rank ambiguous diagnoses): perception
# fails more often than wheels, a heading near steel or a GPS near walls
# more often than a gyro; a whole sensor less often than one modality.
_PRIORS = {"SM": 0.05, "IMU_YAW": 0.05, "GPS": 0.05, "LOOP": 0.05, "ODO": 0.02, "IMU_GYRO": 0.01}
_SENSOR_PRIORS = {"SM": 0.04, "ODO": 0.01}
_EXTRA_PRIOR = 0.05
_WHOLE_SENSOR = 0.8
"""A further source's whole-sensor prior against one of its modalities'."""


@dataclass(frozen=True)
class Source:
    """One stream of the recording as the proposal sees it.

    ``kind``: gyro, compass, odometry (the odometry or a further source),
    scan or gps. ``name``: its validation prefix (``gyro``, ``compass``,
    ``odo``, ``sm`` for the laser's scan matching, ``gps``, or a further
    odometry source's name). ``origin``: where it comes from, for the
    comments (a topic and type). ``period_s``: its median sample period (s)
    if known. ``magnetometer``: a compass that measures the field (it can be
    checked against the Earth's)."""

    kind: SourceKind
    name: str
    origin: str = ""
    period_s: float | None = None
    magnetometer: bool = False


@dataclass(frozen=True)
class ProposedRelation:
    """An observer and why physics gives it."""

    config: RelationConfig
    why: str


@dataclass
class ModelProposal:
    """The proposed structure (module docstring) and its observers."""

    sources: tuple[Source, ...]
    components: list[str]
    sensors: dict[str, list[str]]
    relations: list[ProposedRelation]
    unary_checks: dict[str, str]
    checks: dict[str, bool]
    """``validation.observers`` checks on or off: magnetometer, gps, scan."""
    priors: dict[str, float]
    gating_factors: dict[str, dict[str, list[str]]]
    unvalidated: list[str] = field(default_factory=list)
    """Streams no relation compares, each with the reason."""

    def model(self) -> SystemModel:
        """The proposal as a checked system model."""
        return SystemModel.model_validate(self.model_mapping())

    def model_mapping(self) -> dict[str, Any]:
        return {
            "components": list(self.components),
            "sensors": {s: list(parts) for s, parts in self.sensors.items()},
            "relations": {r.config.name: list(r.config.components) for r in self.relations},
            "unary_checks": dict(self.unary_checks),
            "fault_propagation": [],
            "failure_masking": [],
            "priors": dict(self.priors),
        }

    def nothing_to_validate(self) -> str | None:
        """Why no relation is proposed (None when there is one)."""
        if self.relations:
            return None
        if not self.sources:
            return "the recording holds no stream the pipeline reads (laser, gyro, compass, odometry, GPS)"
        if len(self.sources) == 1:
            return (f"the recording holds one stream ({_describe(self.sources[0])}{_origin(self.sources[0])}); a "
                    "stream is validated against another that measures the same motion")
        names = ", ".join(f"{_describe(s)}{_origin(s)}" for s in self.sources)
        return f"no two of its streams ({names}) measure the same motion: {'; '.join(self.unvalidated)}"


def _describe(source: Source) -> str:
    """A source in a few words: ``gyro``, ``odometry 'vo'``, ``scan matching``."""
    if source.kind == "odometry":
        return "odometry" if source.name == "odo" else f"odometry '{source.name}'"
    return {"gyro": "gyro", "compass": "compass", "scan": "scan matching", "gps": "GPS"}[source.kind]


def _origin(source: Source) -> str:
    return f" {source.origin}" if source.origin else ""


def _window(base: float, *sources: Source) -> float:
    """``base`` s, or :data:`MIN_SAMPLES` samples of the sparser source,
    rounded up to a whole number of step pairs."""
    periods = [s.period_s for s in sources if s.period_s is not None and math.isfinite(s.period_s)]
    w = max([base, *(MIN_SAMPLES * p for p in periods)])
    return round(math.ceil(w / STEP_PAIR_S - 1e-9) * STEP_PAIR_S, 6)


def _trend(name: str, a: str, b: str, boundary: float, window_s: float) -> RelationConfig:
    return RelationConfig(name=name, stream_a=a, stream_b=b, boundary=boundary, window_s=window_s,
                          threshold=_TREND_TH, max_counter=_TREND_TH + _HEADROOM)


def _residual(name: str, a: str, b: str, noise: tuple[float, float], window_s: float) -> RelationConfig:
    return RelationConfig(name=name, kind="residual", stream_a=a, stream_b=b, sigma_floor=noise[0],
                          sigma_rel=noise[1], window_s=window_s, threshold=_QUANT_TH,
                          max_counter=_QUANT_TH + _HEADROOM)


def _offset(name: str, a: str, b: str, sigma: float, window_s: float, level_window_s: float | None) -> RelationConfig:
    return RelationConfig(name=name, kind="offset", stream_a=a, stream_b=b, sigma_floor=sigma, window_s=window_s,
                          level_window_s=level_window_s, threshold=_QUANT_TH, max_counter=_QUANT_TH + _HEADROOM)


# Name order of a relation's two sides, as the shipped models name them
# (yaw_compass_gyro, yaw_odo_gyro, yaw_gyro_sm, distance_odo_sm).
_NAME_ORDER = {"compass": 0, "odometry": 1, "gyro": 2, "scan": 3, "gps": 4}
# The reference side (stream a) of a residual: the sensor that fails least
# often, by the priors below (its changes set the band, and calibration
# learns from the steps where it moves).
_REFERENCE_ORDER = {"gyro": 0, "odometry": 1, "compass": 2, "scan": 3, "gps": 4}


def _yaw_stream(s: Source) -> str:
    return {"gyro": "gyro_yaw", "compass": "compass_yaw"}.get(s.kind, source_stream(s.name, "yaw"))


def _named(a: Source, b: Source) -> tuple[Source, Source]:
    return (a, b) if (_NAME_ORDER[a.kind], a.name) <= (_NAME_ORDER[b.kind], b.name) else (b, a)


def _referenced(a: Source, b: Source) -> tuple[Source, Source]:
    return (a, b) if (_REFERENCE_ORDER[a.kind], a.name) <= (_REFERENCE_ORDER[b.kind], b.name) else (b, a)


def _heading_relations(yaws: Sequence[Source]) -> list[ProposedRelation]:
    out = []
    for a, b in itertools.combinations(yaws, 2):
        first, second = _named(a, b)
        ref, other = _referenced(a, b)
        name = f"yaw_{first.name}_{second.name}"
        w = _window(_WINDOW_S, a, b)
        turn = f"heading change: {_describe(first)} against {_describe(second)}"
        out.append(ProposedRelation(_trend(name, _yaw_stream(first), _yaw_stream(second), _TREND_YAW, w),
                                    f"{turn} (trends, Algorithm 3)"))
        out.append(ProposedRelation(_residual(f"{name}_res", _yaw_stream(ref), _yaw_stream(other), _RES_YAW, w),
                                    f"{turn}: the size of the turns"))
        if "compass" in (a.kind, b.kind):
            integrated = b if a.kind == "compass" else a
            compass = a if a.kind == "compass" else b
            out.append(ProposedRelation(
                _offset(f"{name}_off", _yaw_stream(integrated), _yaw_stream(compass), _OFF_YAW, w, 60.0),
                f"the compass's heading against the {_describe(integrated)}'s integrated turns: a heading that "
                "stands off"))
    return out


def _travel_relations(movers: Sequence[Source]) -> list[ProposedRelation]:
    out = []
    for a, b in itertools.combinations(movers, 2):
        first, second = _named(a, b)
        ref, other = _referenced(first, second)
        w = _window(_WINDOW_S, a, b)
        pair = f"{_describe(first)} against {_describe(second)}"
        s = lambda src, q: source_stream(src.name, q)  # noqa: E731
        out += [
            ProposedRelation(_trend(f"distance_{first.name}_{second.name}", s(first, "forward"),
                                    s(second, "forward"), _TREND_DISTANCE, w), f"forward travel: {pair} (trends)"),
            ProposedRelation(_residual(f"distance_{first.name}_{second.name}_res", s(ref, "forward"),
                                       s(other, "forward"), _RES_FORWARD, w), f"forward travel: {pair}, its size"),
            # Sideways travel stays flat on wheels and tracks: a trend would compare the
            # symbols of two noises, so only its size is watched.
            ProposedRelation(_residual(f"lateral_{first.name}_{second.name}_res", s(ref, "lateral"),
                                       s(other, "lateral"), _RES_LATERAL, w),
                             f"sideways travel (none on wheels or tracks): {pair}"),
        ]
    return out


def _gps_relations(gps: Source, movers: Sequence[Source], compass: Source | None,
                   odometry: Source | None) -> list[ProposedRelation]:
    out = []
    for m in movers:
        w = _window(_SPEED_WINDOW_S, gps, m)
        out.append(ProposedRelation(
            _trend(f"speed_gps_{m.name}", "gps_speed", source_stream(m.name, "fix_speed"), _TREND_SPEED, w),
            f"speed over ground: GPS against {_describe(m)}, derived alike"))
    if compass is not None and odometry is not None:
        w = _window(_SPEED_WINDOW_S, gps, compass)
        out.append(ProposedRelation(
            _offset("yaw_compass_gps", "gps_course", "compass_yaw", _OFF_COURSE, w, None),
            "absolute heading: compass against the GPS course, where the odometry says the course is the heading"))
    return out


def propose_model(sources: Sequence[Source]) -> ModelProposal:
    """The model of the module docstring for ``sources``."""
    sources = tuple(sources)
    kinds = {s.kind: s for s in sources}
    gyro, compass, scan, gps = (kinds.get(k) for k in ("gyro", "compass", "scan", "gps"))
    odometries = [s for s in sources if s.kind == "odometry"]
    main = next((s for s in odometries if s.name == "odo"), None)
    movers = [*odometries, *([scan] if scan is not None else [])]
    yaws = [s for s in (compass, *odometries, gyro, scan) if s is not None]

    components: list[str] = []
    sensors: dict[str, list[str]] = {}
    priors: dict[str, float] = {}
    for src in movers:
        sensor = source_component(src.name)
        parts = [f"{sensor}_DIST", f"{sensor}_LAT", f"{sensor}_YAW"] if src.kind == "scan" else [
            f"{sensor}_DIST", f"{sensor}_YAW"]
        components += [*parts, sensor]
        sensors[sensor] = parts
        p = _PRIORS.get(sensor, _EXTRA_PRIOR)
        priors.update({part: p for part in parts})
        priors[sensor] = _SENSOR_PRIORS.get(sensor, round(_WHOLE_SENSOR * p, 4))
    if gyro is not None:
        components.append("IMU_GYRO")
        priors["IMU_GYRO"] = _PRIORS["IMU_GYRO"]
    if compass is not None:
        components.append("IMU_YAW")
        priors["IMU_YAW"] = _PRIORS["IMU_YAW"]
    if gps is not None:
        components.append("GPS")
        priors["GPS"] = _PRIORS["GPS"]

    relations = _heading_relations(yaws) + _travel_relations(movers)
    if gps is not None:
        relations += _gps_relations(gps, movers, compass, main)

    unary: dict[str, str] = {}
    checks = {"magnetometer": False, "gps": False, "scan": False}
    if compass is not None and compass.magnetometer:
        unary["mag_plausible"] = "IMU_YAW"
        checks["magnetometer"] = True
        if gyro is not None:  # its observer (observers.field_gyro) is off unless enabled
            unary["mag_field_gyro"] = "IMU_YAW"
    if gps is not None:
        unary["gps_plausible"] = "GPS"
        checks["gps"] = True
    if scan is not None:
        for axis, comp in (("dist", "SM_DIST"), ("lat", "SM_LAT"), ("yaw", "SM_YAW")):
            unary[f"scan_degenerate_{axis}"] = comp
        checks["scan"] = True
        components.append("LOOP")
        unary["loop_consistency"] = "LOOP"
        priors["LOOP"] = _PRIORS["LOOP"]

    compared = {c for r in relations for c in r.config.components}
    unvalidated = [f"{_describe(s)}: {_why_alone(s, sources)}" for s in sources
                   if not (_own_components(s) & compared)]
    return ModelProposal(sources, components, sensors, relations, unary, checks, priors,
                         _gating_factors(sources), unvalidated)


def _own_components(source: Source) -> set[str]:
    if source.kind in ("odometry", "scan"):
        sensor = source_component(source.name)
        return {f"{sensor}_DIST", f"{sensor}_LAT", f"{sensor}_YAW"}
    return {{"gyro": "IMU_GYRO", "compass": "IMU_YAW", "gps": "GPS"}[source.kind]}


def _why_alone(source: Source, sources: Sequence[Source]) -> str:
    if source.kind == "gps":
        return "GPS speed needs an odometry or a laser beside it, its course a compass and an odometry"
    if source.kind == "compass":
        return "a heading needs a gyro, an odometry, a laser or GPS with an odometry beside it"
    if source.kind == "gyro":
        return "a gyro's turns need a heading, an odometry or a laser beside them"
    return "its motion needs another odometry, a laser, a gyro or a compass beside it"


def _gating_factors(sources: Sequence[Source]) -> dict[str, dict[str, list[str]]]:
    """The components each factor type's degrees of freedom depend on, for
    the factor types the sources feed (further odometry sources are no
    factor of the graph)."""
    kinds = {s.kind for s in sources}
    names = {s.name for s in sources}
    out: dict[str, dict[str, list[str]]] = {}
    if "odo" in names:
        out["odometry"] = {"x": ["ODO_DIST", "ODO"], "y": ["ODO_DIST", "ODO"], "yaw": ["ODO_YAW", "ODO"]}
    if "gyro" in kinds:
        out["gyro"] = {"yaw": ["IMU_GYRO"]}
    if "compass" in kinds:
        out["compass"] = {"yaw": ["IMU_YAW"]}
    if "scan" in kinds:
        out["scan_matching"] = {"x": ["SM_DIST", "SM"], "y": ["SM_LAT", "SM"], "yaw": ["SM_YAW", "SM"]}
    if "gps" in kinds:
        out["gps"] = {"x": ["GPS"], "y": ["GPS"]}
    return out


__all__ = ["ModelProposal", "ProposedRelation", "Source", "propose_model"]
