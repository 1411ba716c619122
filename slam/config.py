"""Typed pipeline configuration, loaded from YAML.

One model per component, nested under :class:`PipelineConfig`; every model
forbids unknown keys, so a typo in a config or an override is an error and
never silently runs the default. Angles are in degrees only where a key says
``_deg``; the code converts them at the edge.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Literal

import yaml
from pydantic import BaseModel, ConfigDict, Field, ValidationError, model_validator

from slam.errors import GslamError
from slam.loops.config import LoopsConfig


class Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", validate_assignment=True)


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
    declination_deg: float = 0.0
    mounting_yaw_deg: float = 0.0


class GpsInputConfig(Strict):
    """Datum of the local frame; null takes the first fix."""

    datum_lat_deg: float | None = None
    datum_lon_deg: float | None = None


class GyroInputConfig(Strict):
    """Which rate of a sensor_msgs/Imu is the yaw rate.

    ``z``: ``angular_velocity.z``, for an IMU mounted level (body z up).
    ``world_z``: the angular velocity rotated into the world by the message's
    orientation quaternion, its vertical component: the yaw rate of an IMU
    mounted tilted or rolled (the orientation must be valid).
    """

    axis: Literal["z", "world_z"] = "z"


class InputConfig(Strict):
    """``format``: ``auto`` guesses the reader from the path (ROS 1 ``.bag``,
    ROS 2 bag folder, simulated run folder, CARMEN ``.log``/``.log.gz``,
    BROAD ``.mat``, libRSF ``*_Input.txt``)."""

    format: Literal["auto", "rosbag", "carmen", "broad", "librsf"] = "auto"
    topics: TopicsConfig = TopicsConfig()
    gyro: GyroInputConfig = GyroInputConfig()
    compass: CompassInputConfig = CompassInputConfig()
    gps: GpsInputConfig = GpsInputConfig()


# --- front-end -----------------------------------------------------------


class FrontendConfig(Strict):
    """KISS-ICP on 2D scans (points at z = 0).

    ``initial_guess``: ``constant_velocity`` is KISS-ICP's own prediction;
    ``odometry`` starts each registration from the odometry step instead,
    which sparse, fast-turning logs (CARMEN) need. With odometry as the
    guess, a scan matcher that sees nothing returns the odometry step, so
    its failure no longer shows as a disagreement with odometry.
    """

    enabled: bool = True
    initial_guess: Literal["constant_velocity", "odometry"] = "constant_velocity"
    min_range_m: float = Field(0.1, ge=0.0)
    max_range_m: float = Field(30.0, gt=0.0)
    voxel_size_m: float = Field(0.1, gt=0.0)
    max_points_per_voxel: int = Field(20, ge=1)
    initial_threshold_m: float = Field(0.5, gt=0.0)
    min_motion_m: float = Field(0.05, ge=0.0)
    max_iterations: int = Field(500, ge=1)


# --- keyframes and back-end ----------------------------------------------


class KeyframeConfig(Strict):
    """A new keyframe when either limit is reached (null disables a limit)."""

    period_s: float | None = Field(0.5, gt=0.0)
    distance_m: float | None = Field(None, gt=0.0)
    yaw_deg: float | None = Field(None, gt=0.0)

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
    robust_param: float | None = Field(None, gt=0.0)


class OdometryFactorConfig(FactorConfig):
    """Between factor from track odometry; sigma grows with the step length."""

    sigma_xy_m: float = Field(0.01, gt=0.0)
    sigma_xy_per_m: float = Field(0.05, ge=0.0)
    sigma_yaw_deg: float = Field(0.5, gt=0.0)
    sigma_yaw_per_rad: float = Field(0.1, ge=0.0)


class GyroFactorConfig(FactorConfig):
    """Relative-yaw factor from the integrated gyro rate."""

    sigma_yaw_deg: float = Field(0.2, gt=0.0)
    sigma_yaw_per_s_deg: float = Field(0.05, ge=0.0)


class CompassFactorConfig(FactorConfig):
    """Absolute-yaw prior from the compass heading at the keyframe."""

    sigma_yaw_deg: float = Field(3.0, gt=0.0)


class ScanMatchingFactorConfig(FactorConfig):
    """Between factor from KISS-ICP's relative pose."""

    sigma_xy_m: float = Field(0.02, gt=0.0)
    sigma_xy_per_m: float = Field(0.02, ge=0.0)
    sigma_yaw_deg: float = Field(0.3, gt=0.0)


class GpsFactorConfig(FactorConfig):
    """Position prior from a GPS fix near the keyframe; sigma from the
    receiver's covariance, floored, times ``sigma_scale``."""

    sigma_floor_m: float = Field(0.5, gt=0.0)
    sigma_scale: float = Field(1.0, gt=0.0)
    max_time_offset_s: float = Field(0.25, gt=0.0)


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
    initial_sigma_xy_m: float = Field(0.01, gt=0.0)
    initial_sigma_yaw_deg: float = Field(0.5, gt=0.0)
    max_iterations: int = Field(100, ge=1)
    relative_error_tol: float = Field(1e-6, gt=0.0)
    robust_kernel: Kernel = "none"
    robust_param: float = Field(1.345, gt=0.0)
    gnc_inlier_probability: float | None = Field(None, gt=0.0, lt=1.0)
    fallback_inflation: float = Field(10.0, ge=1.0)
    factors: FactorsConfig = FactorsConfig()


# --- evaluation and output -----------------------------------------------


