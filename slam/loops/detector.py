"""Loop detection and geometric verification over the keyframes of one run.

The keyframes are walked in order, as they would arrive on the robot; the
estimate is the dead-reckoning chain (slam.loops.chain), re-anchored at each
accepted loop. Every ``query_spacing_m`` of path, the current keyframe
becomes a *place*: its local map (the scans just before it) gets a
descriptor, and it looks for loop candidates among earlier places at least
``min_separation_m`` back along the path:

1. geometric: places within ``candidate_distance_m`` of its estimate,
   nearest first, their relative pose from the estimate; the uncertainty
   window (translation and yaw) grows with the path since the last accepted
   loop, as the drift does;
2. place recognition: the places nearest by ring key whose Scan Context
   distance is within ``descriptor.max_distance`` (their relative yaw comes
   from the descriptor, the translation guess is zero).

At most ``max_candidates`` are tried per query, until one is verified. An
accepted geometric loop re-anchors the estimate; a recognised place does not
(it may be a look-alike: the loop observer judges it). Verification: a
branch-and-bound search of the candidate's likelihood field over the
uncertainty window (:mod:`slam.matching.search`), then point-to-line ICP of
the query's local map against the candidate's (:mod:`slam.matching.icp`),
the submaps' own toolbox; accepted with enough overlap and a low residual.
Directions the registration barely constrains (a corridor's axis) are taken
out of the loop's information, so it does not pin them; a loop with fewer
than ``acceptance.min_pinned`` directions left is rejected.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field

import numpy as np

from slam.loops.chain import Chain
from validation.base.geometry import between, compose
from slam.config.loops import LoopsConfig
from validation.loops.constraint import LoopConstraint
from slam.matching.icp import Refinement, refine
from slam.matching.search import branch_and_bound
from slam.matching.descriptor import context_distance, ring_key, scan_context
from slam.loops.local_maps import KeyframePoints, LocalMaps, window

log = logging.getLogger(__name__)

MIN_QUERY_POINTS = 20
"""A query with fewer laser points than this is not a place."""


@dataclass
class Detection:
    """What detection found: verified loops (in the order found), the
    re-anchored estimate (K, 3), the places, and counts and wall time (s)."""

    loops: list[LoopConstraint]
    estimate: np.ndarray
    places: list[int] = field(default_factory=list)
    candidates: int = 0
    registrations: int = 0
    rejected: dict[str, int] = field(default_factory=dict)
    time_s: float = 0.0


@dataclass
class _Candidate:
    place: int  # keyframe index of the candidate place
    guess: np.ndarray  # pose of the query in its frame
    linear_m: float  # search window
    angular_rad: float
    descriptor_distance: float  # NaN for a geometric candidate
    geometric: bool  # guess from the estimate (else from the descriptor)


def pinned_information(reg: Refinement, length_m: float, min_relative: float) -> tuple[np.ndarray | None, int]:
    """The registration's information in the loop's convention (frame of the
    query), without the directions it barely constrains, and how many
    directions are kept.

    Yaw is compared with translation at ``length_m`` (a rotation by dyaw
    moves points at that range by ``length_m * dyaw``). A direction whose
    information is below ``min_relative`` of the strongest direction's is
    removed: the point-to-line information treats every point as
    independent, so its absolute size says little, but its shape does (a
    corridor's axis gets only the noise of the wall normals)."""
    c, s = np.cos(reg.pose[2]), np.sin(reg.pose[2])
    a = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    info = a.T @ reg.information @ a  # d_map = A d_query
    scale = np.array([1.0, 1.0, 1.0 / length_m])
    values, vectors = np.linalg.eigh(info * np.outer(scale, scale))
    if values[-1] <= 0.0:
        return None, 0
    keep = values >= min_relative * values[-1]
    scaled = (vectors[:, keep] * values[keep]) @ vectors[:, keep].T
    inv = 1.0 / scale
    return scaled * np.outer(inv, inv), int(keep.sum())


class LoopDetector:
    """Runs detection over one run; see the module docstring."""

    def __init__(self, points: KeyframePoints, chain: Chain, config: LoopsConfig):
        self.points = points
        self.chain = chain
        self.config = config
        self.maps = LocalMaps(
            points, chain.path_m, config.local_map_m, config.local_map_scans, config.registration,
            config.max_search_radius_m + config.registration.max_distance_m,
        )

    def run(self) -> Detection:
        cfg, chain = self.config, self.chain
        start = time.perf_counter()
        n = len(chain)
        est = chain.poses.copy()
        det = Detection(loops=[], estimate=est)
        keys: list[np.ndarray] = []
        contexts: list[np.ndarray] = []
        last_query_m = -np.inf
        last_loop_m = 0.0
        for j in range(1, n):
            est[j] = compose(est[j - 1], chain.deltas[j])
            s_j = chain.path_m[j]
            if s_j - last_query_m < cfg.query_spacing_m:
                continue
            last_query_m = s_j
            query = self.points.gather(j, window(chain.path_m, j, cfg.query_map_m, 0.0, cfg.local_map_scans), est)[0]
            if len(query) < MIN_QUERY_POINTS:
                continue  # nothing in range (an open yard): no place here
            d = cfg.descriptor
            context = scan_context(query, d.rings, d.sectors, d.max_radius_m)
            key = ring_key(context)
            since = s_j - last_loop_m
            radius = min(cfg.search_radius_m + cfg.search_radius_per_m * since, cfg.max_search_radius_m)
            yaw = np.radians(min(cfg.search_yaw_deg + cfg.search_yaw_per_m_deg * since, cfg.max_search_yaw_deg))
            candidates = self._candidates(j, est, det.places, keys, contexts, context, key, radius, yaw)
            det.places.append(j)
            keys.append(key)
            contexts.append(context)
            det.candidates += len(candidates)
            for cand in candidates:
                loop = self._verify(j, cand, query, est, det)
                if loop is not None:
                    loop.id = len(det.loops)
                    det.loops.append(loop)
                    # Only a loop found where the estimate expected it moves
                    # the estimate: a recognised place may be a look-alike.
                    if cand.geometric:
                        est[j] = compose(est[cand.place], loop.delta)
                        last_loop_m = s_j
                    break
        det.time_s = time.perf_counter() - start
        log.info(
            "loops: %d places, %d candidates, %d registrations, %d verified in %.2f s",
            len(det.places), det.candidates, det.registrations, len(det.loops), det.time_s,
        )
        return det

    def _candidates(self, j, est, places, keys, contexts, context, key, radius, yaw) -> list[_Candidate]:
        """Candidates of query ``j``: earlier places whose local map covers
        its estimate (nearest first), then places recognised by descriptor."""
        cfg = self.config
        if not places:
            return []
        idx = np.asarray(places)
        path = self.chain.path_m
        far = (path[j] - path[idx] >= cfg.min_separation_m) & (path[idx] + cfg.local_map_m < path[j] - cfg.query_map_m)
        if not far.any():
            return []
        idx_far = np.flatnonzero(far)
        dist = np.hypot(*(est[idx[idx_far], :2] - est[j, :2]).T)
        order = np.argsort(dist, kind="stable")
        # Geometric candidates go nearest first: no descriptor needed.
        found: dict[int, _Candidate] = {}
        for p in idx_far[order[dist[order] <= cfg.candidate_distance_m]][: cfg.max_candidates]:
            found[int(p)] = _Candidate(int(idx[p]), between(est[idx[p]], est[j]), radius, yaw, np.nan, True)
        d = cfg.descriptor
        if d.candidates > 0 and len(found) < cfg.max_candidates:
            key_dist = np.linalg.norm(np.asarray(keys)[idx_far] - key, axis=1)
            sector = 2.0 * np.pi / d.sectors
            for p in idx_far[np.argsort(key_dist, kind="stable")[: d.candidates]]:
                if int(p) in found:
                    continue
                distance, rel_yaw = context_distance(contexts[p], context)
                if distance <= d.max_distance:
                    guess = np.array([0.0, 0.0, rel_yaw])
                    found[int(p)] = _Candidate(int(idx[p]), guess, d.linear_window_m, 1.5 * sector, distance, False)
        return list(found.values())[: cfg.max_candidates]

    def _verify(self, j: int, cand: _Candidate, query: np.ndarray, est: np.ndarray, det: Detection) -> LoopConstraint | None:
        cfg = self.config
        reg_cfg, acc, cor = cfg.registration, cfg.acceptance, cfg.correlative
        det.registrations += 1
        guess = cand.guess
        if cand.linear_m > cor.skip_below_m or cand.angular_rad > np.radians(cor.skip_below_deg):
            step = max(len(query) // cor.max_points, 1)
            # At most 11 x 11 translations and 15 yaws, however wide the
            # window: ICP refines what the coarse grid leaves.
            resolution = max(cor.resolution_m, cand.linear_m / 5.0)
            angular_step = max(np.radians(cor.angular_step_deg), cand.angular_rad / 7.0)
            pyr = self.maps.score_pyramid(cand.place, est, resolution, cand.linear_m)
            found = branch_and_bound(pyr, query[::step], guess, cand.linear_m, cand.angular_rad,
                                     angular_step_rad=angular_step, tie_tolerance=cor.tie_tolerance)
            if found is not None:
                guess = found.pose
        pm = self.maps.point_map(cand.place, est)
        reg = refine(query, pm, guess, reg_cfg.max_distance_m, reg_cfg.inlier_distance_m, reg_cfg.kernel_m,
                     reg_cfg.max_iterations)

        def reject(reason: str) -> None:
            det.rejected[reason] = det.rejected.get(reason, 0) + 1

        if reg.inliers < acc.min_overlap:
            reject("overlap")
            return None
        if reg.rms_m > acc.max_rms_m:
            reject("residual")
            return None
        moved = reg.pose - cand.guess
        if np.hypot(*moved[:2]) > cand.linear_m + acc.max_correction_m:
            reject("correction")
            return None
        extent = float(np.median(np.hypot(query[:, 0], query[:, 1])))
        info, dims = pinned_information(reg, max(extent, 1.0), acc.min_relative_information)
        if info is None or dims < acc.min_pinned:
            reject("degenerate")
            return None
        quality = {
            "overlap": round(reg.inliers, 3),
            "rms_m": round(reg.rms_m, 4),
            "descriptor_distance": round(cand.descriptor_distance, 3),
            "pinned_dims": dims,
        }
        return LoopConstraint(0, cand.place, j, reg.pose.copy(), info * cfg.information_scale, "scans", quality)
