"""Typed scenario description of a simulated run, loaded from YAML.

A scenario has five parts: the ``world`` (walls, doors, obstacles, labelled
regions, magnetic disturbers), the ``robot`` (waypoints and motion limits),
the ``sensors`` (rate and noise of each), the ``environment`` (Earth field,
GPS datum, start time) and the ``faults`` thresholds that turn the physics
into true fault intervals. Every model forbids unknown keys, so a typo is an
error naming the file and the key. Coordinates are metres in the ENU world
frame (x east, y north); angles in the YAML are degrees (keys say ``_deg``).
"""

from __future__ import annotations

import math
from enum import Enum
from pathlib import Path
from typing import Annotated

import yaml
from pydantic import Field, ValidationError, field_validator, model_validator

from slam.config import describe_validation_error
from slam.results.records import PLAIN_NAME, PLAIN_NAME_RULE
from slam.config.trees import check_finite
from slam.readers.data_checks import MIN_BEAM_STEP_RAD
from validation.base.yamlio import load_yaml
from slam.errors import GslamError
from validation.base import bounds
from validation.base.bounds import within
from validation.base.yamlio import Strict

MAX_COORDINATE_M = 1e6
"""How far from the origin of its ENU frame a scenario's world reaches (m): a
site, not a continent (and the squares of 1e300 m overflow)."""
Coordinate_m = Annotated[float, within(-MAX_COORDINATE_M, MAX_COORDINATE_M, "m", "a scenario's world is a site "
                                       "within 1000 km of its origin", "a scenario's world is a site within 1000 km "
                                       "of its origin")]
Point = tuple[Coordinate_m, Coordinate_m]
Polyline = Annotated[list[Point], Field(min_length=2)]
Polygon = Annotated[list[Point], Field(min_length=3)]


# --- world ---------------------------------------------------------------


class RegionKind(str, Enum):
    """Whether a region is under a roof (no GPS) or in the open."""

    INDOOR = "indoor"
    OUTDOOR = "outdoor"


class Door(Strict):
    """An opening cut into every wall segment that passes through ``center``."""

    center: Point
    width_m: Annotated[float, within(None, 100.0, "m", high="a door that wide is no door: it cuts every wall it "
                                     "passes through")] = Field(gt=0.0)


class Region(Strict):
    """A labelled area; ``slip`` is the terrain's track slip fraction."""

    name: str
    kind: RegionKind
    polygon: list[Point] = Field(min_length=3)
    slip: float = Field(0.02, ge=0.0, lt=1.0)


class Disturber(Strict):
    """A magnetic dipole (a steel structure). ``position`` is (x, y, z) m with
    z the height of the dipole's centre; ``direction`` is the moment's axis
    in the world frame (normalised on load)."""

    name: str
    position: tuple[Coordinate_m, Coordinate_m, Coordinate_m]
    moment_A_m2: bounds.DipoleMoment_A_m2 = Field(gt=0.0)
    direction: tuple[Annotated[float, bounds.AXIS_COMPONENT], Annotated[float, bounds.AXIS_COMPONENT],
                     Annotated[float, bounds.AXIS_COMPONENT]] = (0.0, 0.0, 1.0)

    @field_validator("direction")
    @classmethod
    def _nonzero(cls, v: tuple[float, float, float]) -> tuple[float, float, float]:
        if sum(c * c for c in v) == 0.0:
            raise ValueError("direction must not be the zero vector")
        return v


