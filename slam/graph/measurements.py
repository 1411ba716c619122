"""Keyframes and the per-step measurements of every factor type.

A *step* is a keyframe. Between-measurements (odometry, gyro, scan matching)
with index ``k`` connect keyframes ``k - 1`` and ``k`` and belong to step
``k`` (index 0 is unused and invalid); priors (compass, GPS) belong to the
step of their keyframe. Everything is built once, vectorised, so the
back-end and the gating only index arrays.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from slam.config import FactorsConfig, KeyframeConfig
from validation.base.geometry import wrap_angle
from slam.recording import Recording, Trajectory, covered, interpolate_poses, path_length, relative_poses

FACTOR_TYPES: tuple[str, ...] = ("odometry", "gyro", "compass", "scan_matching", "gps")

FACTOR_DOFS: dict[str, tuple[str, ...]] = {
    "odometry": ("x", "y", "yaw"),
    "gyro": ("yaw",),
    "compass": ("yaw",),
    "scan_matching": ("x", "y", "yaw"),
    "gps": ("x", "y"),
}
"""The degrees of freedom of each factor type's measurement, in the order of
its noise model: a between factor's x (along the keyframe's heading), y
(to its left) and yaw in the frame of keyframe k-1; a prior's world x, y or
yaw."""
SUBMAP_DOFS: tuple[str, ...] = FACTOR_DOFS["scan_matching"]
"""The degrees of freedom of the scan-to-submap constraints (between factors,
as scan matching's), which ``gating.factors.submaps`` may gate apart from
scan matching (:func:`slam.pipeline.core.submap_factors`)."""


# --- keyframes -------------------------------------------------------------


def select_keyframes(candidate_t: np.ndarray, odometry: Trajectory | None, config: KeyframeConfig) -> np.ndarray:
    """Indices of ``candidate_t`` chosen as keyframes.

    A candidate becomes a keyframe once the time, the odometry path length
    or the odometry yaw change since the last keyframe reaches its limit.
    The first candidate is always a keyframe.
    """
    n = len(candidate_t)
    if n == 0:
        return np.zeros(0, dtype=np.int64)
    dist = np.zeros(n)
    yaw = np.zeros(n)
    if odometry is not None and len(odometry) > 1:
        poses = interpolate_poses(odometry, candidate_t)
        dist = path_length(poses[:, :2])
        yaw = np.unwrap(poses[:, 2])
    period = config.period_s if config.period_s is not None else np.inf
    d_lim = config.distance_m if config.distance_m is not None else np.inf
    yaw_lim = np.radians(config.yaw_deg) if config.yaw_deg is not None else np.inf
    chosen = [0]
    t_last, d_last, y_last = candidate_t[0], dist[0], yaw[0]
    for i in range(1, n):
        if (
            candidate_t[i] - t_last >= period - 1e-9
            or dist[i] - d_last >= d_lim
            or abs(yaw[i] - y_last) >= yaw_lim
        ):
            chosen.append(i)
            t_last, d_last, y_last = candidate_t[i], dist[i], yaw[i]
    return np.asarray(chosen, dtype=np.int64)


# --- measurements ----------------------------------------------------------


@dataclass
class BetweenMeasurement:
    """Relative poses (K, 3) keyframe k-1 -> k in the frame of k-1, sigmas
    (K, 3) (x m, y m, yaw rad), validity (K,)."""

    delta: np.ndarray
    sigma: np.ndarray
    valid: np.ndarray


@dataclass
class ScalarMeasurement:
    """One value per step (K,) with its sigma (K,) and validity (K,):
    a yaw increment (gyro), an absolute yaw (compass), rad.

    ``factor_sigma`` (K,): the sigma its factors carry where successive
    errors are alike (the compass's ``correlation_s``), so that a stretch of
    factors holds the information of its independent errors; None: ``sigma``.
    ``sigma`` stays the error of one measurement."""

    value: np.ndarray
    sigma: np.ndarray
    valid: np.ndarray
    factor_sigma: np.ndarray | None = None

    @property
    def information_sigma(self) -> np.ndarray:
        """The sigma of its factors: ``factor_sigma``, else ``sigma``."""
        return self.sigma if self.factor_sigma is None else self.factor_sigma


@dataclass
class PositionMeasurement:
    """Positions (K, 2) m with sigma (K,) m and validity (K,)."""

    xy: np.ndarray
    sigma: np.ndarray
    valid: np.ndarray


@dataclass(frozen=True)
class RelativeConstraint:
    """A between factor from keyframe ``i`` to keyframe ``j`` (any two):
    ``delta`` (x, y, yaw) in the frame of ``i``, ``sigma`` (3,) m, m, rad,
    ``inf`` for a degree of freedom it says nothing about; ``kind`` is the
    factor type whose robust kernel it takes, ``label`` what it is (counted
    per label in the result). ``information`` (3, 3), when given, replaces
    ``sigma``: the noise of the between factor's error (in the frame of
    ``j``), possibly singular."""

    i: int
    j: int
    delta: np.ndarray
    sigma: np.ndarray
    kind: str
    label: str
    information: np.ndarray | None = None


@dataclass
class Measurements:
    """Everything the back-end needs, per keyframe step."""

    t: np.ndarray
    scan_index: np.ndarray | None
    odometry: BetweenMeasurement | None = None
    gyro: ScalarMeasurement | None = None
    compass: ScalarMeasurement | None = None
    scan_matching: BetweenMeasurement | None = None
    gps: PositionMeasurement | None = None

    def __len__(self) -> int:
        return len(self.t)

    def get(self, factor: str):
        return getattr(self, factor)


def _between_from_poses(poses: np.ndarray, valid: np.ndarray, sigma_xy, sigma_xy_per_m, sigma_yaw, sigma_yaw_per_rad=0.0):
    delta = np.zeros_like(poses)
    delta[1:] = relative_poses(poses[:-1], poses[1:])
    step = np.hypot(delta[:, 0], delta[:, 1])
    s_xy = sigma_xy + sigma_xy_per_m * step
    s_yaw = sigma_yaw + sigma_yaw_per_rad * np.abs(delta[:, 2])
    ok = np.zeros(len(poses), dtype=bool)
    ok[1:] = valid[1:] & valid[:-1]
    return BetweenMeasurement(delta=delta, sigma=np.column_stack([s_xy, s_xy, s_yaw]), valid=ok)


def _odometry(rec: Recording, t: np.ndarray, cfg, max_gap_s: float) -> BetweenMeasurement:
    odo = rec.odometry
    poses = interpolate_poses(odo, t)
    valid = covered(odo.t, t, max_gap_s)
    return _between_from_poses(
        poses, valid, cfg.sigma_xy_m, cfg.sigma_xy_per_m, np.radians(cfg.sigma_yaw_deg), cfg.sigma_yaw_per_rad
    )


def _gyro(rec: Recording, t: np.ndarray, cfg, max_gap_s: float) -> ScalarMeasurement:
    g = rec.gyro
    # Trapezoidal integral of the rate, then differences at keyframe times.
    integral = np.concatenate([[0.0], np.cumsum(0.5 * (g.rate[1:] + g.rate[:-1]) * np.diff(g.t))])
    yaw_at = np.interp(t, g.t, integral)
    value = np.zeros(len(t))
    value[1:] = np.diff(yaw_at)
    dt = np.zeros(len(t))
    dt[1:] = np.diff(t)
    sigma = np.radians(cfg.sigma_yaw_deg) + np.radians(cfg.sigma_yaw_per_s_deg) * dt
    cov = covered(g.t, t, max_gap_s)
    valid = np.zeros(len(t), dtype=bool)
    valid[1:] = cov[1:] & cov[:-1]
    return ScalarMeasurement(value=value, sigma=sigma, valid=valid)


def _compass(rec: Recording, t: np.ndarray, cfg, max_gap_s: float) -> ScalarMeasurement:
    c = rec.compass
    yaw = wrap_angle(np.interp(t, c.t, np.unwrap(c.yaw)))
    sigma = np.full(len(t), np.radians(cfg.sigma_yaw_deg))
    factor_sigma = None
    if cfg.correlation_s is not None and len(t) > 1:
        spacing = np.maximum(_keyframe_spacing(t), 1e-3)
        factor_sigma = sigma * np.sqrt(np.maximum(1.0, 2.0 * cfg.correlation_s / spacing))
    return ScalarMeasurement(value=yaw, sigma=sigma, valid=covered(c.t, t, max_gap_s), factor_sigma=factor_sigma)


def _keyframe_spacing(t: np.ndarray) -> np.ndarray:
    """The time each keyframe stands for: half the span to its two
    neighbours (the one neighbour's whole span at the ends), s; n >= 2."""
    gaps = np.diff(t)
    return np.concatenate(([gaps[0]], 0.5 * (gaps[1:] + gaps[:-1]), [gaps[-1]]))


def _gps(rec: Recording, t: np.ndarray, cfg) -> PositionMeasurement:
    g = rec.gps
    idx = np.clip(np.searchsorted(g.t, t), 1, len(g.t) - 1) if len(g.t) > 1 else np.zeros(len(t), dtype=int)
    if len(g.t) > 1:
        prev_closer = np.abs(g.t[idx - 1] - t) <= np.abs(g.t[idx] - t)
        idx = np.where(prev_closer, idx - 1, idx)
    valid = np.abs(g.t[idx] - t) <= cfg.max_time_offset_s
    sigma = np.where(np.isfinite(g.sigma[idx]), g.sigma[idx], 0.0)
    sigma = np.maximum(sigma, cfg.sigma_floor_m) * cfg.sigma_scale
    return PositionMeasurement(xy=np.column_stack([g.x[idx], g.y[idx]]), sigma=sigma, valid=valid)


def _scan_matching(sm: Trajectory, scan_index: np.ndarray, cfg) -> BetweenMeasurement:
    poses = np.column_stack([sm.x, sm.y, sm.yaw])[scan_index]
    valid = np.ones(len(scan_index), dtype=bool)
    return _between_from_poses(poses, valid, cfg.sigma_xy_m, cfg.sigma_xy_per_m, np.radians(cfg.sigma_yaw_deg))


def build_measurements(
    rec: Recording,
    keyframe_t: np.ndarray,
    factors: FactorsConfig,
    scan_index: np.ndarray | None = None,
    sm_poses: Trajectory | None = None,
    max_gap_s: float = 0.5,
) -> Measurements:
    """Measurements of every enabled factor type whose sensor is present.

    ``scan_index`` gives the scan of each keyframe and ``sm_poses`` the
    front-end's pose per scan; scan matching is absent without them.
    """
    t = keyframe_t
    m = Measurements(t=t, scan_index=scan_index)
    if factors.odometry.enabled and rec.odometry is not None:
        m.odometry = _odometry(rec, t, factors.odometry, max_gap_s)
    if factors.gyro.enabled and rec.gyro is not None:
        m.gyro = _gyro(rec, t, factors.gyro, max_gap_s)
    if factors.compass.enabled and rec.compass is not None:
        m.compass = _compass(rec, t, factors.compass, max_gap_s)
    if factors.gps.enabled and rec.gps is not None and len(rec.gps.t):
        m.gps = _gps(rec, t, factors.gps)
    if factors.scan_matching.enabled and sm_poses is not None and scan_index is not None:
        m.scan_matching = _scan_matching(sm_poses, scan_index, factors.scan_matching)
    return m


# --- residuals ---------------------------------------------------------------


def measurement_residuals(meas: Measurements, reference: Trajectory) -> dict[str, np.ndarray]:
    """Residual of every measurement against a reference trajectory at the
    keyframes (the truth, or an estimate), per factor type: (K, dofs) in the
    order of :data:`FACTOR_DOFS`, NaN where the measurement is absent.

    Between factors: the x, y and yaw of ``inverse(reference step) *
    measured step`` (frame of keyframe k-1, as GTSAM's residual); the gyro:
    measured minus reference yaw increment; the compass: measured minus
    reference yaw (wrapped); GPS: measured minus reference position.
    """
    true = interpolate_poses(reference, meas.t)
    step = np.zeros_like(true)
    step[1:] = relative_poses(true[:-1], true[1:])
    out: dict[str, np.ndarray] = {}
    for factor in FACTOR_TYPES:
        m = meas.get(factor)
        if m is None:
            continue
        if factor in ("odometry", "scan_matching"):
            err = relative_poses(step, m.delta)
        elif factor == "gyro":
            err = wrap_angle(m.value - step[:, 2])[:, None]
        elif factor == "compass":
            err = wrap_angle(m.value - true[:, 2])[:, None]
        else:
            err = m.xy - true[:, :2]
        err = np.where(m.valid[:, None], err, np.nan)
        out[factor] = err.reshape(len(meas.t), len(FACTOR_DOFS[factor]))
    return out


def measurement_sigmas(meas: Measurements, information: bool = False) -> dict[str, np.ndarray]:
    """The configured sigma of every measurement, (K, dofs) per factor type:
    the error of one measurement, or with ``information`` the sigma its
    factor carries (:attr:`ScalarMeasurement.information_sigma`)."""
    out: dict[str, np.ndarray] = {}
    for factor in FACTOR_TYPES:
        m = meas.get(factor)
        if m is None:
            continue
        sigma = np.asarray(m.information_sigma if information and isinstance(m, ScalarMeasurement) else m.sigma,
                           dtype=float)
        dofs = len(FACTOR_DOFS[factor])
        out[factor] = sigma if sigma.ndim == 2 else np.repeat(sigma[:, None], dofs, axis=1)
    return out
