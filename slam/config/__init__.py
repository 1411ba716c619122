"""Typed pipeline configuration, loaded from YAML.

One model per component, nested under :class:`PipelineConfig`; every model
forbids unknown keys, so a typo in a config or an override is an error and
never silently runs the default, and every number must be finite. Angles
are in degrees only where a key says ``_deg``; the code converts them at the
edge.

Loading checks the whole config before anything runs and reports the first
problem in one line, naming the file (or the ``--set KEY=VALUE`` that caused
it) and the key. The loaded config holds the ``validation`` and ``gating``
sections in their checked, fully defaulted form, so :func:`dump_config`
writes a YAML that loads back to an equal config.
"""

from __future__ import annotations

import logging
import re
from collections.abc import Sequence
from pathlib import Path
from typing import Annotated, Any, Literal

import yaml
from pydantic import BaseModel, Field, ValidationError, field_validator, model_validator

from slam.errors import GslamError
from validation.base.errors import InputError
from slam.config.loops import LoopsConfig
from slam.config.submaps import SubmapsConfig
from slam.config.trees import check_finite, non_finite, yaml_number
from validation.base.yamlio import DuplicateKey, UniqueKeyLoader, did_you_mean, load_yaml
from validation.base import bounds
from validation.base.modes import GatingMode
from validation.base.yamlio import Strict

__all__ = [  # the YAML helpers are used through this module too
    "PipelineConfig", "check_finite", "check_given_once", "config_files", "describe_validation_error", "dump_config",
    "load_config", "non_finite", "parse_override", "validation_sections", "yaml_number",
]

log = logging.getLogger(__name__)


# --- input ---------------------------------------------------------------


class TopicsConfig(Strict):
    """Topic of each stream in the bag; null means the stream is not used."""

    scan: str | None = "/scan"
    gyro: str | None = "/imu/data"
    compass: str | None = "/imu/mag"
    odometry: str | None = "/odom"
    gps: str | None = "/gps/fix"
    groundtruth: str | None = "/ground_truth"


class CompassInputConfig(Strict):
    """How a heading is made from the compass topic.

    ``magnetic_field``: sensor_msgs/MagneticField, heading of a level robot.
    ``imu_orientation``: the yaw of a sensor_msgs/Imu orientation estimate.
    """

    source: Literal["magnetic_field", "imu_orientation"] = "magnetic_field"
    declination_deg: float = Field(0.0, ge=-180.0, le=180.0)
    mounting_yaw_deg: float = Field(0.0, ge=-360.0, le=360.0)


class GpsInputConfig(Strict):
    """Datum of the local frame; null takes the first fix."""

    datum_lat_deg: float | None = Field(None, ge=-90.0, le=90.0)
    datum_lon_deg: float | None = Field(None, ge=-180.0, le=180.0)


class GyroInputConfig(Strict):
    """Which rate of a sensor_msgs/Imu is the yaw rate.

    ``z``: ``angular_velocity.z``, for an IMU mounted level (body z vertical).
    ``x``, ``y``: that body axis's rate, for an IMU mounted on its side (the
    sign as ``input.frames.gyro`` says). ``world_z``: the angular velocity
    rotated into the world by the message's orientation quaternion, its
    vertical component: the yaw rate of an IMU mounted tilted or rolled (the
    orientation must be valid).
    """

    axis: Literal["z", "x", "y", "world_z"] = "z"


class StreamFrameConfig(Strict):
    """The frame conventions of one stream of a bag; the reader turns them
    into the project's (ENU world, REP-103 body; :mod:`slam.recording`).

    ``world``: ``enu`` (REP-103: x east, y north, z up; headings
    counter-clockwise from east) or ``ned`` (x north, y east, z down;
    headings clockwise from north). A planar frame with x north and y east
    is ``ned``. ``body``: ``flu`` (REP-103: x forward, y left, z up) or
    ``frd`` (x forward, y right, z down): the sign of a rate about the body
    axis, and of a magnetometer's y and z. ``yaw_sign``: -1 mirrors the
    stream once more (headings and yaw rates the other way round, y of a
    pose negated), for a source whose turns come out reversed in the frame
    stated. Details in :mod:`slam.readers.frames`.
    """

    world: Literal["enu", "ned"] = "enu"
    body: Literal["flu", "frd"] = "flu"
    yaw_sign: Literal[1, -1] = 1