class WorldConfig(Strict):
    """Walls are open polylines (each consecutive pair of points a segment);
    obstacles are closed polygons. Anything outside every region is
    ``default_region``."""

    walls: list[Polyline] = Field(default_factory=list)
    doors: list[Door] = Field(default_factory=list)
    obstacles: list[Polygon] = Field(default_factory=list)
    regions: list[Region] = Field(default_factory=list)
    default_region: Region = Region(
        name="open", kind=RegionKind.OUTDOOR, polygon=[(0, 0), (1, 0), (0, 1)], slip=0.03
    )
    disturbers: list[Disturber] = Field(default_factory=list)

    @model_validator(mode="after")
    def _shapes(self) -> "WorldConfig":
        """What the simulator would use in silence as nothing: an obstacle or
        a region of no area, a region whose name another one holds (the
        laser and the slip would be of either). A door that cuts no wall is
        refused by :func:`slam.sim.budget.check_doors`, once the cost of
        cutting is known to be bounded."""
        for i, poly in enumerate(self.obstacles):
            if _area(poly) == 0.0:
                raise ValueError(f"obstacles.{i}: its points enclose no area; the laser would see a line or "
                                 "a point, not an obstacle (give its corners in order round it)")
        named: dict[str, str] = {}
        for where, region in [*((f"regions.{i}", r) for i, r in enumerate(self.regions)),
                              ("default_region", self.default_region)]:
            if where != "default_region" and _area(region.polygon) == 0.0:
                raise ValueError(f"{where}.polygon: its points enclose no area; no point of the route lies in it")
            if region.name in named:
                raise ValueError(f"{where}.name: {region.name!r} names {named[region.name]} too; give each region "
                                 "a name of its own")
            named[region.name] = where
        return self


def _area(polygon: list[Point]) -> float:
    """The area a polygon's points enclose (shoelace; m^2)."""
    return abs(sum(x0 * y1 - x1 * y0 for (x0, y0), (x1, y1) in zip(polygon, polygon[1:] + polygon[:1]))) / 2.0


# --- robot ---------------------------------------------------------------

MAX_SPEED_M_S = 50.0
"""The fastest a simulated robot drives, on any leg (m/s)."""


class RobotConfig(Strict):
    """A tracked vehicle driving through ``waypoints``: ``[x, y]``,
    ``[x, y, pause_s]`` (wait there) or ``[x, y, pause_s, max_speed_m_s]``
    (a lower or higher speed limit on the leg that ends there; default
    ``max_speed_m_s``). Corners sharper than ``spot_turn_above_deg`` are
    turned on the spot, the others on arcs of ``corner_radius_m``."""

    start_yaw_deg: bounds.Azimuth_deg = 0.0
    waypoints: list[
        tuple[float, float] | tuple[float, float, float] | tuple[float, float, float, float]
    ] = Field(min_length=2)
    # What a ground robot can do: the fastest drive at tens of m/s and brake
    # at about 1 g; none turns faster than a gyro measures.
    max_speed_m_s: Annotated[float, within(None, MAX_SPEED_M_S, "m/s", high="no ground robot drives at 180 km/h")] = Field(
        0.5, gt=0.0)
    max_accel_m_s2: Annotated[float, within(None, 100.0, "m/s^2", high="ten times gravity: no ground robot's "
                                            "wheels or tracks grip that")] = Field(0.3, gt=0.0)
    max_turn_rate_deg_s: Annotated[float, within(None, 2000.0, "deg/s", high="beyond any gyro's measuring range "
                                                 "(2000 deg/s)")] = Field(30.0, gt=0.0)
    max_turn_accel_deg_s2: Annotated[float, within(None, 1e5, "deg/s^2", high="full turn rate in a fiftieth of a "
                                                   "second: no robot's drive does that")] = Field(60.0, gt=0.0)
    corner_radius_m: Annotated[float, within(None, 1000.0, "m", high="a corner a kilometre round is no corner of "
                                             "a ground robot's route")] = Field(1.0, ge=0.0)
    spot_turn_above_deg: float = Field(100.0, ge=0.0, le=180.0)
    start_pause_s: Annotated[float, bounds.PAUSE_S] = Field(1.0, ge=0.0)
    end_pause_s: Annotated[float, bounds.PAUSE_S] = Field(1.0, ge=0.0)
    truth_rate_hz: bounds.Rate_hz = Field(100.0, ge=100.0)
    laps: Annotated[int, bounds.LAPS] = 1

    @field_validator("waypoints")
    @classmethod
    def _pauses_nonnegative(cls, v: list[tuple[float, ...]]) -> list[tuple[float, ...]]:
        if any(len(w) >= 3 and w[2] < 0.0 for w in v):
            raise ValueError("a waypoint's pause (third value, s) must be >= 0")
        if any(len(w) == 4 and not w[3] > 0.0 for w in v):
            raise ValueError("a waypoint's leg speed (fourth value, m/s) must be > 0")
        for i, w in enumerate(v):
            if max(abs(w[0]), abs(w[1])) > MAX_COORDINATE_M:
                raise ValueError(f"waypoint {i} at ({w[0]:g}, {w[1]:g}) m lies beyond {MAX_COORDINATE_M:g} m of the "
                                 "origin: a scenario's world is a site within 1000 km of its origin")
            if len(w) >= 3 and w[2] > bounds.MAX_MISSION_S:
                raise ValueError(f"waypoint {i}'s pause (third value) {bounds.shown_beside(w[2], bounds.MAX_MISSION_S)} s "
                                 f"is above {bounds.MAX_MISSION_S:g} s: a robot standing still that long outlasts the "
                                 "longest mission simulated (4 h)")
            if len(w) == 4 and w[3] > MAX_SPEED_M_S:
                raise ValueError(f"waypoint {i}'s leg speed (fourth value) {bounds.shown_beside(w[3], MAX_SPEED_M_S)} m/s "
                                 f"is above {MAX_SPEED_M_S:g} m/s: no ground robot drives at 180 km/h")
        return v

    @model_validator(mode="after")
    def _laps_close_the_loop(self) -> "RobotConfig":
        if self.laps > 1 and tuple(self.waypoints[0][:2]) != tuple(self.waypoints[-1][:2]):
            raise ValueError("laps > 1 needs a closed path: the last waypoint must equal the first")
        return self

    def path(self) -> list[tuple[float, ...]]:
        """The waypoints of the whole run: the closed path driven ``laps`` times."""
        return list(self.waypoints) + list(self.waypoints[1:]) * (self.laps - 1)


