"""Trajectory error metrics: ATE, RPE and final drift, planar.

The definitions follow evo (Grupp, https://github.com/MichaelGrupp/evo) so
that our numbers can be checked with ``evo_ape`` / ``evo_rpe`` on the TUM
files every run writes; ``tests/test_evo_agreement.py`` does that.

* Association (:func:`associate`) is evo's ``sync.associate_trajectories``
  with nearest-time matching: every pose of the trajectory with fewer poses
  (the estimate when both are equally long) takes the nearest stamp of the
  other within ``max_dt``; ties go to the earlier stamp.
* ATE (:func:`ate`) is evo's APE with ``pose_relation=trans_part``: the
  per-pose position error ``|p_k - q_k|`` (m), optionally after the
  least-squares rigid SE(2) alignment of the estimate onto the reference
  (``evo_ape -a``; Umeyama without scale, which for planar data equals evo's
  3D alignment).
* RPE (:func:`rpe`) is evo's RPE with ``--delta D --delta_unit m
  --all_pairs --pairs_from_reference`` and the default relative tolerance
  0.1: for every reference pose i, j > i is the pose whose path length along
  the reference from i is closest to D, kept if within ``0.1 D``. The error
  pose is ``E = (Q_i^-1 Q_j)^-1 (P_i^-1 P_j)`` with Q reference and P
  estimate; its translation norm (m) and rotation angle (deg) are averaged
  over the pairs (the mean, as KITTI does) and divided by D:
  ``trans_pct = 100 * mean(|t(E)|) / D`` and ``rot_deg_per_m =
  mean(|angle(E)|) / D``.

Frames and units as in :mod:`slam.recording`.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from slam.errors import GslamError
from validation.base.geometry import wrap_angle
from slam.recording import Trajectory

logger = logging.getLogger(__name__)

DEFAULT_MAX_DT_S = 0.01  # evo's default --t_max_diff
DEFAULT_REL_DELTA_TOL = 0.1  # evo's default --delta_tol


@dataclass(frozen=True)
class AteResult:
    """Statistics of the per-pose position errors ``errors_m`` (m)."""

    errors_m: np.ndarray

    @property
    def rmse_m(self) -> float:
        return float(np.sqrt(np.mean(self.errors_m**2)))

    @property
    def mean_m(self) -> float:
        return float(np.mean(self.errors_m))

    @property
    def median_m(self) -> float:
        return float(np.median(self.errors_m))

    @property
    def max_m(self) -> float:
        return float(np.max(self.errors_m))


@dataclass(frozen=True)
class RpeResult:
    """Relative errors over the index pairs ``pairs`` (k, 2) of the matched
    poses: translation ``trans_errors_m`` (m) and rotation
    ``rot_errors_deg`` (deg, in [0, 180]) for the path length ``delta_m``."""

    delta_m: float
    pairs: np.ndarray
    trans_errors_m: np.ndarray
    rot_errors_deg: np.ndarray

    @property
    def trans_pct(self) -> float:
        """Mean translational error in percent of ``delta_m``."""
        return float(100.0 * np.mean(self.trans_errors_m) / self.delta_m)

    @property
    def rot_deg_per_m(self) -> float:
        """Mean rotational error per metre of path, deg/m."""
        return float(np.mean(self.rot_errors_deg) / self.delta_m)


def _check_sorted(traj: Trajectory, name: str) -> None:
    if len(traj) == 0:
        raise GslamError(f"{name} trajectory is empty")
    if np.any(np.diff(traj.t) < 0.0):
        raise GslamError(f"{name} trajectory: timestamps are not sorted")


def associate(
    est: Trajectory, ref: Trajectory, max_dt: float = DEFAULT_MAX_DT_S
) -> tuple[np.ndarray, np.ndarray]:
    """Index pairs ``(i_est, i_ref)`` of poses with the nearest stamps.

    Walks the trajectory with fewer poses (the estimate if equally long) and
    matches each pose to the nearest stamp of the other, if at most
    ``max_dt`` (s) away; a stamp of the longer one may be used twice. Both
    trajectories must share one time base and be sorted by time.
    """
    _check_sorted(est, "estimated")
    _check_sorted(ref, "reference")
    est_longer = len(est) > len(ref)
    short, long_ = (ref.t, est.t) if est_longer else (est.t, ref.t)

    # 1. Neighbours in the longer stamps: upper (first later) and lower.
    upper = np.minimum(np.searchsorted(long_, short, side="right"), len(long_) - 1)
    diff_ub = long_[upper] - short
    diff_lb = np.where(upper > 0, short - long_[np.maximum(upper - 1, 0)], np.inf)
    # 2. The nearer one within max_dt, the lower one on a tie.
    take_ub = (diff_ub <= max_dt) & (diff_ub < diff_lb)
    take_lb = ~take_ub & (diff_lb <= max_dt) & (diff_lb <= diff_ub)
    inside = (short >= long_[0] - max_dt) & (short <= long_[-1] + max_dt)
    ok = inside & (take_ub | take_lb)
    i_short = np.flatnonzero(ok)
    i_long = np.where(take_ub, upper, upper - 1)[ok]
    return (i_long, i_short) if est_longer else (i_short, i_long)


def _matched(
    est: Trajectory, ref: Trajectory, max_dt: float
) -> tuple[Trajectory, Trajectory]:
    """The associated sub-trajectories, at least 2 poses each."""
    i_est, i_ref = associate(est, ref, max_dt)
    if len(i_est) < 2:
        raise GslamError(
            f"only {len(i_est)} pose(s) of the estimate match the reference within "
            f"{max_dt} s: time ranges [{est.t[0]:.3f}, {est.t[-1]:.3f}] s and "
            f"[{ref.t[0]:.3f}, {ref.t[-1]:.3f}] s do not overlap or use different time bases"
        )

    def pick(traj: Trajectory, idx: np.ndarray) -> Trajectory:
        return Trajectory(t=traj.t[idx], x=traj.x[idx], y=traj.y[idx], yaw=traj.yaw[idx])

    return pick(est, i_est), pick(ref, i_ref)


def align_se2(est_xy: np.ndarray, ref_xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rigid transform ``(R (2, 2), t (2,))`` minimising
    ``sum |R est_k + t - ref_k|^2`` over corresponding (n, 2) points, m.

    Umeyama's closed form without scale; the sign fix keeps R a rotation.
    """
    est_xy = np.asarray(est_xy, dtype=float)
    ref_xy = np.asarray(ref_xy, dtype=float)
    if est_xy.shape != ref_xy.shape or est_xy.ndim != 2 or est_xy.shape[1] != 2:
        raise GslamError(f"align_se2: expected two (n, 2) arrays, got {est_xy.shape} and {ref_xy.shape}")
    mu_est, mu_ref = est_xy.mean(axis=0), ref_xy.mean(axis=0)
    cov = (ref_xy - mu_ref).T @ (est_xy - mu_est) / len(est_xy)
    u, _, vt = np.linalg.svd(cov)
    s = np.diag([1.0, np.sign(np.linalg.det(u) * np.linalg.det(vt)) or 1.0])
    rot = u @ s @ vt
    return rot, mu_ref - rot @ mu_est