class FramesConfig(Strict):
    """Frame conventions per stream of a bag (``input.frames``). GPS fixes
    are latitude and longitude: they always become ENU and need no entry."""

    odometry: StreamFrameConfig = StreamFrameConfig()
    gyro: StreamFrameConfig = StreamFrameConfig()
    compass: StreamFrameConfig = StreamFrameConfig()
    groundtruth: StreamFrameConfig = StreamFrameConfig()

    def is_default(self) -> bool:
        return self == FramesConfig()


class TimeOffsetsConfig(Strict):
    """Seconds added to each stream's stamps when the recording is read
    (``input.time_offsets_s``): stamp + offset = the time the sample was
    taken. A stream stamped 0.1 s early (its turns show 0.1 s before the
    gyro's) gets +0.1; one stamped late gets a negative offset.
    ``gslam calibrate`` measures the yaw streams' offsets against the gyro."""

    scan: Annotated[float, bounds.TIME_OFFSET_S] = 0.0
    gyro: Annotated[float, bounds.TIME_OFFSET_S] = 0.0
    compass: Annotated[float, bounds.TIME_OFFSET_S] = 0.0
    odometry: Annotated[float, bounds.TIME_OFFSET_S] = 0.0
    gps: Annotated[float, bounds.TIME_OFFSET_S] = 0.0
    groundtruth: Annotated[float, bounds.TIME_OFFSET_S] = 0.0

    def shifted(self) -> dict[str, float]:
        """The streams with a non-zero offset."""
        return {name: value for name, value in self.model_dump().items() if value != 0.0}


class ExtraOdometryConfig(Strict):
    """A further odometry source (``input.extra_odometry.NAME``): a visual
    odometry, a lidar odometry, a second wheel odometry. nav_msgs/Odometry
    on ``topic`` (ROS bags), in the frame conventions ``frame``, its stamps
    moved by ``time_offset_s`` as ``time_offsets_s`` moves the others'.

    Validation compares it with the other sensors as a sensor of its own:
    streams ``NAME_yaw``, ``NAME_forward``, ... and components
    ``NAME_YAW``, ``NAME_DIST`` (upper case; :mod:`validation.streams.names`).
    It is a witness: the graph fuses ``topics.odometry`` only. A fused
    estimate (robot_localization's ``odometry/filtered``) is no witness of
    the sensors it fuses."""

    topic: str
    frame: StreamFrameConfig = StreamFrameConfig()
    time_offset_s: Annotated[float, bounds.TIME_OFFSET_S] = 0.0


class InputConfig(Strict):
    """``format``: ``auto`` guesses the reader from the path (ROS 1 ``.bag``,
    ROS 2 bag folder, simulated run folder, CARMEN ``.log``/``.log.gz``,
    BROAD ``.mat``, libRSF ``*_Input.txt``). ``frames``: the frame
    conventions of a bag's streams (the other formats have fixed ones).
    ``time_offsets_s``: per stream, seconds added to its stamps (any format).
    ``extra_odometry``: further odometry sources by name (ROS bags)."""

    format: Literal["auto", "rosbag", "carmen", "broad", "librsf"] = "auto"
    topics: TopicsConfig = TopicsConfig()
    gyro: GyroInputConfig = GyroInputConfig()
    compass: CompassInputConfig = CompassInputConfig()
    gps: GpsInputConfig = GpsInputConfig()
    frames: FramesConfig = FramesConfig()
    time_offsets_s: TimeOffsetsConfig = TimeOffsetsConfig()
    extra_odometry: dict[str, ExtraOdometryConfig] = Field(default_factory=dict)

    @field_validator("extra_odometry")
    @classmethod
    def _source_names(cls, value: dict[str, ExtraOdometryConfig]) -> dict[str, ExtraOdometryConfig]:
        from validation.streams.names import check_source_name

        for name in value:
            check_source_name(name)
        return value


# --- front-end -----------------------------------------------------------


