"""GTSAM Pose2 back-end over keyframes.

The graph is built step by step: step ``k`` adds the factors that end at
keyframe ``k`` (between factors from k-1, priors at k). Batch optimisation
(Levenberg-Marquardt or GTSAM's graduated non-convexity) adds all steps and
solves once; iSAM2 adds one step at a time as it would run on the robot.

Each factor's noise is scaled per step by a *weight* (a sigma multiplier)
that sensor validation decides: 1 keeps the configured noise, k > 1
inflates it, ``inf`` excludes the factor.

Loop closures (slam.loops) join the step of their later keyframe as
between factors to the earlier one. With loops, GNC can serve as the
optimiser-level fallback: every factor but the loops is a known inlier.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Sequence
from dataclasses import dataclass, field

import gtsam
import numpy as np

from slam.config import BackendConfig
from slam.graph.factors import (
    between_factor,
    gaussian,
    pose_key,
    position_prior_factor,
    yaw_increment_factor,
    yaw_only_noise,
    yaw_prior_factor,
)
from slam.graph.loop_factors import LoopFactors, loop_factor, loop_noise
from slam.graph.measurements import FACTOR_DOFS, FACTOR_TYPES, Measurements, RelativeConstraint
from slam.recording import Trajectory

log = logging.getLogger(__name__)

FactorWeights = dict[str, np.ndarray]
"""Per factor type, sigma multipliers per step and degree of freedom
(K, len(FACTOR_DOFS[type])); ``inf`` excludes that degree of freedom. A
(K,) array applies to every degree of freedom of the step."""


def unit_weights(n_steps: int) -> FactorWeights:
    """Every factor included with its configured noise."""
    return {f: np.ones((n_steps, len(FACTOR_DOFS[f]))) for f in FACTOR_TYPES}


def dof_weights(weights: np.ndarray, factor: str) -> np.ndarray:
    """``weights`` of one factor type as (K, dofs): a (K,) array is broadcast."""
    w = np.asarray(weights, dtype=float)
    dofs = len(FACTOR_DOFS[factor])
    if w.ndim == 1:
        return np.repeat(w[:, None], dofs, axis=1)
    if w.ndim != 2 or w.shape[1] != dofs:
        raise ValueError(f"weights of {factor}: expected (K,) or (K, {dofs}), got {w.shape}")
    return w


@dataclass
class BackendResult:
    """Optimised keyframe poses and bookkeeping.

    ``factor_counts``: factors of each type in the graph. ``fallback_steps``:
    steps where every translational factor was excluded and the least
    penalised one was kept, inflated, so the graph stays connected.
    ``update_latencies_s``: with iSAM2, the wall time (s) of each keyframe's
    step as it would run online: building its factors, ``ISAM2.update`` and
    reading back the new pose (needed for the next prediction); ``None``
    for batch optimisation.
    """

    trajectory: Trajectory
    build_time_s: float
    optimise_time_s: float
    factor_counts: dict[str, int] = field(default_factory=dict)
    fallback_steps: int = 0
    iterations: int = 0
    update_latencies_s: np.ndarray | None = None
    marginals: gtsam.Marginals | None = None


def robust_kernel(kernel: str, c: float):
    if kernel == "none":
        return None
    est = gtsam.noiseModel.mEstimator
    return {"huber": est.Huber, "cauchy": est.Cauchy, "dcs": est.DCS}[kernel].Create(c)


def _kernels(config: BackendConfig) -> dict[str, object]:
    """The M-estimator of each factor type: its own, else the back-end's."""
    out = {}
    for factor in FACTOR_TYPES:
        fc = getattr(config.factors, factor)
        kernel = fc.robust_kernel if fc.robust_kernel is not None else config.robust_kernel
        param = fc.robust_param if fc.robust_param is not None else config.robust_param
        out[factor] = robust_kernel(kernel, param)
    return out


