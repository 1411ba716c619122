"""Sensor models: each samples the ground truth at its own rate and adds
its own noise from the scenario, drawing from its own random stream.

Sample times are ``k / rate_hz`` s from the start of the run. All outputs
are in SI units; frames are stated per model.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from validation.base.geometry import geodetic_from_enu
from slam.recording import MagneticReference
from slam.sim.magnetics import body_field
from slam.sim.robot import Motion
from slam.sim.scenario import (
    Disturber,
    EnvironmentConfig,
    GpsConfig,
    GyroConfig,
    LaserConfig,
    MagnetometerConfig,
    OdometryConfig,
)
from slam.sim.world import World, distance_to_segments, scan_constraint


def sample_times(duration_s: float, rate_hz: float) -> np.ndarray:
    """``k / rate_hz`` for every k with the time inside the run, s."""
    return np.arange(int(np.floor(duration_s * rate_hz + 1e-9)) + 1) / rate_hz


# --- laser -----------------------------------------------------------------


@dataclass
class LaserData:
    """``ranges`` (n, B) float32 m, inf without a return (REP-117), -inf
    closer than ``range_min``; ``angles`` (B,) rad in the laser frame (= body
    frame, the laser sits at the robot centre). From the noise-free scan:
    ``returns`` (n,) the number of returns, ``min_eigenvalue`` (n,) the
    degeneracy measure of :func:`slam.sim.world.scan_constraint` and
    ``weak_direction`` (n, 3) its eigenvector (world x, world y, turn)."""

    t: np.ndarray
    ranges: np.ndarray
    angles: np.ndarray
    range_min: float
    range_max: float
    returns: np.ndarray
    min_eigenvalue: np.ndarray
    weak_direction: np.ndarray


def laser_angles(cfg: LaserConfig) -> np.ndarray:
    """Beam angles (B,) rad, symmetric about the x axis."""
    half = np.radians(cfg.fov_deg) / 2.0
    return np.linspace(-half, half, cfg.beams)


_CHUNK = 256  # scans per block: bounds memory on long runs


def simulate_laser(
    motion: Motion, world: World, cfg: LaserConfig, rng: np.random.Generator, progress: Any = None
) -> LaserData:
    """Ray-cast a 2D scan against the world at every laser time, add range
    noise and measure how well each noise-free scan constrains a pose.
    ``progress`` is an optional tqdm-like bar advanced once per scan."""
    t = sample_times(motion.duration, cfg.rate_hz)
    pose = motion.at(t)
    angles = laser_angles(cfg)
    ranges = np.empty((len(t), len(angles)), dtype=np.float32)
    returns = np.empty(len(t), dtype=np.int64)
    min_eig = np.empty(len(t))
    weak = np.empty((len(t), 3))
    for start in range(0, len(t), _CHUNK):
        ks = range(start, min(start + _CHUNK, len(t)))
        beam_yaw = angles[None, :] + pose["yaw"][ks.start : ks.stop, None]
        true = np.empty((len(ks), len(angles)))
        hit = np.empty((len(ks), len(angles)), dtype=np.int64)
        for i, k in enumerate(ks):
            origin = np.array([pose["x"][k], pose["y"][k]])
            true[i], hit[i] = world.cast(origin, beam_yaw[i], cfg.max_range_m)
        returns[ks.start : ks.stop], min_eig[ks.start : ks.stop], weak[ks.start : ks.stop] = scan_constraint(
            true, hit, beam_yaw, world.normals
        )
        noisy = true + rng.normal(0.0, cfg.range_noise_m, true.shape)
        noisy = np.where(noisy > cfg.max_range_m, np.inf, noisy)
        ranges[ks.start : ks.stop] = np.where(noisy < cfg.min_range_m, -np.inf, noisy)
        if progress is not None:
            progress.update(len(ks))
    return LaserData(t, ranges, angles, cfg.min_range_m, cfg.max_range_m, returns, min_eig, weak)


# --- gyroscope ---------------------------------------------------------------


@dataclass
class GyroData:
    """``rate`` (n,) rad/s about body z; ``bias`` (n,) rad/s, the true bias."""

    t: np.ndarray
    rate: np.ndarray
    bias: np.ndarray


def simulate_gyro(motion: Motion, cfg: GyroConfig, rng: np.random.Generator) -> GyroData:
    """True yaw rate + bias random walk + white noise."""
    t = sample_times(motion.duration, cfg.rate_hz)
    dt = 1.0 / cfg.rate_hz
    steps = rng.normal(0.0, cfg.bias_walk_rad_s_sqrt_s * np.sqrt(dt), len(t))
    steps[0] = 0.0
    bias = cfg.bias_initial_rad_s + np.cumsum(steps)
    rate = np.interp(t, motion.t, motion.w) + bias + rng.normal(0.0, cfg.noise_rad_s, len(t))
    return GyroData(t, rate, bias)


# --- magnetometer ------------------------------------------------------------


@dataclass
class MagData:
    """``field`` (n, 3) T in the body frame with noise; ``true_field`` without."""

    t: np.ndarray
    field: np.ndarray
    true_field: np.ndarray


def simulate_magnetometer(
    motion: Motion,
    cfg: MagnetometerConfig,
    ref: MagneticReference,
    disturbers: list[Disturber],
    rng: np.random.Generator,
) -> MagData:
    """Earth field + steel dipoles, in the body frame, + white noise per axis."""
    t = sample_times(motion.duration, cfg.rate_hz)
    p = motion.at(t)
    true = body_field(np.column_stack([p["x"], p["y"]]), p["yaw"], cfg.mounting_height_m, ref, disturbers)
    return MagData(t, true + rng.normal(0.0, cfg.noise_T, true.shape), true)


# --- track odometry ------------------------------------------------------------


@dataclass
class OdomData:
    """Pose integrated in the ``odom`` frame from (0, 0, 0): ``x``/``y`` m,
    ``yaw`` rad (unwrapped); twist ``v`` m/s and ``w`` rad/s (body)."""

    t: np.ndarray
    x: np.ndarray
    y: np.ndarray
    yaw: np.ndarray
    v: np.ndarray
    w: np.ndarray


def simulate_odometry(
    motion: Motion, world: World, cfg: OdometryConfig, rng: np.random.Generator
) -> OdomData:
    """Per step, the reported distance and rotation are the true ones scaled
    by (1 + scale error + slip) plus noise growing with the step."""
    t = sample_times(motion.duration, cfg.rate_hz)
    p = motion.at(t)
    dt = np.diff(t)
    ds, dyaw = np.diff(p["s"]), np.diff(p["yaw"])
    mid = np.column_stack([0.5 * (p["x"][1:] + p["x"][:-1]), 0.5 * (p["y"][1:] + p["y"][:-1])])
    slip = world.track_slip(mid, dyaw / dt, cfg.turn_slip_per_rad_s)
    ds_m = ds * (1.0 + cfg.distance_scale_error + slip)
    ds_m += rng.normal(0.0, 1.0, len(ds)) * cfg.distance_noise_m_sqrt_m * np.sqrt(np.abs(ds))
    dyaw_m = dyaw * (1.0 + cfg.rotation_overreport + slip)
    dyaw_m += rng.normal(0.0, 1.0, len(dyaw)) * cfg.yaw_noise_rad_sqrt_rad * np.sqrt(np.abs(dyaw))
    yaw = np.concatenate([[0.0], np.cumsum(dyaw_m)])
    heading = yaw[:-1] + 0.5 * dyaw_m  # midpoint rule over the step
    x = np.concatenate([[0.0], np.cumsum(ds_m * np.cos(heading))])
    y = np.concatenate([[0.0], np.cumsum(ds_m * np.sin(heading))])
    v = np.concatenate([[0.0], ds_m / dt])
    w = np.concatenate([[0.0], dyaw_m / dt])
    return OdomData(t, x, y, yaw, v, w)


# --- GPS -----------------------------------------------------------------------


@dataclass
class GpsData:
    """``status`` (n,) 0 fix / -1 no fix; ``lat``/``lon`` deg (NaN without
    fix); ``x``/``y`` m the measured ENU position; ``multipath`` (n,) m the
    magnitude of the multipath bias; ``sigma`` m the nominal noise."""

    t: np.ndarray
    status: np.ndarray
    lat: np.ndarray
    lon: np.ndarray
    x: np.ndarray
    y: np.ndarray
    multipath: np.ndarray
    sigma: float
    altitude: float


def multipath_bias(world: World, xy: np.ndarray, cfg: GpsConfig) -> np.ndarray:
    """Bias (n, 2) m pushing the fix away from the nearest wall, decaying
    exponentially with the distance to it (reflected signals arrive late)."""
    dist, away = distance_to_segments(xy, world.segments)
    return cfg.multipath_max_m * np.exp(-dist / cfg.multipath_scale_m)[:, None] * away


def gps_available(world: World, xy: np.ndarray, cfg: GpsConfig) -> np.ndarray:
    """A fix (n,) bool only in the open, away from buildings."""
    return (~world.indoor(xy)) & (world.distance_to_indoor(xy) > cfg.outage_distance_m)


def simulate_gps(
    motion: Motion, world: World, cfg: GpsConfig, env: EnvironmentConfig, rng: np.random.Generator
) -> GpsData:
    """Fixes with white noise and multipath; NO_FIX near or inside buildings."""
    t = sample_times(motion.duration, cfg.rate_hz)
    p = motion.at(t)
    xy = np.column_stack([p["x"], p["y"]])
    bias = multipath_bias(world, xy, cfg)
    meas = xy + bias + rng.normal(0.0, cfg.sigma_m, xy.shape)
    ok = gps_available(world, xy, cfg)
    meas[~ok] = np.nan
    lat, lon = geodetic_from_enu(meas[:, 0], meas[:, 1], env.datum_lat_deg, env.datum_lon_deg)
    status = np.where(ok, 0, -1)
    multipath = np.hypot(bias[:, 0], bias[:, 1])
    return GpsData(t, status, lat, lon, meas[:, 0], meas[:, 1], multipath, cfg.sigma_m, cfg.altitude_m)