class FrontendConfig(Strict):
    """KISS-ICP on 2D scans (points at z = 0).

    ``initial_guess``: ``constant_velocity`` is KISS-ICP's own prediction;
    ``odometry`` starts each registration from the odometry step instead,
    which sparse, fast-turning logs (CARMEN) need. With odometry as the
    guess, a scan matcher that sees nothing returns the odometry step, so
    its failure no longer shows as a disagreement with odometry.

    ``threads``: the threads of KISS-ICP's registration. 1 (the default)
    gives the same poses to the last bit on every run and every machine;
    0 is all cores (KISS-ICP's own default), faster, with sums whose order,
    and so whose last bits, depend on the scheduling.
    """

    enabled: bool = True
    initial_guess: Literal["constant_velocity", "odometry"] = "constant_velocity"
    min_range_m: bounds.LaserRange_m = Field(0.1, ge=0.0)
    max_range_m: bounds.LaserRange_m = Field(30.0, gt=0.0)
    voxel_size_m: Annotated[float, bounds.MAP_VOXEL_M] = Field(0.1, gt=0.0)
    max_points_per_voxel: bounds.Count = Field(20, ge=1)
    initial_threshold_m: bounds.MatchDistance_m = Field(0.5, gt=0.0)
    min_motion_m: bounds.LaserRange_m = Field(0.05, ge=0.0)
    max_iterations: bounds.Iterations = Field(500, ge=1)
    threads: bounds.Threads = Field(1, ge=0)

    @model_validator(mode="after")
    def _range_window(self) -> "FrontendConfig":
        if self.min_range_m >= self.max_range_m:
            raise ValueError(f"min_range_m {self.min_range_m:g} is not below max_range_m {self.max_range_m:g}: "
                             "no beam would be kept")
        # A scan is registered only once the robot moved min_motion_m: beyond
        # the laser's reach, the next scan shares nothing with the map.
        if self.min_motion_m >= self.max_range_m:
            raise ValueError(f"min_motion_m {self.min_motion_m:g} m is not below max_range_m {self.max_range_m:g} m: "
                             "a scan registered only after the robot left the laser's reach matches nothing")
        return self


# --- keyframes and back-end ----------------------------------------------


class KeyframeConfig(Strict):
    """A new keyframe when either limit is reached (null disables a limit)."""

    period_s: Annotated[float, bounds.KEYFRAME_PERIOD_S] | None = Field(0.5, gt=0.0)
    distance_m: Annotated[float, bounds.KEYFRAME_DISTANCE_M] | None = Field(None, gt=0.0)
    yaw_deg: Annotated[float, bounds.KEYFRAME_YAW_DEG] | None = Field(None, gt=0.0)

    @model_validator(mode="after")
    def _one_limit(self) -> "KeyframeConfig":
        if self.period_s is None and self.distance_m is None and self.yaw_deg is None:
            raise ValueError("at least one of period_s, distance_m, yaw_deg must be set")
        return self


Kernel = Literal["none", "huber", "cauchy", "dcs"]


class FactorConfig(Strict):
    """Common to every factor type: ``robust_kernel`` (null: the back-end's
    ``robust_kernel``) and its parameter in sigmas (null: the back-end's)."""

    enabled: bool = True
    robust_kernel: Kernel | None = None
    robust_param: bounds.RobustParam | None = Field(None, gt=0.0)


class OdometryFactorConfig(FactorConfig):
    """Between factor from track odometry; sigma grows with the step length.

    ``learn_scale``: with validation on (or an oracle), where the scan
    matcher's forward motion is gated, the odometry's distance is corrected
    by its scale against scan matching, learnt over the stretches where
    validation keeps both; see :mod:`slam.gating.odometry_scale`."""

    learn_scale: bool = False
    sigma_xy_m: bounds.Sigma_m = Field(0.01, gt=0.0)
    sigma_xy_per_m: Annotated[float, bounds.SIGMA_GROWTH] = Field(0.05, ge=0.0)
    sigma_yaw_deg: bounds.Sigma_deg = Field(0.5, gt=0.0)
    sigma_yaw_per_rad: Annotated[float, bounds.SIGMA_GROWTH] = Field(0.1, ge=0.0)


class GyroFactorConfig(FactorConfig):
    """Relative-yaw factor from the integrated gyro rate."""

    sigma_yaw_deg: bounds.Sigma_deg = Field(0.2, gt=0.0)
    sigma_yaw_per_s_deg: Annotated[float, bounds.SIGMA_GROWTH] = Field(0.05, ge=0.0)