class GraphBuilder:
    """Turns measurements and weights into GTSAM factors, one step at a time.

    A weight scales the sigma of one degree of freedom of one factor; an
    infinite weight gives that degree of freedom zero precision, and a
    factor whose every degree of freedom is excluded is left out.
    """

    BETWEEN = ("odometry", "scan_matching")

    def __init__(
        self,
        meas: Measurements,
        weights: FactorWeights,
        config: BackendConfig,
        constraints: Sequence[RelativeConstraint] = (),
        loops: LoopFactors | None = None,
    ):
        self.meas = meas
        self.weights = {f: dof_weights(w, f) for f, w in weights.items()}
        self.config = config
        self.robust = _kernels(config)
        self.counts = {f: 0 for f in FACTOR_TYPES}
        self.fallback_steps = 0
        self.constraints: dict[int, list[RelativeConstraint]] = {}
        for c in constraints:
            if not 0 <= c.i < len(meas) or not 0 <= c.j < len(meas) or c.i == c.j:
                raise ValueError(f"constraint {c.label} {c.i}->{c.j}: keyframes out of range or equal")
            self.constraints.setdefault(max(c.i, c.j), []).append(c)
        self.loops = loops
        self._loops_at = loops.by_keyframe() if loops is not None else {}
        if loops is not None:
            self.counts["loop"] = 0

    def _weight(self, factor: str, k: int) -> np.ndarray:
        w = self.weights.get(factor)
        return np.ones(len(FACTOR_DOFS[factor])) if w is None else w[k]

    def _available(self, factor: str, k: int) -> bool:
        m = self.meas.get(factor)
        return m is not None and bool(m.valid[k])

    def _relative_weights(self, k: int) -> dict[str, np.ndarray]:
        """Weights of the relative factors (between factors and the gyro) at
        step k. Where validation leaves no relative constraint on x, y or
        yaw, the least penalised measurement of that degree of freedom stays,
        inflated by ``fallback_inflation``, so the graph stays connected."""
        present = {f: self._weight(f, k).copy() for f in (*self.BETWEEN, "gyro") if self._available(f, k)}
        fell_back = False
        for d, dof in enumerate(("x", "y", "yaw")):
            holders = [f for f in present if dof in FACTOR_DOFS[f]]
            if not holders or any(np.isfinite(present[f][FACTOR_DOFS[f].index(dof)]) for f in holders):
                continue
            keep = "odometry" if "odometry" in holders else holders[0]
            present[keep][FACTOR_DOFS[keep].index(dof)] = self.config.fallback_inflation
            fell_back = True
        self.fallback_steps += fell_back
        return present

    def step(self, k: int) -> list[gtsam.NonlinearFactor]:
        """Factors of step ``k``; step 0 holds only what is measured at k = 0."""
        m, out = self.meas, []
        if k > 0:
            relative = self._relative_weights(k)
            for factor, w in relative.items():
                if not np.any(np.isfinite(w)):
                    continue
                meas = m.get(factor)
                if factor == "gyro":
                    noise = yaw_only_noise(meas.information_sigma[k] * w[0], self.robust["gyro"])
                    out.append(yaw_increment_factor(k, meas.value[k], noise))
                else:
                    noise = gaussian(meas.sigma[k] * w, self.robust[factor])
                    out.append(between_factor(k, self._patched(factor, k, w, relative), noise))
                self.counts[factor] += 1
        if self._available("compass", k) and np.isfinite(w := self._weight("compass", k)[0]):
            noise = gaussian([m.compass.information_sigma[k] * w], self.robust["compass"])
            out.append(yaw_prior_factor(k, m.compass.value[k], noise))
            self.counts["compass"] += 1
        if self._available("gps", k) and np.any(np.isfinite(w := self._weight("gps", k))):
            out.append(position_prior_factor(k, m.gps.xy[k], gaussian(m.gps.sigma[k] * w, self.robust["gps"])))
            self.counts["gps"] += 1
        for c in self.constraints.get(k, ()):
            if c.information is not None:
                noise = loop_noise(c.information, self.robust.get(c.kind))
            else:
                noise = gaussian(c.sigma, self.robust.get(c.kind))
            out.append(gtsam.BetweenFactorPose2(pose_key(c.i), pose_key(c.j), gtsam.Pose2(*c.delta), noise))
            self.counts[c.label] = self.counts.get(c.label, 0) + 1
        return out + self.loop_factors(k)

    def loops_at(self, k: int) -> list:
        """The loop constraints whose later keyframe is ``k``."""
        return self._loops_at.get(k, [])

    def loop_factors(self, k: int) -> list[gtsam.NonlinearFactor]:
        """The loop factors that end at keyframe ``k``."""
        lf = self.loops
        out = []
        for lp in self.loops_at(k):
            out.append(loop_factor(lp, lf.robust, lf.inflation.get(lp.id, 1.0)))
            self.counts["loop"] += 1
        return out

    def _patched(self, factor: str, k: int, w: np.ndarray, relative: dict[str, np.ndarray]) -> np.ndarray:
        """The step's relative pose with each excluded degree of freedom taken
        from another relative measurement that keeps it.

        A Pose2 between factor's residual is formed in the measured pose's
        frame, so a grossly wrong value in a zero-precision degree of freedom
        still leaks into the others (a scan matcher that turned 40 deg the
        wrong way rotates its own translation residual by 40 deg). The
        excluded value says nothing; the kept ones must be read in a frame
        that is right."""
        delta = np.array(self.meas.get(factor).delta[k], dtype=float)
        for d, dof in enumerate(("x", "y", "yaw")):
            if np.isfinite(w[d]):
                continue
            for other, ow in relative.items():
                if other == factor or dof not in FACTOR_DOFS[other]:
                    continue
                i = FACTOR_DOFS[other].index(dof)
                if np.isfinite(ow[i]):
                    om = self.meas.get(other)
                    delta[d] = om.value[k] if other == "gyro" else om.delta[k][d]
                    break
        return delta

    def anchor(self, pose0: np.ndarray) -> gtsam.NonlinearFactor:
        """Prior that fixes the graph's frame at the first keyframe."""
        c = self.config
        sig = np.array([c.initial_sigma_xy_m, c.initial_sigma_xy_m, np.radians(c.initial_sigma_yaw_deg)])
        return gtsam.PriorFactorPose2(pose_key(0), gtsam.Pose2(*pose0), gaussian(sig))

    def predict(self, k: int, previous: gtsam.Pose2) -> gtsam.Pose2:
        """Initial guess of keyframe k from k-1: odometry, else scan matching,
        else the gyro's yaw increment, else standing still."""
        for factor in self.BETWEEN:
            if self._available(factor, k):
                return previous.compose(gtsam.Pose2(*self.meas.get(factor).delta[k]))
        if self._available("gyro", k):
            return previous.compose(gtsam.Pose2(0.0, 0.0, self.meas.gyro.value[k]))
        return previous