def _ate_matched(est: Trajectory, ref: Trajectory, align: bool) -> AteResult:
    est_xy, ref_xy = est.xy(), ref.xy()
    if align:
        rot, trans = align_se2(est_xy, ref_xy)
        est_xy = est_xy @ rot.T + trans
    return AteResult(errors_m=np.linalg.norm(est_xy - ref_xy, axis=1))


def ate(
    est: Trajectory, ref: Trajectory, align: bool, max_dt: float = DEFAULT_MAX_DT_S
) -> AteResult:
    """Absolute trajectory error of the associated positions, m; with
    ``align`` the estimate is first rigidly aligned onto the reference."""
    return _ate_matched(*_matched(est, ref, max_dt), align)


def path_pairs(xy: np.ndarray, delta_m: float, tol_m: float) -> np.ndarray:
    """Index pairs (k, 2) ``(i, j)``, one per i, with j > i the pose whose
    path length from i along ``xy`` (n, 2) is nearest to ``delta_m`` (the
    first on a tie), kept if it differs from ``delta_m`` by at most ``tol_m``.
    evo's ``filter_pairs_by_path(..., all_pairs=True)``, vectorised."""
    dist = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(xy, axis=0), axis=1))])
    n = len(dist)
    if n < 2:
        return np.empty((0, 2), dtype=int)
    i = np.arange(n - 1)
    k = np.searchsorted(dist, dist[i] + delta_m, side="left")
    # 1. The nearest lies next to the insertion point; a neighbour either
    #    side covers rounding of dist[i] + delta_m.
    cand = np.clip(k[:, None] + np.array([-2, -1, 0, 1]), i[:, None] + 1, n - 1)
    # 2. On a plateau (robot standing) the first index of equal length wins.
    cand = np.maximum(np.searchsorted(dist, dist[cand], side="left"), i[:, None] + 1)
    err = np.abs((dist[cand] - dist[i][:, None]) - delta_m)
    best = np.argmin(np.where(err == err.min(axis=1, keepdims=True), cand, n), axis=1)
    j = cand[i, best]
    keep = err[i, best] <= tol_m
    return np.column_stack([i[keep], j[keep]])