class CompassFactorConfig(FactorConfig):
    """Absolute-yaw prior from the compass heading at the keyframe.

    ``correlation_s``: how long the compass's error stays alike (an AHRS
    heading's or a magnetic field's slow wander: the e-folding time of its
    autocorrelation, which ``gslam calibrate`` measures). Priors at
    keyframes ``dt`` apart then each carry ``sigma_yaw_deg * sqrt(2 *
    correlation_s / dt)`` (at least ``sigma_yaw_deg``): a stretch of ``T``
    seconds holds about ``T / (2 * correlation_s)`` independent errors, and
    its priors together say no more than those. Null: independent errors."""

    sigma_yaw_deg: bounds.Sigma_deg = Field(3.0, gt=0.0)
    correlation_s: Annotated[float, bounds.CORRELATION_S] | None = Field(None, gt=0.0)


class ScanMatchingFactorConfig(FactorConfig):
    """Between factor from KISS-ICP's relative pose."""

    sigma_xy_m: bounds.Sigma_m = Field(0.02, gt=0.0)
    sigma_xy_per_m: Annotated[float, bounds.SIGMA_GROWTH] = Field(0.02, ge=0.0)
    sigma_yaw_deg: bounds.Sigma_deg = Field(0.3, gt=0.0)


class GpsFactorConfig(FactorConfig):
    """Position prior from a GPS fix near the keyframe; sigma from the
    receiver's covariance, floored, times ``sigma_scale``."""

    sigma_floor_m: bounds.Sigma_m = Field(0.5, gt=0.0)
    sigma_scale: Annotated[float, bounds.SIGMA_SCALE] = Field(1.0, gt=0.0)
    max_time_offset_s: Annotated[float, bounds.MATCH_OFFSET_S] = Field(0.25, gt=0.0)


class FactorsConfig(Strict):
    odometry: OdometryFactorConfig = OdometryFactorConfig()
    gyro: GyroFactorConfig = GyroFactorConfig()
    compass: CompassFactorConfig = CompassFactorConfig()
    scan_matching: ScanMatchingFactorConfig = ScanMatchingFactorConfig()
    gps: GpsFactorConfig = GpsFactorConfig()


class BackendConfig(Strict):
    """GTSAM Pose2 graph over keyframes.

    ``initial_pose``: ``groundtruth`` anchors the first keyframe at the
    reference's first pose (so unaligned ATE is meaningful), ``origin`` at
    (0, 0) with the first compass heading if any, else yaw 0.

    ``optimizer``: batch Levenberg-Marquardt, incremental iSAM2, or GTSAM's
    graduated non-convexity with a truncated-least-squares or Geman-McClure
    loss. ``robust_kernel`` wraps every measurement factor's noise in an
    M-estimator with parameter ``robust_param`` (in sigmas).
    ``fallback_inflation``: when validation excludes every translational
    factor of a step, the least penalised one stays with its sigma times
    this, so the graph stays connected.
    """

    optimizer: Literal["batch", "isam2", "gnc_tls", "gnc_gm"] = "batch"
    initial_pose: Literal["groundtruth", "origin"] = "groundtruth"
    initial_sigma_xy_m: bounds.Sigma_m = Field(0.01, gt=0.0)
    initial_sigma_yaw_deg: bounds.Sigma_deg = Field(0.5, gt=0.0)
    max_iterations: bounds.Iterations = Field(100, ge=1)
    relative_error_tol: Annotated[float, bounds.RELATIVE_TOLERANCE] = Field(1e-6, gt=0.0)
    robust_kernel: Kernel = "none"
    robust_param: bounds.RobustParam = Field(1.345, gt=0.0)
    gnc_inlier_probability: float | None = Field(None, gt=0.0, lt=1.0)
    fallback_inflation: Annotated[float, bounds.INFLATION] = Field(10.0, ge=1.0)
    factors: FactorsConfig = FactorsConfig()


# --- evaluation and output -----------------------------------------------


