"""The dead-reckoning chain between keyframes, from the graph's
measurements: per step, the between-measurements (odometry, scan matching,
the gyro's yaw increment) fused by their information with the gating's
weights (:func:`fuse_steps`), and the chain they make (:func:`build_chain`).
A step's covariance is the fused one, plus the disagreement of its sources
when they disagree more than their sigmas say. The chain's algebra and its
uncertainty between keyframes are :mod:`validation.loops.chain`'s."""

from __future__ import annotations

import numpy as np

from slam.graph.backend import dof_weights
from validation.base.geometry import wrap_angle
from slam.graph.measurements import Measurements
from validation.loops.chain import Chain, chain_from_steps


def fuse_steps(meas: Measurements, weights: dict[str, np.ndarray] | None) -> tuple[np.ndarray, np.ndarray]:
    """Per step, the information-weighted mean of the between-measurements
    (odometry, scan matching; the gyro for yaw only) and its covariance;
    a factor whose weight is ``inf`` (excluded by validation) is left out.
    Steps with no translational measurement keep zero motion and a
    covariance of 1e6 (unknown)."""
    n = len(meas)
    info = np.zeros((n, 3))
    weighted = np.zeros((n, 3))
    first_yaw = np.full(n, np.nan)
    sources: list[tuple[np.ndarray, np.ndarray]] = []

    def weight(name: str) -> np.ndarray:
        """Per step and degree of freedom (K, dofs)."""
        w = None if weights is None else weights.get(name)
        return dof_weights(np.ones(n) if w is None else w, name)

    for name in ("scan_matching", "odometry"):
        m = meas.get(name)
        if m is None:
            continue
        w = weight(name)
        use = m.valid[:, None] & np.isfinite(w)
        sig = m.sigma * np.where(use, w, 1.0)
        inv = np.where(use, 1.0 / sig**2, 0.0)
        first_yaw = np.where(np.isnan(first_yaw) & use[:, 2], m.delta[:, 2], first_yaw)
        sources.append((np.where(use, m.delta, np.nan), inv))
    if meas.gyro is not None:
        w = weight("gyro")[:, 0]
        use = meas.gyro.valid & np.isfinite(w)
        inv = np.zeros((n, 3))
        inv[:, 2] = np.where(use, 1.0 / (meas.gyro.sigma * np.where(use, w, 1.0)) ** 2, 0.0)
        value = np.full((n, 3), np.nan)
        value[:, 2] = np.where(use, meas.gyro.value, np.nan)
        first_yaw = np.where(np.isnan(first_yaw) & use, meas.gyro.value, first_yaw)
        sources.append((value, inv))
    ref_yaw = np.nan_to_num(first_yaw)
    for value, inv in sources:
        v = np.nan_to_num(value)
        v[:, 2] = ref_yaw + wrap_angle(v[:, 2] - ref_yaw)  # average yaw near one branch
        weighted += inv * v
        info += inv
    known = info > 0
    delta = np.where(known, weighted / np.where(known, info, 1.0), 0.0)
    var = np.where(known, 1.0 / np.where(known, info, 1.0), 1e6)
    # Disagreement of the sources beyond what their sigmas explain.
    spread = np.zeros((n, 3))
    for value, inv in sources:
        d = np.where(inv > 0, np.nan_to_num(value) - delta, 0.0)
        d[:, 2] = np.where(inv[:, 2] > 0, wrap_angle(np.nan_to_num(value[:, 2]) - delta[:, 2]), 0.0)
        spread = np.maximum(spread, np.abs(d))
    var = var + spread**2
    delta[:, 2] = wrap_angle(delta[:, 2])
    delta[0] = 0.0
    cov = np.zeros((n, 3, 3))
    cov[:, [0, 1, 2], [0, 1, 2]] = var
    cov[0] = 0.0
    return delta, cov


def build_chain(meas: Measurements, weights: dict[str, np.ndarray] | None, start: np.ndarray) -> Chain:
    """The chain of ``meas`` from pose ``start`` (3,); see :func:`fuse_steps`."""
    deltas, step_cov = fuse_steps(meas, weights)
    return chain_from_steps(deltas, step_cov, np.asarray(start, dtype=float))
