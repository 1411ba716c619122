"""The recheck of offline validation: every measurement the diagnosis
blamed is checked against what the other sensors say.

The diagnosis (:mod:`validation.validator`) blames components over
stretches of time, and gates every measurement of a blamed component there.
Within a blamed stretch a measurement can still be right. So:

1. The graph is optimised with the diagnosis's weights: the estimate of
   the sensors that were not blamed, with its marginal covariances.
2. Each gated degree of freedom of each absolute measurement (compass
   headings, GPS fixes: ``gating.recheck_factors``) is compared with that
   estimate: ``z = residual / sqrt(sigma_measurement^2 + sigma_estimate^2)``,
   where ``sigma_estimate`` is the estimate's own uncertainty of the same
   quantity (the pose of the prior's keyframe). Where ``|z| <= keep_k_sigma``
   the measurement agrees with the others and is kept with its configured
   noise. Relative measurements are not taken back step by step: a bias
   well inside one step's noise adds up over many steps.
3. For the between-factor types in ``gating.baseline_factors`` (scan
   matching), each degree of freedom that stays excluded step by step is
   checked again over baselines of ``gating.baseline_m`` of path: the
   measured motion over the baseline (the composition of its steps, its
   sigma theirs added in quadrature) against the estimate's. A baseline that
   agrees enters the graph as one between factor over those keyframes, for
   that degree of freedom only: a scan matcher that sticks and catches up
   again is wrong step by step but right over metres.

Nothing here knows the truth; ``validation.mode: oracle`` is the bound.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field

import gtsam
import numpy as np

from slam.graph.backend import FactorWeights, dof_weights, optimise
from slam.config import BackendConfig
from slam.graph.factors import pose_key
from validation.base.geometry import wrap_angle
from slam.graph.measurements import FACTOR_DOFS, Measurements, RelativeConstraint, measurement_residuals, measurement_sigmas
from slam.recording import relative_poses
from validation.gating import GatingConfig

log = logging.getLogger(__name__)

BETWEEN = ("odometry", "scan_matching")


@dataclass
class RecheckResult:
    """The recheck's weights, the baselines it kept, and counts for
    ``metrics.json``."""

    weights: FactorWeights
    constraints: list[RelativeConstraint] = field(default_factory=list)
    metrics: dict = field(default_factory=dict)


def _relative_cov(marginals: gtsam.Marginals, values: gtsam.Values, i: int, j: int) -> np.ndarray:
    """Covariance (3, 3) of the relative pose from keyframe i to j, in the
    tangent space of that relative pose."""
    ki, kj = pose_key(i), pose_key(j)
    joint = marginals.jointMarginalCovariance(gtsam.KeyVector([ki, kj])).fullMatrix()
    pi, pj = values.atPose2(ki), values.atPose2(kj)
    a = pi.between(pj).inverse().AdjointMap()
    s11, s12, s21, s22 = joint[:3, :3], joint[:3, 3:], joint[3:, :3], joint[3:, 3:]
    return a @ s11 @ a.T - a @ s12 - s21 @ a.T + s22


def _estimate_sigmas(factor: str, k: int, marginals: gtsam.Marginals, values: gtsam.Values) -> np.ndarray:
    """The estimate's standard deviation of what a measurement of ``factor``
    at step k measures, per degree of freedom."""
    if factor in BETWEEN:
        return np.sqrt(np.clip(np.diag(_relative_cov(marginals, values, k - 1, k)), 0.0, None))
    if factor == "gyro":
        return np.sqrt(max(_relative_cov(marginals, values, k - 1, k)[2, 2], 0.0))[None]
    cov = marginals.marginalCovariance(pose_key(k))
    if factor == "compass":
        return np.sqrt(max(cov[2, 2], 0.0))[None]
    # GPS: the pose's position covariance is in its body frame; the prior's
    # residual is in the world frame.
    yaw = values.atPose2(pose_key(k)).theta()
    c, s = np.cos(yaw), np.sin(yaw)
    r = np.array([[c, -s], [s, c]])
    return np.sqrt(np.clip(np.diag(r @ cov[:2, :2] @ r.T), 0.0, None))


def _values(traj) -> gtsam.Values:
    values = gtsam.Values()
    for k in range(len(traj)):
        values.insert(pose_key(k), gtsam.Pose2(traj.x[k], traj.y[k], traj.yaw[k]))
    return values


def recheck(
    meas: Measurements,
    weights: FactorWeights,
    initial_pose: np.ndarray,
    backend: BackendConfig,
    gating: GatingConfig,
) -> RecheckResult:
    """The recheck (module docstring); ``weights`` are the diagnosis's."""
    k_sigma = gating.keep_k_sigma
    weights = {f: dof_weights(w, f).copy() for f, w in weights.items()}
    gated = {f: w > 1.0 for f, w in weights.items() if meas.get(f) is not None}
    if k_sigma is None or not any(g.any() for g in gated.values()):
        return RecheckResult(weights)
    batch = backend.model_copy(update={"optimizer": "batch"})
    first = optimise(meas, initial_pose, batch, weights, marginals=True)
    values = _values(first.trajectory)
    residuals = measurement_residuals(meas, first.trajectory)
    sigmas = measurement_sigmas(meas)
    # A mean of n neighbours is as sure as n factors say (correlated errors average down less).
    shared = measurement_sigmas(meas, information=True)

    # 1. Absolute measurements, one by one, and the mean of their
    #    neighbours: a disturbance ramps up and down, and its shoulders are
    #    biased well inside one measurement's noise.
    kept: dict[str, dict[str, int]] = {}
    half = 0.5 * gating.recheck_window_s
    for factor, mask in gated.items():
        if factor not in gating.recheck_factors:
            continue
        rows = np.flatnonzero(mask.any(axis=1) & np.isfinite(residuals[factor]).any(axis=1))
        counts = dict.fromkeys(FACTOR_DOFS[factor], 0)
        res, sig, info = residuals[factor], sigmas[factor], shared[factor]
        finite = np.isfinite(res).all(axis=1)
        t = meas.t
        for k in rows:
            if k == 0 and factor in (*BETWEEN, "gyro"):
                continue
            est = _estimate_sigmas(factor, k, first.marginals, values)
            z = res[k] / np.sqrt(sig[k] ** 2 + est**2)
            # The neighbours within half a window, looked for only among the
            # keyframes within a whole one (the times increase), so a row
            # costs the same however long the run.
            lo, hi = np.searchsorted(t, t[k] - 2.0 * half), np.searchsorted(t, t[k] + 2.0 * half, side="right")
            near = (np.abs(t[lo:hi] - t[k]) <= half) & finite[lo:hi]
            n = int(near.sum())
            mean = res[lo:hi][near].mean(axis=0)
            z_mean = mean / np.sqrt((info[lo:hi][near] ** 2).mean(axis=0) / n + est**2)
            agree = mask[k] & (np.abs(z) <= k_sigma) & (np.abs(z_mean) <= k_sigma)
            weights[factor][k, agree] = 1.0
            for d in np.flatnonzero(agree):
                counts[FACTOR_DOFS[factor][d]] += 1
        kept[factor] = counts

    # 2. Baselines of the between factors still excluded step by step.
    constraints, tried = [], 0
    # The estimate's covariance over each stretch, asked of GTSAM once: where
    # several degrees of freedom are excluded together, their baselines span
    # the same keyframes, and each query walks the Bayes tree.
    relative_cov: dict[tuple[int, int], np.ndarray] = {}
    for factor in gating.baseline_factors:
        m = meas.get(factor)
        if factor not in BETWEEN or m is None:
            continue
        for d, dof in enumerate(FACTOR_DOFS[factor]):
            for c in _baselines(meas, factor, d, weights[factor], gating.baseline_m):
                tried += 1
                if (c.i, c.j) not in relative_cov:
                    relative_cov[c.i, c.j] = _relative_cov(first.marginals, values, c.i, c.j)
                est = relative_cov[c.i, c.j]
                traj = first.trajectory
                ref = relative_poses(
                    np.array([[traj.x[c.i], traj.y[c.i], traj.yaw[c.i]]]),
                    np.array([[traj.x[c.j], traj.y[c.j], traj.yaw[c.j]]]),
                )[0]
                # The baseline measures one degree of freedom; the others are
                # the estimate's, so its residual is read in a frame that is right.
                delta = ref.copy()
                delta[d] = c.delta[d]
                err = relative_poses(ref[None], delta[None])[0]
                z = err[d] / np.sqrt(c.sigma[d] ** 2 + max(est[d, d], 0.0))
                if abs(z) <= k_sigma:
                    constraints.append(RelativeConstraint(c.i, c.j, delta, c.sigma, c.kind, c.label))
    metrics = {
        "recheck": {
            "kept": kept,
            "baselines_tried": tried,
            "baselines_kept": len(constraints),
        }
    }
    log.info("recheck: kept %s, %d of %d baselines", kept, len(constraints), tried)
    return RecheckResult(weights, constraints, metrics)