class EvaluationConfig(Strict):
    """RPE over path-length deltas (m), as in KITTI / evo ``--delta_unit m``.

    ``sm_output_faults``: with ground truth, scan matching also counts as
    truly faulty where its motion over ``sm_fault_window_s`` is off the true
    motion by more than ``sm_fault_trans_m`` or ``sm_fault_yaw_deg``
    (slam.gating.truth); these times join the simulator's geometric fault intervals
    for the oracle and the validation metrics.
    """

    rpe_deltas_m: list[Annotated[float, Field(gt=0.0), bounds.PATH_DELTA_M]] = Field(default_factory=lambda: [5.0])
    max_time_offset_s: Annotated[float, bounds.MATCH_OFFSET_S] = Field(0.05, gt=0.0)
    sm_output_faults: bool = True
    sm_fault_window_s: Annotated[float, bounds.within(1e-2, 3600.0, "s", "shorter than any scan period",
                                                      "an hour of scan matching judged as one motion")] = Field(1.0, gt=0.0)
    sm_fault_trans_m: bounds.MatchDistance_m = Field(0.15, gt=0.0)
    sm_fault_yaw_deg: bounds.HeadingError_deg = Field(3.0, gt=0.0)


class OutputConfig(Strict):
    """What a result holds beside the trajectory and the metrics.

    ``map_voxel_m``: the spacing of ``map.ply``'s points. ``grid``:
    ``map.pgm`` + ``map.yaml``, an occupancy grid of ``grid_resolution_m``
    cells (slam.outputs.occupancy: a beam's end is a hit of ``grid_hit_probability``,
    each cell it crosses a miss of ``grid_miss_probability``, a beam without
    a return frees ``grid_no_return_m``). ``mcap``: ``run.mcap``
    (slam.outputs.run_mcap). ``report``: ``report.html`` of ``gslam compare``
    and ``gslam ablate`` (slam.outputs.report).
    """

    map_voxel_m: Annotated[float, bounds.MAP_VOXEL_M] = Field(0.05, gt=0.0)
    plots: bool = True
    progress: bool = True
    grid: bool = True
    grid_resolution_m: Annotated[float, bounds.GRID_CELL_M] = Field(0.05, gt=0.0)
    grid_hit_probability: float = Field(0.7, gt=0.5, lt=1.0)
    grid_miss_probability: float = Field(0.4, gt=0.0, lt=0.5)
    grid_no_return_m: bounds.LaserRange_m = Field(5.0, ge=0.0)
    mcap: bool = True
    report: bool = True


class PipelineConfig(Strict):
    """Root of a pipeline config (e.g. ``configs/telemax.yaml``).

    ``validation`` and ``gating`` are handled by the ``validation`` package
    and checked by its own models; they are kept here as the mappings of
    those models' dumps (every default spelled out), as
    :func:`load_config` leaves them.
    """

    input: InputConfig = InputConfig()
    frontend: FrontendConfig = FrontendConfig()
    keyframes: KeyframeConfig = KeyframeConfig()
    backend: BackendConfig = BackendConfig()
    evaluation: EvaluationConfig = EvaluationConfig()
    output: OutputConfig = OutputConfig()
    loops: LoopsConfig = LoopsConfig()
    submaps: SubmapsConfig = SubmapsConfig()
    validation: dict[str, Any] = Field(default_factory=lambda: _section_defaults()[0])
    gating: dict[str, Any] = Field(default_factory=lambda: _section_defaults()[1])

    @model_validator(mode="after")
    def _loops_from_submaps(self) -> "PipelineConfig":
        if self.loops.enabled and self.loops.source == "submaps" and not self.submaps.enabled:
            raise ValueError("loops.source is submaps, but submaps.enabled is false: enable the submaps "
                             "or choose another loops.source (auto, scans, file)")
        return self


def _section_defaults() -> tuple[dict[str, Any], dict[str, Any]]:
    """The ``validation`` and ``gating`` sections with every default."""
    vcfg, gcfg = _parse_sections({}, {})
    return vcfg.model_dump(mode="json", by_alias=True), gcfg.model_dump(mode="json", by_alias=True)


# --- loading -------------------------------------------------------------


def _loc_text(loc: tuple, unknown: bool = False) -> str:
    # pydantic names the member of a union it tried ("tuple[float, float]"):
    # not a key the user wrote. An unknown key's own name is the user's,
    # brackets or not ('period[s]' was dropped, naming its section instead).
    kept = [str(p) for p in loc[: -1 if unknown else None] if not (isinstance(p, str) and "[" in p)]
    return ".".join(kept + ([str(loc[-1])] if unknown and loc else []))