class EvaluationConfig(Strict):
    """RPE over path-length deltas (m), as in KITTI / evo ``--delta_unit m``.

    ``sm_output_faults``: with ground truth, scan matching also counts as
    truly faulty where its motion over ``sm_fault_window_s`` is off the true
    motion by more than ``sm_fault_trans_m`` or ``sm_fault_yaw_deg``
    (slam.truth); these times join the simulator's geometric fault intervals
    for the oracle and the validation metrics.
    """

    rpe_deltas_m: list[float] = Field(default_factory=lambda: [5.0])
    max_time_offset_s: float = Field(0.05, gt=0.0)
    sm_output_faults: bool = True
    sm_fault_window_s: float = Field(1.0, gt=0.0)
    sm_fault_trans_m: float = Field(0.15, gt=0.0)
    sm_fault_yaw_deg: float = Field(3.0, gt=0.0)


class OutputConfig(Strict):
    map_voxel_m: float = Field(0.05, gt=0.0)
    plots: bool = True
    progress: bool = True


class PipelineConfig(Strict):
    """Root of a pipeline config (e.g. ``configs/telemax.yaml``).

    ``validation`` and ``gating`` are handled by the ``validation`` package;
    they are kept as plain mappings here and checked by its own models.
    """

    input: InputConfig = InputConfig()
    frontend: FrontendConfig = FrontendConfig()
    keyframes: KeyframeConfig = KeyframeConfig()
    backend: BackendConfig = BackendConfig()
    evaluation: EvaluationConfig = EvaluationConfig()
    output: OutputConfig = OutputConfig()
    loops: LoopsConfig = LoopsConfig()
    validation: dict[str, Any] = Field(default_factory=dict)
    gating: dict[str, Any] = Field(default_factory=dict)


# --- loading -------------------------------------------------------------


def describe_validation_error(source: str, err: ValidationError, what: str = "config", prefix: str = "") -> str:
    """One line for a pydantic error: the file, the key (after ``prefix``)
    and what is wrong; an unknown key first, since a typo is what the user
    must see."""
    errors = err.errors()
    first = next((e for e in errors if e["type"] == "extra_forbidden"), errors[0])
    loc = prefix + ".".join(str(p) for p in first["loc"])
    if first["type"] == "extra_forbidden":
        return f"{source}: unknown {what} key '{loc}'"
    return f"{source}: {loc}: {first['msg']}"


def set_dotted(tree: dict[str, Any], dotted: str, value: Any) -> None:
    """Set ``tree['a']['b']['c'] = value`` for ``dotted = 'a.b.c'``."""
    keys = dotted.split(".")
    node = tree
    for k in keys[:-1]:
        nxt = node.get(k)
        if nxt is None:
            nxt = node[k] = {}
        if not isinstance(nxt, dict):
            raise GslamError(f"override '{dotted}': '{k}' is not a section")
        node = nxt
    node[keys[-1]] = value


def parse_override(text: str) -> tuple[str, Any]:
    """``'a.b=3'`` -> ``('a.b', 3)``; the value is parsed as YAML."""
    if "=" not in text:
        raise GslamError(f"override '{text}': expected dotted.key=value")
    key, raw = text.split("=", 1)
    key = key.strip()
    if not key:
        raise GslamError(f"override '{text}': empty key")
    try:
        value = yaml.safe_load(raw) if raw.strip() else None
    except yaml.YAMLError:
        value = raw
    return key, value


def load_yaml(path: str | Path) -> dict[str, Any]:
    """Read a YAML mapping, with a one-line error for anything else."""
    path = Path(path)
    try:
        text = path.read_text()
    except OSError as e:
        raise GslamError(f"{path}: cannot read config ({e.strerror})") from None
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as e:
        mark = getattr(e, "problem_mark", None)
        where = f" line {mark.line + 1}" if mark else ""
        raise GslamError(f"{path}:{where} invalid YAML") from None
    if data is None:
        return {}
    if not isinstance(data, dict):
        raise GslamError(f"{path}: expected a mapping at the top level")
    return data


def load_config(path: str | Path | None, overrides: list[str] | tuple[str, ...] = ()) -> PipelineConfig:
    """Load a pipeline config and apply ``dotted.key=value`` overrides."""
    from validation.config import inline_model
    from validation.errors import ValidationError as SectionError

    tree = load_yaml(path) if path is not None else {}
    source = str(path) if path is not None else "config"
    # A model path in the file is relative to the file; one given as an
    # override is relative to the working directory.
    try:
        if isinstance(tree.get("validation"), dict) and path is not None:
            inline_model(tree["validation"], Path(path).parent)
        for text in overrides:
            key, value = parse_override(text)
            set_dotted(tree, key, value)
        if isinstance(tree.get("validation"), dict):
            inline_model(tree["validation"], Path.cwd())
    except SectionError as e:
        raise GslamError(f"{source}: {e}") from None
    try:
        config = PipelineConfig.model_validate(tree)
    except ValidationError as e:
        raise GslamError(describe_validation_error(source, e)) from None
    # The validation package checks its own sections (imported here, not at
    # module level: it builds on this module).
    from validation.config import parse_sections

    try:
        vcfg, _ = parse_sections(config.validation, config.gating)
        if config.loops.enabled and vcfg.mode == "on":
            from validation.loop_gating import check_model

            check_model(vcfg.model)
    except SectionError as e:
        raise GslamError(f"{source}: {e}") from None
    return config


def validation_sections(config: PipelineConfig):
    """The typed ``validation`` and ``gating`` sections of a loaded config."""
    from validation.config import parse_sections

    return parse_sections(config.validation, config.gating)


def dump_config(config: PipelineConfig) -> str:
    """The config as YAML, every default spelled out."""
    return yaml.safe_dump(config.model_dump(mode="json"), sort_keys=False)