def _rpe_matched(
    est: Trajectory, ref: Trajectory, delta_m: float, rel_delta_tol: float
) -> RpeResult:
    if not delta_m > 0.0:
        raise GslamError(f"RPE delta must be positive, got {delta_m} m")
    pairs = path_pairs(ref.xy(), delta_m, rel_delta_tol * delta_m)
    i, j = pairs[:, 0], pairs[:, 1]

    def relative(traj: Trajectory) -> tuple[np.ndarray, np.ndarray]:
        # Pose j in the frame of pose i: rotate the offset by -yaw_i.
        c, s = np.cos(traj.yaw[i]), np.sin(traj.yaw[i])
        dx, dy = traj.x[j] - traj.x[i], traj.y[j] - traj.y[i]
        return np.column_stack([c * dx + s * dy, -s * dx + c * dy]), traj.yaw[j] - traj.yaw[i]

    d_ref, dyaw_ref = relative(ref)
    d_est, dyaw_est = relative(est)
    # E = Q_rel^-1 P_rel: its translation is R_Qrel^T (d_est - d_ref), whose
    # norm needs no rotation; its angle is the difference of the yaw changes.
    trans = np.linalg.norm(d_est - d_ref, axis=1)
    rot = np.degrees(np.abs(wrap_angle(dyaw_est - dyaw_ref)))
    return RpeResult(delta_m=float(delta_m), pairs=pairs, trans_errors_m=trans, rot_errors_deg=rot)


def rpe(
    est: Trajectory,
    ref: Trajectory,
    delta_m: float,
    max_dt: float = DEFAULT_MAX_DT_S,
    rel_delta_tol: float = DEFAULT_REL_DELTA_TOL,
) -> RpeResult:
    """Relative pose error over ``delta_m`` metres of reference path (see the
    module docstring). Raises :class:`GslamError` if no pair is that far apart."""
    result = _rpe_matched(*_matched(est, ref, max_dt), delta_m, rel_delta_tol)
    if len(result.pairs) == 0:
        raise GslamError(f"RPE: no pose pairs {delta_m} m apart along the reference path")
    return result


def _delta_key(delta_m: float) -> str:
    return f"{delta_m:g}m"


def evaluate(
    est: Trajectory,
    ref: Trajectory,
    deltas_m: Sequence[float],
    max_dt: float = DEFAULT_MAX_DT_S,
) -> dict[str, float | int | None]:
    """All metrics of one run as a flat, JSON-ready dict.

    ``ate_rmse_m``, ``ate_mean_m``, ``ate_median_m``, ``ate_max_m``: ATE
    after SE(2) alignment; ``ate_rmse_unaligned_m``: without it (m).
    ``rpe_trans_pct_<D>m`` / ``rpe_rot_deg_per_m_<D>m`` per delta D (m), and
    ``rpe_trans_pct`` / ``rpe_rot_deg_per_m`` for the first delta; None where
    the reference path is too short for D (or no delta is given).
    ``yaw_rmse_deg`` / ``yaw_max_deg``: heading error per associated pose,
    without alignment (deg; meaningful when the estimate starts at the
    reference's first pose or its heading is absolute, as with a compass).
    ``final_error_m`` (m) and ``n_matched`` (associated poses).
    """
    m_est, m_ref = _matched(est, ref, max_dt)
    aligned = _ate_matched(m_est, m_ref, align=True)
    unaligned = _ate_matched(m_est, m_ref, align=False)
    out: dict[str, float | int | None] = {
        "ate_rmse_m": aligned.rmse_m,
        "ate_rmse_unaligned_m": unaligned.rmse_m,
        "ate_mean_m": aligned.mean_m,
        "ate_median_m": aligned.median_m,
        "ate_max_m": aligned.max_m,
        "rpe_trans_pct": None,
        "rpe_rot_deg_per_m": None,
    }
    for n, delta in enumerate(deltas_m):
        result = _rpe_matched(m_est, m_ref, float(delta), DEFAULT_REL_DELTA_TOL)
        if len(result.pairs):
            trans, rot = result.trans_pct, result.rot_deg_per_m
        else:
            logger.warning("RPE: reference path too short for delta %g m", delta)
            trans = rot = None
        out[f"rpe_trans_pct_{_delta_key(delta)}"] = trans
        out[f"rpe_rot_deg_per_m_{_delta_key(delta)}"] = rot
        if n == 0:
            out["rpe_trans_pct"], out["rpe_rot_deg_per_m"] = trans, rot
    yaw_error = np.degrees(np.abs(wrap_angle(m_est.yaw - m_ref.yaw)))
    out["yaw_rmse_deg"] = float(np.sqrt(np.mean(yaw_error**2)))
    out["yaw_max_deg"] = float(yaw_error.max())
    out["final_error_m"] = float(unaligned.errors_m[-1])
    out["n_matched"] = len(m_est)
    return out