def describe_validation_error(source: str, err: ValidationError, what: str = "config", prefix: str = "",
                              model: type[BaseModel] | None = None) -> str:
    """One line for a pydantic error: the file, the key (after ``prefix``)
    and what is wrong; an unknown key first, since a typo is what the user
    must see, with the nearest known key of ``model`` at that place."""
    errors = err.errors()
    first = next((e for e in errors if e["type"] == "extra_forbidden"), errors[0])
    loc = prefix + _loc_text(first["loc"], unknown=first["type"] == "extra_forbidden")
    if first["type"] == "extra_forbidden":
        hint = did_you_mean(model, first["loc"]) if model is not None else ""
        return f"{source}: unknown {what} key '{loc}'{hint}{_not_ascii(str(first['loc'][-1]))}"
    msg = first["msg"].removeprefix("Value error, ")
    return f"{source}: {loc}: {msg}" if loc else f"{source}: {msg}"


def _not_ascii(key: str) -> str:
    """`` (its 'ѕ' is U+0455 CYRILLIC SMALL LETTER DZE; keys are ASCII)`` for
    the characters of an unknown ``key`` that only look like the ASCII ones
    of a known key (pasted from a document, typed on another keyboard)."""
    import unicodedata

    odd = list(dict.fromkeys(c for c in key if not c.isascii()))
    if not odd:
        return ""
    named = ", ".join(f"'{c}' is U+{ord(c):04X} {unicodedata.name(c, 'unnamed')}" for c in odd[:3])
    return f" (its {named}{', ...' if len(odd) > 3 else ''}; keys are ASCII)"


def set_dotted(tree: dict[str, Any], dotted: str, value: Any) -> None:
    """Set ``tree['a']['b']['c'] = value`` for ``dotted = 'a.b.c'``."""
    keys = dotted.split(".")
    node = tree
    for n, k in enumerate(keys[:-1]):
        nxt = node.get(k)
        if nxt is None:
            nxt = node[k] = {}
        if not isinstance(nxt, dict):
            section = ".".join(keys[: n + 1])
            raise GslamError(f"'{section}' is a value, not a section")
        node = nxt
    node[keys[-1]] = value


def parse_override(text: str) -> tuple[str, Any]:
    """``'a.b=3'`` -> ``('a.b', 3)``; the value is parsed as YAML."""
    if "=" not in text:
        raise GslamError(f"--set {text}: expected KEY=VALUE, e.g. backend.optimizer=isam2")
    key, raw = text.split("=", 1)
    key = key.strip()
    if not key or any(not part for part in key.split(".")):
        raise GslamError(f"--set {text}: expected KEY=VALUE with a dotted key, e.g. backend.optimizer=isam2")
    try:
        value = yaml.load(raw, Loader=UniqueKeyLoader) if raw.strip() else None
    except DuplicateKey as e:
        raise GslamError(f"--set {text}: key '{e.key}' given twice; the second would silently replace the first") \
            from None
    except yaml.constructor.ConstructorError as e:  # a value YAML reads but cannot hold (a 5,000-digit integer)
        raise GslamError(f"--set {text}: {e.problem}") from None
    except yaml.YAMLError:
        value = raw
    return key, value


def _inside(value: Any, dotted: str) -> tuple[bool, Any]:
    """``(True, value['a']['b'])`` for ``dotted = 'a.b'`` if ``value`` holds it, else ``(False, None)``."""
    for k in dotted.split("."):
        if not isinstance(value, dict) or k not in value:
            return False, None
        value = value[k]
    return True, value


def _replaces(earlier: tuple[str, Any], later: tuple[str, Any]) -> bool:
    """Whether override ``later`` (key, value) would change what ``earlier``
    set: the same key to another value, a section whose value drops or
    changes the earlier key, or a key inside an earlier section's value that
    it changes. A key beside one a section set, or the same value again,
    replaces nothing."""
    (ekey, evalue), (key, value) = earlier, later
    if key == ekey:
        return value != evalue
    if ekey.startswith(key + "."):
        held, inner = _inside(value, ekey[len(key) + 1:])
        return not held or inner != evalue
    if key.startswith(ekey + "."):
        held, inner = _inside(evalue, key[len(ekey) + 1:])
        return held and inner != value
    return False