# --- sensors -------------------------------------------------------------


class LaserConfig(Strict):
    rate_hz: bounds.Rate_hz = Field(10.0, gt=0.0)
    beams: bounds.Count = Field(541, ge=2)
    fov_deg: float = Field(270.0, gt=0.0, le=360.0)
    min_range_m: bounds.LaserRange_m = Field(0.1, ge=0.0)
    max_range_m: bounds.LaserRange_m = Field(10.0, gt=0.0)
    # A 2D laser ranges to 1-3 cm; a metre is no laser's noise.
    range_noise_m: Annotated[float, within(None, 1.0, "m", high="no laser ranges that noisily")] = Field(0.01, ge=0.0)

    @model_validator(mode="after")
    def _range_window(self) -> "LaserConfig":
        if self.min_range_m >= self.max_range_m:
            raise ValueError(f"min_range_m {self.min_range_m:g} is not below max_range_m {self.max_range_m:g}: "
                             "the laser would return nothing")
        # The same bound as on a recorded laser (slam.readers.data_checks): a
        # simulated run must read back as a recording does.
        step = self.fov_deg / (self.beams - 1)
        if step < math.degrees(MIN_BEAM_STEP_RAD):
            raise ValueError(f"fov_deg {self.fov_deg:g} over beams {self.beams} puts the beams {step:.3g} deg apart; "
                             "no 2D laser resolves a thousandth of a degree")
        return self


