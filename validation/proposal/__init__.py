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

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

from validation.diagnosis.model import SystemModel
from validation.proposal.relations import (ProposedRelation, Source, describe, gps_relations, heading_relations,
                                           travel_relations)
from validation.streams.names import source_component

# Prior fault probabilities (they rank ambiguous diagnoses): perception
# fails more often than wheels, a heading near steel or a GPS near walls
# more often than a gyro; a whole sensor less often than one modality.
_PRIORS = {"SM": 0.05, "IMU_YAW": 0.05, "GPS": 0.05, "LOOP": 0.05, "ODO": 0.02, "IMU_GYRO": 0.01}
_SENSOR_PRIORS = {"SM": 0.04, "ODO": 0.01}
_EXTRA_PRIOR = 0.05
_WHOLE_SENSOR = 0.8
"""A further source's whole-sensor prior against one of its modalities'."""


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
            return (f"the recording holds one stream ({describe(self.sources[0])}{_origin(self.sources[0])}); a "
                    "stream is validated against another that measures the same motion")
        names = ", ".join(f"{describe(s)}{_origin(s)}" for s in self.sources)
        return f"no two of its streams ({names}) measure the same motion: {'; '.join(self.unvalidated)}"


def _origin(source: Source) -> str:
    return f" {source.origin}" if source.origin else ""


def propose_model(sources: Sequence[Source], loops: bool = False) -> ModelProposal:
    """The model of the module docstring for ``sources``; ``loops``: the
    config closes loops, so LOOP and its check stand in the model even
    without a laser (a loop list, or a later recording with one)."""
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

    relations = heading_relations(yaws) + travel_relations(movers)
    if gps is not None:
        relations += gps_relations(gps, movers, compass, main)

    unary: dict[str, str] = {}
    checks = {"magnetometer": False, "gps": False, "scan": False, "scan_ceiling": False}
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
        unary["scan_ceiling"] = "SM"
        checks["scan"] = checks["scan_ceiling"] = True
    if scan is not None or loops:
        components.append("LOOP")
        unary["loop_consistency"] = "LOOP"
        priors["LOOP"] = _PRIORS["LOOP"]

    compared = {c for r in relations for c in r.config.components}
    unvalidated = [f"{describe(s)}: {_why_alone(s, sources)}" for s in sources
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
