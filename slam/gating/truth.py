"""True fault intervals: helpers shared by the simulator and the pipeline.

The simulator labels each sensor from physics (slam.sim.faults). Scan
matching is a special case: the simulator can say when the scan geometry
cannot constrain a pose, but not what KISS-ICP makes of it (after a blind
stretch its local map is wrong for a while, even once walls are back in
range). So where ground truth exists, the pipeline adds the times where the
front-end's output is wrong: its motion over ``window_s`` differs from the
true motion by more than ``max_trans_m`` or ``max_yaw_deg``, far beyond its
nominal error (millimetres and hundredths of a degree per scan here).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from slam.recording import Interval, Trajectory, intervals_from_mask


def scan_matching_output_faults(
    sm: Trajectory,
    groundtruth: Trajectory,
    window_s: float = 1.0,
    max_trans_m: float = 0.15,
    max_yaw_deg: float = 3.0,
    merge_gap_s: float = 1.0,
    min_duration_s: float = 0.5,
) -> dict[str, list[Interval]]:
    """Times (s) where the scan matcher's motion over ``window_s`` is wrong,
    per modality: ``SM_DIST`` where its motion along the heading is off by
    more than ``max_trans_m``, ``SM_LAT`` sideways, ``SM_YAW`` where its turn
    is off by more than ``max_yaw_deg``.

    A scan is marked when the relative pose from the scan ``window_s``
    earlier differs from the true one by more than the limits; the marks are
    merged into intervals (module docstring).
    """
    from slam.recording import interpolate_poses, relative_poses

    t = sm.t
    est = np.column_stack([sm.x, sm.y, sm.yaw])
    true = interpolate_poses(groundtruth, t)
    prev = np.searchsorted(t, t - window_s)
    valid = (t - window_s >= t[0]) & (t >= groundtruth.t[0]) & (t <= groundtruth.t[-1])
    e = relative_poses(est[prev], est) - relative_poses(true[prev], true)
    e[:, 2] = np.angle(np.exp(1j * e[:, 2]))
    limits = {"SM_DIST": (0, max_trans_m), "SM_LAT": (1, max_trans_m), "SM_YAW": (2, np.radians(max_yaw_deg))}
    out = {}
    for name, (dof, limit) in limits.items():
        wrong = valid & (np.abs(e[:, dof]) > limit)
        # A wrong window implicates every scan in it, from its start.
        marked = wrong.copy()
        for i in np.flatnonzero(wrong):
            marked[prev[i] : i] = True
        out[name] = intervals_from_mask(t, marked, merge_gap_s, min_duration_s)
    return out


@dataclass
class TightOracle:
    """The tight oracle's decisions: ``weights`` per factor type (K, dofs),
    ``inf`` where the measurement's error exceeds ``k_sigma`` sigmas, and
    the normalised errors ``z`` (error / sigma, NaN where absent)."""

    t: np.ndarray
    k_sigma: float
    z: dict[str, np.ndarray]
    weights: dict[str, np.ndarray]

    def metrics(self) -> dict:
        """``alarm_fraction``: keyframes where any degree of freedom is
        excluded; ``excluded_dofs``: per factor type and degree of freedom,
        the keyframes excluded. Isolation figures need a diagnosis: null."""
        from slam.graph.measurements import FACTOR_DOFS

        any_excluded = np.zeros(len(self.t), dtype=bool)
        counts = {}
        for factor, w in self.weights.items():
            bad = ~np.isfinite(w)
            any_excluded |= bad.any(axis=1)
            counts[factor] = {d: int(bad[:, i].sum()) for i, d in enumerate(FACTOR_DOFS[factor])}
        return {
            "alarm_fraction": round(float(any_excluded.mean()) if len(self.t) else 0.0, 5),
            "isolation_precision": None,
            "isolation_recall": None,
            "detection_delay_s": None,
            "oracle_k_sigma": self.k_sigma,
            "excluded_dofs": counts,
        }

    def csv_text(self) -> str:
        """Per keyframe: each measurement's normalised error and whether it is excluded."""
        import csv
        import io

        from slam.graph.measurements import FACTOR_DOFS

        cols: dict[str, list] = {"t": [round(float(x), 4) for x in self.t]}
        for factor, z in self.z.items():
            for i, d in enumerate(FACTOR_DOFS[factor]):
                cols[f"{factor}.{d}.z"] = ["" if not np.isfinite(v) else round(float(v), 3) for v in z[:, i]]
                cols[f"{factor}.{d}.excluded"] = [int(not np.isfinite(w)) for w in self.weights[factor][:, i]]
        out = io.StringIO()
        writer = csv.writer(out, lineterminator="\n")
        writer.writerow(cols)
        writer.writerows(zip(*cols.values()))
        return out.getvalue()


def tight_oracle_weights(meas, groundtruth: Trajectory, k_sigma: float) -> TightOracle:
    """The tight oracle: every degree of freedom of every measurement whose
    error against the truth exceeds ``k_sigma`` times its sigma is excluded
    (``inf``); all others keep their noise (1)."""
    from slam.graph.measurements import measurement_residuals, measurement_sigmas

    errors, sigmas = measurement_residuals(meas, groundtruth), measurement_sigmas(meas)
    weights, zs = {}, {}
    for factor, err in errors.items():
        z = err / sigmas[factor]
        with np.errstate(invalid="ignore"):
            weights[factor] = np.where(np.abs(z) > k_sigma, np.inf, 1.0)
        zs[factor] = z
    return TightOracle(np.asarray(meas.t, dtype=float), k_sigma, zs, weights)