def _to_trajectory(t: np.ndarray, values: gtsam.Values) -> Trajectory:
    poses = np.array([[p.x(), p.y(), p.theta()] for p in (values.atPose2(pose_key(k)) for k in range(len(t)))])
    return Trajectory(t=t.copy(), x=poses[:, 0], y=poses[:, 1], yaw=poses[:, 2])


def _optimise_batch(graph, initial, config: BackendConfig, anchor_index: int):
    if config.optimizer.startswith("gnc"):
        params = gtsam.GncLMParams()
        params.setLossType(gtsam.GncLossType.TLS if config.optimizer == "gnc_tls" else gtsam.GncLossType.GM)
        params.setKnownInliers([anchor_index])
        optimizer = gtsam.GncLMOptimizer(graph, initial, params)
        if config.gnc_inlier_probability is not None:
            optimizer.setInlierCostThresholdsAtProbability(config.gnc_inlier_probability)
        return optimizer.optimize(), 0
    params = gtsam.LevenbergMarquardtParams()
    params.setMaxIterations(config.max_iterations)
    params.setRelativeErrorTol(config.relative_error_tol)
    optimizer = gtsam.LevenbergMarquardtOptimizer(graph, initial, params)
    result = optimizer.optimize()
    return result, optimizer.iterations()


def _closed_at(start: gtsam.Pose2, loop, predicted: gtsam.Pose2) -> gtsam.Pose2:
    """Where ``loop`` puts its later keyframe, seen from its earlier one at
    ``start``. A loop that says nothing of the yaw leaves the ``predicted``
    pose: moving the position alone would break the dead reckoning that
    follows (measured on libRSF Corridor: ATE 2.1 m from the prediction,
    9.6 m with the positions moved)."""
    if loop.information[2, 2] == 0.0:
        return predicted
    return start.compose(gtsam.Pose2(*loop.delta))


def _optimise_gnc_loops(graph, initial, loop_indices: list[int]):
    """GNC (truncated least squares) where only loop factors may be outliers:
    every other factor, the anchor included, is a known inlier."""
    params = gtsam.GncLMParams()
    params.setLossType(gtsam.GncLossType.TLS)
    loops = set(loop_indices)
    params.setKnownInliers([k for k in range(graph.size()) if k not in loops])
    optimizer = gtsam.GncLMOptimizer(graph, initial, params)
    return optimizer.optimize(), 0