def check_given_once(overrides: Sequence[str], names: Sequence[str] | None = None) -> None:
    """Refuse overrides of which a later one would replace what an earlier
    one set (``--set a.b=1 --set a.b=2``; ``--set a.b=1 --set a={c: 2}``,
    which drops ``a.b``): the later would win in silence, as a key given
    twice in a YAML file would. ``names[i]`` names override ``i`` in the
    error (default ``--set TEXT``). Callers that layer overrides on purpose
    (a sweep's point over its variant) do not call it."""
    names = list(names) if names is not None else [f"--set {text}" for text in overrides]
    seen: list[tuple[str, tuple[str, Any]]] = []
    for name, text in zip(names, overrides):
        pair = parse_override(text)
        for earlier_name, earlier in seen:
            if _replaces(earlier, pair):
                what = (f"sets the whole section '{pair[0]}', replacing '{earlier[0]}'"
                        if earlier[0].startswith(pair[0] + ".") else f"key '{pair[0]}' given twice")
                raise GslamError(f"{name}: {what} (first set by {earlier_name}); the second would silently "
                                 "replace the first")
        seen.append((name, pair))


def _blame(source: str, overrides: list[tuple[str, str]], key: str) -> str:
    """Who set ``key``: the last ``--set`` that touched it or a section
    holding it, else the config file."""
    for text, okey in reversed(overrides):
        if key == okey or key.startswith(okey + ".") or okey.startswith(key + "."):
            return f"--set {text}"
    return source


def config_files(path: str | Path | None) -> list[Path]:
    """The files a config reads: itself and the system model it names by
    path (``validation.model``), for the output rule (nothing is written
    over them); a file that cannot be read is left for :func:`load_config`
    to report."""
    if path is None:
        return []
    files = [Path(path)]
    try:
        tree = load_yaml(path, "config")
    except InputError:
        return files
    model = tree.get("validation", {}).get("model") if isinstance(tree.get("validation"), dict) else None
    if isinstance(model, str):
        files.append(Path(model) if Path(model).is_absolute() else Path(path).parent / model)
    return files


def load_config(path: str | Path | None, overrides: list[str] | tuple[str, ...] = ()) -> PipelineConfig:
    """Load a pipeline config and apply ``dotted.key=value`` overrides.

    An empty config file is allowed (every key takes its default) with a
    warning, since it is more often a mistake than a choice."""
    from validation.config import inline_model
    from validation.base.errors import ValidationError as SectionError

    tree = load_yaml(path, "config") if path is not None else {}
    source = str(path) if path is not None else "config"
    if path is not None and not tree:
        log.warning("%s is empty: every key takes its built-in default (configs/telemax.yaml is a commented example)", path)
    parsed = [(text, parse_override(text)) for text in overrides]
    applied = [(text, key) for text, (key, _) in parsed]
    # A model path in the file is relative to the file; one given as an
    # override is relative to the working directory.
    model_file = None  # the system model's file, which its own errors name
    try:
        if isinstance(tree.get("validation"), dict) and path is not None:
            model_file = inline_model(tree["validation"], Path(path).parent)
    except (SectionError, GslamError) as e:
        raise GslamError(f"{source}: {e}") from None
    for text, (key, value) in parsed:
        try:
            set_dotted(tree, key, value)
        except GslamError as e:
            raise GslamError(f"--set {text}: {e}") from None
    try:
        if isinstance(tree.get("validation"), dict):
            model_file = inline_model(tree["validation"], Path.cwd()) or model_file
    except (SectionError, GslamError) as e:
        raise GslamError(f"{_blame(source, applied, 'validation.model')}: {e}") from None
    found = non_finite(tree)
    if found is not None:
        key, value = found
        raise GslamError(f"{_blame(source, applied, key)}: {key}: expected a finite number, got {yaml_number(value)}")
    try:
        config = PipelineConfig.model_validate(tree)
    except ValidationError as e:
        first = next((x for x in e.errors() if x["type"] == "extra_forbidden"), e.errors()[0])
        who = _blame(source, applied, _loc_text(first["loc"]))
        raise GslamError(describe_validation_error(who, e, model=PipelineConfig)) from None
    try:
        vcfg, gcfg = _parse_sections(config.validation, config.gating)
        if config.loops.enabled and vcfg.mode is GatingMode.ON:
            from validation.loops.gating import check_model

            check_model(vcfg.model)
    except SectionError as e:
        key = _section_error_key(str(e))
        in_model = model_file is not None and (key + ".").startswith("validation.model.")
        raise GslamError(f"{model_file if in_model else _blame(source, applied, key)}: {e}") from None
    _check_sources(vcfg, config.input, lambda key: _blame(source, applied, key))
    _check_gated_factors(gcfg, lambda key: _blame(source, applied, key))
    # The checked sections, every default spelled out (validate_assignment
    # checks them as mappings).
    config.validation = vcfg.model_dump(mode="json", by_alias=True)
    config.gating = gcfg.model_dump(mode="json", by_alias=True)
    if not enabled_factors(config):
        why = ("scan_matching is the only one enabled and frontend.enabled is false"
               if config.backend.factors.scan_matching.enabled else "every one is disabled")
        raise GslamError(f"{_blame(source, applied, 'backend.factors')}: backend.factors: no factor left ({why}); "
                         "the graph needs at least one of odometry, gyro, compass, scan_matching, gps")
    return config