def _baselines(meas: Measurements, factor: str, d: int, weights: np.ndarray, length_m: float) -> list[RelativeConstraint]:
    """Baselines over the stretches where degree of freedom ``d`` of
    ``factor`` is excluded: chained from the keyframe before each stretch,
    each ``length_m`` of path long (the last one shorter), measuring only
    that degree of freedom."""
    m = meas.get(factor)
    excluded = ~np.isfinite(weights[:, d]) & m.valid
    step_len = np.hypot(m.delta[:, 0], m.delta[:, 1])
    out: list[RelativeConstraint] = []
    k, n = 1, len(excluded)
    while k < n:
        if not excluded[k]:
            k += 1
            continue
        start = k - 1
        pose = np.zeros(3)
        var = np.zeros(3)
        travelled = 0.0
        while k < n and excluded[k]:
            pose = _compose(pose, m.delta[k])
            var += m.sigma[k] ** 2
            travelled += step_len[k]
            end = k
            k += 1
            if travelled >= length_m or k >= n or not excluded[k]:
                sigma = np.full(3, np.inf)
                sigma[d] = np.sqrt(var[d])
                out.append(RelativeConstraint(start, end, pose.copy(), sigma, factor, f"{factor}_baseline"))
                start, pose, var, travelled = end, np.zeros(3), np.zeros(3), 0.0
    return out


def _compose(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Planar pose ``a * b`` (x, y, yaw)."""
    c, s = np.cos(a[2]), np.sin(a[2])
    return np.array([a[0] + c * b[0] - s * b[1], a[1] + s * b[0] + c * b[1], wrap_angle(a[2] + b[2])])