def optimise(
    meas: Measurements,
    initial_pose: np.ndarray,
    config: BackendConfig,
    weights: FactorWeights | None = None,
    progress: bool = False,
    isam2_params: gtsam.ISAM2Params | None = None,
    constraints: Sequence[RelativeConstraint] = (),
    marginals: bool = False,
    loops: LoopFactors | None = None,
    initial_poses: np.ndarray | None = None,
) -> BackendResult:
    """Build the keyframe graph and optimise it (batch, GNC or iSAM2).

    ``initial_pose`` (x, y, yaw) anchors keyframe 0 in the world frame.
    ``isam2_params``: iSAM2 settings (relinearisation threshold and skip)
    instead of GTSAM's defaults; used only by the iSAM2 optimiser.
    ``constraints``: between factors over any two keyframes, added at the
    later one. ``marginals``: also return the estimate's marginal
    covariances (:class:`gtsam.Marginals`; batch optimisers only).
    ``loops``: loop closures to add. A keyframe that closes a loop starts
    where the loop puts it, not where dead reckoning does (far off after a
    long drift, too far for Levenberg-Marquardt). ``initial_poses`` (K, 3),
    world frame: where the batch optimisers start instead (an estimate
    that already holds the loops, e.g. the submaps').
    """
    n = len(meas)
    builder = GraphBuilder(meas, weights if weights is not None else unit_weights(n), config, constraints, loops)
    steps = range(n)
    if progress:
        from tqdm import tqdm

        steps = tqdm(steps, desc="graph", unit="kf", leave=False, disable=None)  # none when stderr is not a terminal

    if config.optimizer == "isam2":
        params = isam2_params if isam2_params is not None else gtsam.ISAM2Params()
        return _optimise_isam2(builder, meas, np.asarray(initial_pose, float), steps, params)

    start = time.perf_counter()
    graph, initial = gtsam.NonlinearFactorGraph(), gtsam.Values()
    graph.add(builder.anchor(initial_pose))
    pose = gtsam.Pose2(*initial_pose)
    loop_indices = []
    for k in steps:
        if initial_poses is not None:
            pose = gtsam.Pose2(*initial_poses[k])
        elif k > 0:
            pose = builder.predict(k, pose)
            if closing := builder.loops_at(k):
                pose = _closed_at(initial.atPose2(pose_key(closing[0].i)), closing[0], pose)
        initial.insert(pose_key(k), pose)
        n_loops = len(builder.loops_at(k))
        factors = builder.step(k)
        for factor in factors:
            graph.add(factor)
        # The loop factors are the last ones of their step.
        loop_indices.extend(range(graph.size() - n_loops, graph.size()))
    built = time.perf_counter()
    if loops is not None and loops.gnc and loop_indices and config.optimizer == "batch":
        result, iterations = _optimise_gnc_loops(graph, initial, loop_indices)
    else:
        result, iterations = _optimise_batch(graph, initial, config, anchor_index=0)
    done = time.perf_counter()
    if builder.fallback_steps:
        log.info("%d steps had every relative factor of a degree of freedom excluded; kept one inflated",
                 builder.fallback_steps)
    return BackendResult(
        trajectory=_to_trajectory(meas.t, result),
        build_time_s=built - start,
        optimise_time_s=done - built,
        factor_counts=dict(builder.counts),
        fallback_steps=builder.fallback_steps,
        iterations=iterations,
        marginals=_marginals(graph, result) if marginals else None,
    )


WEAK_PRIOR_SIGMA = 1e4
"""Sigma (m, rad) of the priors that make a graph determinate for its
marginals where some degree of freedom has no measurement at all (a
heading-only recording has no position): far above any real uncertainty."""


def _marginals(graph: gtsam.NonlinearFactorGraph, values: gtsam.Values) -> gtsam.Marginals:
    """Marginal covariances of the estimate. Where the graph leaves a degree
    of freedom unmeasured, weak priors on every pose make it determinate
    without changing the others' covariances."""
    try:
        return gtsam.Marginals(graph, values)
    except RuntimeError:
        weak = gtsam.NonlinearFactorGraph(graph)
        noise = gtsam.noiseModel.Isotropic.Sigma(3, WEAK_PRIOR_SIGMA)
        for key in values.keys():
            weak.add(gtsam.PriorFactorPose2(key, values.atPose2(key), noise))
        return gtsam.Marginals(weak, values)


def _optimise_isam2(
    builder: GraphBuilder, meas: Measurements, initial_pose: np.ndarray, steps, params: gtsam.ISAM2Params
) -> BackendResult:
    isam = gtsam.ISAM2(params)
    build_s = opt_s = 0.0
    latencies = np.zeros(len(meas))
    latest = gtsam.Pose2(*initial_pose)
    for k in steps:
        t0 = time.perf_counter()
        graph, values = gtsam.NonlinearFactorGraph(), gtsam.Values()
        if k == 0:
            graph.add(builder.anchor(initial_pose))
        elif loops_here := builder.loops_at(k):
            # A loop says where k is: start it there, from the current
            # estimate of the keyframe it closes on.
            latest = _closed_at(isam.calculateEstimatePose2(pose_key(loops_here[0].i)), loops_here[0], builder.predict(k, latest))
        else:
            latest = builder.predict(k, latest)
        values.insert(pose_key(k), latest)
        for factor in builder.step(k):
            graph.add(factor)
        t1 = time.perf_counter()
        isam.update(graph, values)
        latest = isam.calculateEstimatePose2(pose_key(k))
        t2 = time.perf_counter()
        build_s += t1 - t0
        opt_s += t2 - t1
        latencies[k] = t2 - t0
    t1 = time.perf_counter()
    estimate = isam.calculateEstimate()
    opt_s += time.perf_counter() - t1
    return BackendResult(
        trajectory=_to_trajectory(meas.t, estimate),
        build_time_s=build_s,
        optimise_time_s=opt_s,
        factor_counts=dict(builder.counts),
        fallback_steps=builder.fallback_steps,
        update_latencies_s=latencies,
    )