class GyroConfig(Strict):
    """z-rate with white noise (per sample) and a bias random walk."""

    rate_hz: bounds.Rate_hz = Field(100.0, gt=0.0)
    # The worst MEMS gyros are off by a few deg/s (0.05 rad/s) and noisy by
    # a tenth of that per sample: ten times more is no gyro that works.
    noise_rad_s: Annotated[float, within(None, 1.0, "rad/s", high="no gyroscope is that noisy")] = Field(0.002, ge=0.0)
    bias_initial_rad_s: Annotated[float, within(-0.5, 0.5, "rad/s", "no gyroscope's bias is 30 deg/s",
                                                "no gyroscope's bias is 30 deg/s")] = 0.0
    bias_walk_rad_s_sqrt_s: Annotated[float, within(None, 0.05, "rad/s/sqrt(s)", high="the bias would walk beyond "
                                                    "0.5 rad/s in 100 s: no gyroscope's bias is 30 deg/s")] = Field(
        2e-5, ge=0.0)


class MagnetometerConfig(Strict):
    rate_hz: bounds.Rate_hz = Field(20.0, gt=0.0)
    noise_T: Annotated[float, within(None, 1e-4, "T", high="noise twice the Earth's field: no magnetometer that "
                                     "works")] = Field(2e-7, ge=0.0)
    mounting_height_m: Annotated[float, within(None, 10.0, "m", high="no ground robot carries its magnetometer "
                                               "that high")] = Field(0.3, ge=0.0)


class OdometryConfig(Strict):
    """Track odometry. The reported distance is scaled by
    ``1 + distance_scale_error + slip``, the reported rotation by
    ``1 + rotation_overreport + slip``, where ``slip`` is the terrain's slip
    plus ``turn_slip_per_rad_s`` times the true turn rate."""

    rate_hz: bounds.Rate_hz = Field(20.0, gt=0.0)
    # A wheel's or track's radius is known to a few percent; tracks on a
    # spot turn report up to about twice the true turn. -1 and below would
    # report no motion, or motion backwards.
    distance_scale_error: Annotated[float, within(-0.5, 0.5, "", "the odometry would report less than half the "
                                                  "distance driven", "the odometry would report more than 1.5 times "
                                                  "the distance driven")] = 0.005
    rotation_overreport: Annotated[float, within(-0.5, 1.0, "", "the odometry would report less than half the turn",
                                                 "the odometry would report more than twice the turn")] = 0.0
    turn_slip_per_rad_s: Annotated[float, within(None, 1.0, "s/rad", high="a turn of 1 rad/s would slip by more "
                                                 "than the whole motion")] = Field(0.05, ge=0.0)
    # Noise of half the motion over each metre or radian is no odometry.
    distance_noise_m_sqrt_m: Annotated[float, within(None, 0.5, "m/sqrt(m)", high="no odometry is that noisy")] = Field(
        0.005, ge=0.0)
    yaw_noise_rad_sqrt_rad: Annotated[float, within(None, 0.5, "rad/sqrt(rad)", high="no odometry is that noisy")] = Field(
        0.005, ge=0.0)


class GpsConfig(Strict):
    """Fixes only in the open and farther than ``outage_distance_m`` from an
    indoor region. Multipath adds a bias away from the nearest wall of
    ``multipath_max_m * exp(-d / multipath_scale_m)`` at wall distance d."""

    rate_hz: bounds.Rate_hz = Field(5.0, gt=0.0)
    sigma_m: bounds.Sigma_m = Field(1.0, gt=0.0)
    outage_distance_m: Annotated[float, within(None, 1000.0, "m", high="a roof does not shade a fix a kilometre "
                                               "away")] = Field(2.0, ge=0.0)
    multipath_max_m: bounds.Multipath_m = Field(6.0, ge=0.0)
    multipath_scale_m: Annotated[float, within(1e-2, 1000.0, "m", "a reflection felt only within a centimetre of "
                                               "the wall", "a reflection felt a kilometre from the wall")] = Field(
        4.0, gt=0.0)
    altitude_m: Annotated[float, within(-1000.0, 10_000.0, "m", "below the lowest land (the Dead Sea, -430 m)",
                                        "above the highest (Everest, 8849 m)")] = 115.0


class SensorsConfig(Strict):
    laser: LaserConfig = LaserConfig()
    gyro: GyroConfig = GyroConfig()
    magnetometer: MagnetometerConfig = MagnetometerConfig()
    odometry: OdometryConfig = OdometryConfig()
    gps: GpsConfig = GpsConfig()