def _check_sources(vcfg, inputs: InputConfig, blame) -> None:
    """Every odometry-like stream an observer compares must come from the
    odometry, scan matching or a declared further odometry source."""
    from validation.streams.names import BUILTIN_SOURCES, split_source_stream

    for i, rel in enumerate(vcfg.observers.relations):
        for key, stream in (("stream_a", rel.stream_a), ("stream_b", rel.stream_b)):
            split = split_source_stream(stream)
            if split is None or split[0] in BUILTIN_SOURCES or split[0] in inputs.extra_odometry:
                continue
            declared = ", ".join(sorted(inputs.extra_odometry)) or "none"
            where = f"validation.observers.relations.{i}.{key}"
            raise GslamError(f"{blame(where)}: {where}: stream {stream!r} is odometry source {split[0]!r}, which "
                             f"input.extra_odometry does not declare (declared: {declared})")


def _check_gated_factors(gcfg, blame) -> None:
    """Every factor type ``gating.factors`` names must be one the graph has
    (or ``submaps``, the scan-to-submap constraints): a misspelt one would
    gate nothing."""
    known = (*FactorsConfig.model_fields, "submaps")
    for name in gcfg.factors:
        if name not in known:
            where = f"gating.factors.{name}"
            raise GslamError(f"{blame(where)}: {where}: unknown factor type {name!r}; expected one of "
                             f"{', '.join(known)}")


def enabled_factors(config: PipelineConfig) -> list[str]:
    """The factor types the config puts in the graph (scan matching only
    with the front-end on)."""
    factors = config.backend.factors
    names = [name for name in ("odometry", "gyro", "compass", "scan_matching", "gps") if getattr(factors, name).enabled]
    if not config.frontend.enabled and "scan_matching" in names:
        names.remove("scan_matching")
    return names


def _section_error_key(message: str) -> str:
    """The dotted key a validation-package error is about: its leading
    ``section.key:`` (``validation.model.priors:``; in a file's own terms
    ``validation: model.priors:``), or the unknown key it names."""
    unknown = re.match(r"unknown config key '([^']+)'", message)
    if unknown:
        return unknown.group(1)
    head, _, rest = message.partition(":")
    key = head.split(" ", 1)[0]
    inner = re.match(r" ([A-Za-z_][\w.]*):", rest)
    if inner and " " not in head:
        key = f"{key}.{inner.group(1)}"
    unknown = re.search(r"unknown key '([^']+)'", message)
    return f"{key}.{unknown.group(1)}" if unknown else key


def _parse_sections(validation: dict[str, Any], gating: dict[str, Any]):
    # The validation package builds on this module: imported here.
    from validation.config import parse_sections

    return parse_sections(validation, gating)


def validation_sections(config: PipelineConfig):
    """The typed ``validation`` and ``gating`` sections of a loaded config."""
    return _parse_sections(config.validation, config.gating)


def dump_config(config: PipelineConfig) -> str:
    """The config as YAML, every default spelled out; :func:`load_config`
    reads it back to an equal config. Strings YAML 1.1 would read as
    booleans (``off``, ``on``) are quoted."""
    return yaml.safe_dump(config.model_dump(mode="json"), sort_keys=False, allow_unicode=True)