# --- environment and faults ------------------------------------------------


class EnvironmentConfig(Strict):
    """Undisturbed Earth field, GPS datum and absolute start time."""

    field_strength_T: Annotated[float, bounds.EARTH_FIELD_T] = Field(48e-6, gt=0.0)
    dip_deg: float = Field(64.0, ge=-90.0, le=90.0)
    declination_deg: Annotated[float, within(-180.0, 180.0, "deg", "a declination is at most half a turn west",
                                             "a declination is at most half a turn east")] = 3.0
    datum_lat_deg: float = Field(49.0, ge=-90.0, le=90.0)
    datum_lon_deg: float = Field(8.4, ge=-180.0, le=180.0)
    t0_s: float = Field(1_700_000_000.0, ge=0.0, le=2_000_000_000.0)
    """Seconds since 1970, within 0 to 2e9 (1970 to 2033), so that the
    mission's stamps stay within what a ROS 2 time and a bag's log time hold
    (1970 to 2038; see :data:`slam.readers.data_checks.MIN_STAMP_S`)."""


class FaultsConfig(Strict):
    """Thresholds that define the true fault intervals (see
    :mod:`slam.sim.faults`)."""

    compass_error_deg: bounds.HeadingError_deg = Field(5.0, gt=0.0)
    sm_min_returns: bounds.Count = Field(20, ge=3)
    sm_min_eigenvalue: bounds.ScanMinEigenvalue = Field(0.03, ge=0.0)
    odo_slip: bounds.SlipFraction = Field(0.12, gt=0.0)
    gyro_bias_rad_s: Annotated[float, within(1e-5, 35.0, "rad/s", "below any gyroscope's noise: every sample would "
                                             "be a fault", "beyond any gyro's measuring range (2000 deg/s): nothing "
                                             "would be a fault")] = Field(0.01, gt=0.0)
    gps_sigmas: bounds.KSigma = Field(3.0, gt=0.0)
    min_duration_s: Annotated[float, bounds.SPAN_S] = Field(0.5, ge=0.0)
    merge_gap_s: Annotated[float, bounds.SPAN_S] = Field(0.5, ge=0.0)


class Scenario(Strict):
    """Root of a scenario YAML (e.g. ``configs/scenarios/telemax_lab.yaml``)."""

    name: str
    seed: Annotated[int, bounds.SEED] = 0
    world: WorldConfig = WorldConfig()
    robot: RobotConfig
    sensors: SensorsConfig = SensorsConfig()
    environment: EnvironmentConfig = EnvironmentConfig()
    faults: FaultsConfig = FaultsConfig()

    @field_validator("name")
    @classmethod
    def _plain_name(cls, name: str) -> str:
        if not PLAIN_NAME.fullmatch(name):
            raise ValueError(f"{name!r}: a scenario's name names its run folders: {PLAIN_NAME_RULE}")
        return name


def load_scenario(path: str | Path) -> Scenario:
    """Read and validate a scenario YAML; bad input raises :class:`GslamError`
    with one line naming the file and the offending key."""
    tree = load_yaml(path, "scenario")
    if not tree:
        raise GslamError(f"{path}: empty; a scenario needs at least 'name' and 'robot' "
                         "(configs/scenarios/telemax_lab.yaml is an example)")
    return validate_scenario(tree, str(path))


def validate_scenario(tree: dict, source: str) -> Scenario:
    """A scenario from a YAML tree; one-line :class:`GslamError` naming
    ``source`` and the key (NaN and infinite numbers included)."""
    check_finite(tree, source)
    try:
        return Scenario.model_validate(tree)
    except ValidationError as e:
        raise GslamError(describe_validation_error(source, e, "scenario", model=Scenario)) from None


def dump_scenario(scenario: Scenario) -> str:
    """The scenario as YAML, every default spelled out."""
    return yaml.safe_dump(scenario.model_dump(mode="json"), sort_keys=False)
