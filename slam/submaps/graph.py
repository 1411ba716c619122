"""Global SLAM over submaps: constraints between scans and earlier submaps,
found while the run is walked in order, and a pose graph that places them.

Every scan is a node; a submap is anchored at its first scan. Two kinds of
constraint join them (Hess et al. 2016, Sec. V):

* *intra*: the pose of a scan in the submap local SLAM matched it against
  (:mod:`slam.submaps.local`);
* *inter*: the pose of a scan in a finished submap it did not help build,
  found by branch and bound around the current global estimate and refined.
  Close along the path such a match undoes the local drift; far along it,
  it closes a loop.

The global estimate is the local trajectory re-placed by the graph: the
graph is optimised every ``optimise_every`` scans once new inter
constraints have come, so the search windows stay small; incrementally
(iSAM2, Kaess et al. 2012), so that an update costs what changed rather
than the whole graph so far, and in batch (Levenberg-Marquardt) after a
recognised place and at the end. Inter constraints
carry a robust kernel while the run is walked; at the end, graduated
non-convexity over the whole graph (every factor but the inter constraints
a known inlier) decides which of them are outliers, and the graph is
optimised again without those.
"""

from __future__ import annotations

import bisect
import logging
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from validation.base.geometry import between, compose, wrap_angle
from slam.matching.descriptor import context_distance, ring_key, scan_context
from slam.graph.loop_factors import loop_noise
from slam.config.submaps import RecognitionConfig, SubmapsConfig
from slam.submaps.local import LocalStep, Match, Submap, match_scan, refine_near
from slam.submaps.near import NearSubmaps
from slam.submaps.scans import ScanPoints

log = logging.getLogger(__name__)

ISAM2_EXTRA_UPDATES = 2
"""iSAM2 updates without new factors after each walk update: a little more
convergence towards the batch optimum the graph would give (see :meth:`GlobalSlam._incremental`)."""
UNKNOWN_VARIANCE = 1e6
"""A chain step with this variance was not measured (slam.loops.chain)."""
UNMATCHED_VARIANCE = (0.25, 0.25, 0.25)
"""Variance of a step neither measured nor matched: the local SLAM's
predicted pose, loosely (m^2, m^2, rad^2)."""


@dataclass(frozen=True)
class Constraint:
    """Scan ``scan``'s pose ``delta`` (x, y, yaw) in the frame of keyframe
    ``anchor`` (the first scan of submap ``submap``). ``kind``: ``intra``,
    ``near`` or ``loop``; ``score`` of the search; ``information`` (3, 3)
    of ``delta`` in the anchor's frame, zero along the directions the match
    does not pin (``weak``, unit vectors (k, 3))."""

    submap: int
    anchor: int
    scan: int
    delta: np.ndarray
    kind: str
    score: float
    information: np.ndarray
    weak: np.ndarray


@dataclass
class GlobalResult:
    poses: np.ndarray
    constraints: list[Constraint]
    rejected: list[Constraint] = field(default_factory=list)
    searches: int = 0
    time_s: float = 0.0


def _noise(sigmas, robust=None):
    import gtsam

    noise = gtsam.noiseModel.Diagonal.Sigmas(np.asarray(sigmas, dtype=float))
    return gtsam.noiseModel.Robust.Create(robust, noise) if robust is not None else noise


def drift_allowance(rc: RecognitionConfig, path_m: float, blind_m: float) -> tuple[float, float]:
    """How far (m) and how much (deg) a run can have drifted over ``path_m``
    of path since its last loop, ``blind_m`` of it on dead reckoning alone,
    beyond the recognition's windows (:class:`RecognitionConfig`)."""
    drift_m, turn_deg = rc.max_drift_per_m * path_m, rc.max_turn_per_m_deg * path_m
    if blind_m > 0.0:
        if rc.blind_drift_per_m is not None:
            drift_m += (rc.blind_drift_per_m - rc.max_drift_per_m) * blind_m
        if rc.blind_turn_per_m_deg is not None:
            turn_deg += (rc.blind_turn_per_m_deg - rc.max_turn_per_m_deg) * blind_m
    return drift_m, turn_deg


class LocalFeed:
    """Local SLAM's result as the walk needs it, scan by scan: ``next_step``
    gives the :class:`LocalStep` of each of the ``n`` scans in order, then
    None; :meth:`advance` takes them up to a scan. The walk at scan ``i``
    reads only what local SLAM had done by then, so it can follow local
    SLAM in another process (:func:`slam.submaps.build.build_submap_constraints`).

    Its submaps mirror local SLAM's (the same scans at the same poses); a
    submap is listed as finished once complete, in the order they complete
    (``finishing``, with their last scans ``finish_scans``). ``path`` (n,):
    the local path to each scan; ``blind_path`` (n,): the part of it into
    scans with fewer than ``min_points`` points, walked on dead reckoning
    alone (the laser blind, or its scan left out by the gating)."""

    def __init__(self, points: ScanPoints, n: int, min_points: int, next_step: Callable[[], LocalStep | None]):
        self.points, self.min_points, self.next_step = points, min_points, next_step
        self.poses = np.zeros((n, 3))
        self.matches: list[Match | None] = [None] * n
        self.submaps: list[Submap] = []
        self.member: dict[int, set[int]] = {}  # scan -> the submaps it went into
        self.last_scans: list[int | None] = []  # by submap, once complete
        self.centres: list[np.ndarray | None] = []  # by submap once complete: the mean pose (x, y) in its frame
        self.finishing: list[int] = []
        self.finish_scans: list[int] = []
        self.path = np.zeros(n)
        self.blind_path = np.zeros(n)
        self.done = -1  # the last scan taken
        self.ended = False

    def advance(self, scan: int) -> None:
        """Take the steps up to ``scan``."""
        while self.done < scan:
            self._take(self.next_step())

    def end(self) -> None:
        """Take every step left, and the end."""
        while not self.ended:
            self._take(self.next_step())

    def _take(self, step: LocalStep | None) -> None:
        if step is None:
            self.ended = True
            self.done = len(self.poses) - 1
            self._finish([sid for sid, last in enumerate(self.last_scans) if last is None])
            return
        i = self.done = step.scan
        self.poses[i] = step.pose
        self.matches[i] = step.match
        if i > 0:
            moved = np.hypot(*(self.poses[i, :2] - self.poses[i - 1, :2]))
            self.path[i] = self.path[i - 1] + moved
            blind = len(self.points.points[i]) < self.min_points
            self.blind_path[i] = self.blind_path[i - 1] + (moved if blind else 0.0)
        for sid, pose, step_m in step.inserted:
            if sid == len(self.submaps):
                self.submaps.append(Submap())
                self.last_scans.append(None)
                self.centres.append(None)
            self.submaps[sid].insert(i, pose, step_m)
            self.member.setdefault(i, set()).add(sid)
        self._finish(step.finished)

    def _finish(self, sids) -> None:
        for sid in sids:
            sm = self.submaps[sid]
            sm.finished = True
            self.last_scans[sid] = sm.scans[-1]
            self.centres[sid] = np.mean(sm.poses, axis=0)[:2]
            self.finishing.append(sid)
            self.finish_scans.append(sm.scans[-1])

    def finished_before(self, scan: int) -> int:
        """How many submaps (the first of :attr:`finishing`) were complete before ``scan``."""
        return bisect.bisect_left(self.finish_scans, scan)

    def last_scan_array(self) -> np.ndarray:
        """The last scan of each submap (by id), past the run's end for one still open."""
        return np.array([len(self.poses) if last is None else last for last in self.last_scans], dtype=int)


class UnpinnedPath:
    """The path walked on dead reckoning alone (``blind_path``, (n,) m, of
    :class:`LocalFeed`) between each node and the part of the map its loops
    reach, ``at`` (n,) m. A loop to a submap mapped after a blind stretch
    ties the node to what was mapped since, which is still off from the rest
    by the stretch's drift: it pins nothing of that stretch. Only a loop to a
    submap tied to the map before the stretch does."""

    def __init__(self, blind_path: np.ndarray, points: ScanPoints, min_points: int):
        self.blind_path, self.points, self.min_points = blind_path, points, min_points
        self.at = np.zeros(len(blind_path))

    def reach(self, i: int) -> None:
        """Node ``i``, reached from the one before by local SLAM."""
        if i > 0:
            self.at[i] = self.at[i - 1] + self.blind_path[i] - self.blind_path[i - 1]

    def tie(self, i: int, submap: Submap) -> None:
        """Node ``i`` tied to ``submap`` by a loop: the submap is rigid, so
        it reaches whatever the least pinned of its scans does."""
        placed = [s for s in submap.scans if len(self.points.points[s]) >= self.min_points] or submap.scans[-1:]
        self.at[i] = min(self.at[i], float(self.at[placed].min()))


class GlobalSlam:
    """See the module docstring. ``local``: local SLAM's result, scan by
    scan. ``steps`` (n, 3) and ``step_cov`` (n, 3, 3): the dead-reckoning
    chain between the scans, which the graph keeps beside the
    scan-to-submap constraints. ``before_judging``: given the constraints
    found, before GNC judges them, returns more to judge (a bench's wrong
    loops)."""

    def __init__(self, points: ScanPoints, local: LocalFeed, cfg: SubmapsConfig,
                 steps: np.ndarray, step_cov: np.ndarray,
                 before_judging: Callable[[list[Constraint]], list[Constraint]] | None = None):
        self.points, self.local, self.cfg = points, local, cfg
        self.before_judging = before_judging
        self.steps, self.step_cov = steps, step_cov
        self.path, self.blind_path = local.path, local.blind_path
        self.constraints: list[Constraint] = []
        self._contexts: dict[int, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}
        self._chain: list = []  # the prior and the chain's factors, by node
        self._keys: list[int] = []  # the GTSAM key of each node
        self._chain_graph = None  # the graph of the chain so far, and of the constraints (see _walk_graph)
        self._constraint_graph = None
        self._in_graph: list[Constraint] = []
        self._last_scan = -1
        self._factors: dict[tuple[int, bool], tuple[Constraint, object]] = {}
        self._isam = None  # the walk's iSAM2 (see _incremental), started again after a batch optimisation
        self._isam_n = 0
        self._isam_constraints: list[Constraint] = []

    # -- the walk ---------------------------------------------------------------

    def run(self) -> GlobalResult:
        import gtsam

        cfg, local = self.cfg, self.local
        cc = cfg.constraints
        start = time.perf_counter()
        n = len(local.poses)
        est = np.zeros((n, 3))  # each node's row filled in as the walk reaches it
        near = NearSubmaps(cc.max_distance_m)
        placed_at = 0  # estimate updates so far; the index is placed again after each

        def world(sids: list[int]) -> np.ndarray:
            """The centres of finished submaps ``sids`` in the world, as the estimate places their anchors."""
            anchors = est[[local.submaps[sid].anchor for sid in sids]].reshape(-1, 3)
            c, s_ = np.cos(anchors[:, 2]), np.sin(anchors[:, 2])
            cxy = np.array([local.centres[sid] for sid in sids]).reshape(-1, 2)  # in the anchor's frame
            return anchors[:, :2] + np.column_stack([c * cxy[:, 0] - s_ * cxy[:, 1], s_ * cxy[:, 0] + c * cxy[:, 1]])

        done_count, optimised = 0, 0
        searches = 0
        pending = 0
        last_opt = 0
        last_tied: dict[int, float] = {}  # path at the last inter constraint of each submap
        self.robust = gtsam.noiseModel.mEstimator.Cauchy.Create(cc.robust_scale)
        self.chain_robust = gtsam.noiseModel.mEstimator.Cauchy.Create(cc.robust_scale)
        rc = cfg.recognition
        last_loop, last_try = 0.0, -np.inf  # path at the last loop and at the last recognition tried
        unpinned = UnpinnedPath(self.blind_path, self.points, cfg.min_points)
        recognitions: list[tuple[int, Match, int, np.ndarray]] = []  # (node, match, submap, its global pose)
        for i in range(n):
            local.advance(i)
            est[i] = compose(est[i - 1], between(local.poses[i - 1], local.poses[i])) if i > 0 else local.poses[0]
            unpinned.reach(i)
            self._add_intra(i)
            if len(self.points.points[i]) < cfg.min_points:
                continue
            # Finished submaps (which the scan did not help build), nearest
            # first; their places move only when the estimate is optimised.
            finished = local.finished_before(i)
            if optimised != placed_at:
                near.place(local.finishing[:finished], world(local.finishing[:finished]))
                placed_at = optimised
            elif finished > done_count:
                for sid, xy in zip(local.finishing[done_count:finished], world(local.finishing[done_count:finished])):
                    near.add(sid, xy)
            done_count = finished
            if not finished:
                continue
            tried = 0
            for sid, _ in zip(*near.within(est[i, :2], cc.max_distance_m)):
                if tried >= cc.max_per_scan:
                    break
                if self.path[i] - last_tied.get(sid, -np.inf) < cc.spacing_m:
                    continue
                sm = local.submaps[sid]
                sep = self.path[i] - self.path[sm.scans[-1]]
                loop = sep >= cc.loop_separation_m
                grow = sep
                lin = min(cc.linear_window_m + cc.linear_window_per_m * grow, cc.max_linear_window_m)
                ang = np.radians(min(cc.angular_window_deg + cc.angular_window_per_m_deg * grow, cc.max_angular_window_deg))
                min_score = cc.loop_min_score if loop else cc.near_min_score
                guess = between(est[sm.anchor], est[i])
                tried += 1
                searches += 1
                m = match_scan(sm, self.points, i, guess, cfg, lin, ang, min_score, sid, unique=cfg.ambiguity.enabled,
                               inside=cc.inside)
                if m is None or not m.refined:
                    continue
                self._add_inter(m, sm.anchor, "loop" if loop else "near")
                last_tied[sid] = self.path[i]
                pending += 1
                if loop:
                    last_loop = self.path[i]
                    unpinned.tie(i, sm)
            # Blind path whose drift may exceed what the constraint search covers.
            unpinned_blind = drift_allowance(rc, 0.0, unpinned.at[i])[0] > cc.linear_window_m
            if (rc.enabled and (self.path[i] - last_loop >= rc.min_path_m or unpinned_blind)
                    and self.path[i] - last_try >= rc.spacing_m):
                # Drift may have carried the estimate beyond the windows: recognise the place.
                last_try = self.path[i]
                found, tried = self._recognise(i, est, recognitions, self.path[i] - last_loop, unpinned.at[i])
                searches += tried
                if found:
                    # Without the kernel, so the graph closes the loop; from
                    # then on they are loops like the others, under it.
                    est[: i + 1] = self._optimise(est[: i + 1], i + 1, plain=found)
                    last_opt, pending, last_loop = i, 0, self.path[i]
                    for k in found:
                        unpinned.tie(i, self.local.submaps[self.constraints[k].submap])
                    optimised += 1
            if pending and i - last_opt >= cc.optimise_every:
                est[: i + 1] = self._incremental(est[: i + 1], i + 1)
                last_opt, pending = i, 0
                optimised += 1
        local.end()
        est = self._optimise(est, n)
        if self.before_judging is not None:
            self.constraints.extend(self.before_judging(list(self.constraints)))
        bad = self._gnc_outliers(est, n)
        rejected = [self.constraints[k] for k in bad]
        if bad:
            self.constraints = [c for k, c in enumerate(self.constraints) if k not in bad]
            est = self._optimise(est, n)
        return GlobalResult(est, self.constraints, rejected, searches, time.perf_counter() - start)

    # -- constraints --------------------------------------------------------------

    def _add_intra(self, i: int) -> None:
        m = self.local.matches[i]
        if m is None or not m.refined:
            return
        self._add(m, "intra", before=i)

    def _add_inter(self, m: Match, anchor: int, kind: str) -> None:
        self._add(m, kind)

    # -- place recognition -----------------------------------------------------------

    def _recognise(self, i: int, est: np.ndarray, recognitions: list, unpinned_m: float,
                   blind_m: float) -> tuple[set[int], int]:
        """Look for node ``i``'s surroundings among the finished submaps far
        back along the path (see :class:`RecognitionConfig`), ``unpinned_m``
        of path after the last loop, ``blind_m`` of it on dead reckoning
        alone: the indices of the constraints a confirmed recognition added
        (none if none), and how many searches ran."""
        cfg, rc = self.cfg, self.cfg.recognition
        drift_m, turn_deg = drift_allowance(rc, unpinned_m, blind_m)
        query = self._context_of_node(i)
        last_scan = self.local.last_scan_array()
        far = [sid for sid in np.nonzero(last_scan < i)[0]
               if self.path[i] - self.path[last_scan[sid]] >= cfg.constraints.loop_separation_m]
        if query is None or not far:
            return set(), 0
        contexts = [self._context_of_submap(sid) for sid in far]
        keys = np.array([c[1] for c in contexts])
        nearest = np.argsort(np.abs(keys - ring_key(query)).sum(axis=1))[: 4 * rc.candidates]
        scored = []
        for k in nearest:
            d, yaw = context_distance(contexts[k][0], query)
            if d <= rc.max_distance:
                scored.append((d, far[k], yaw))
        scored.sort()
        tried = 0
        for _, sid, yaw in scored[: rc.candidates]:
            tried += 1
            sm = self.local.submaps[sid]
            guess = compose(self._context_of_submap(sid)[2], np.array([0.0, 0.0, yaw]))
            m = match_scan(sm, self.points, i, guess, cfg, rc.linear_window_m, np.radians(rc.angular_window_deg),
                           rc.min_score, sid, unique=cfg.ambiguity.enabled, inside=True)
            if m is None or not m.refined:
                continue
            pose = compose(est[sm.anchor], m.pose)
            moved = between(est[i], pose)
            if (np.hypot(moved[0], moved[1]) > rc.linear_window_m + drift_m
                    or abs(moved[2]) > np.radians(rc.angular_window_deg + turn_deg)):
                continue  # further than the run can have drifted: a look-alike
            for j, mj, sj, pj in recognitions:
                if not 0 < self.path[i] - self.path[j] <= rc.confirm_within_m:
                    continue
                d = between(compose(pj, between(self.local.poses[j], self.local.poses[i])), pose)
                if np.hypot(d[0], d[1]) <= rc.agree_m and abs(d[2]) <= np.radians(rc.agree_deg):
                    before = len(self.constraints)
                    self._add(mj, "loop")
                    self._add(m, "loop")
                    if len(self.constraints) - before == 2:
                        recognitions.clear()
                        return {before, before + 1}, tried
                    del self.constraints[before:]
            recognitions.append((i, m, sid, pose))
            del recognitions[: -4 * rc.candidates]
        return set(), tried

    def _context_of_node(self, i: int):
        """The Scan Context of node ``i``'s submap so far, in ``i``'s frame."""
        rc = self.cfg.recognition
        sm = self.local.submaps[min(self.local.member.get(i, {0}))]
        if i not in sm.scans:
            return None
        upto = sm.scans.index(i) + 1
        return scan_context(sm.points_about(self.points, sm.poses[upto - 1], upto), rc.rings, rc.sectors,
                            rc.max_radius_m)

    def _context_of_submap(self, sid: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """A finished submap's Scan Context about its node nearest its
        centre, its ring key, and that node's pose in the submap's frame."""
        if sid not in self._contexts:
            rc = self.cfg.recognition
            sm = self.local.submaps[sid]
            poses = np.asarray(sm.poses)
            centre = poses[np.argmin(np.hypot(*(poses[:, :2] - poses[:, :2].mean(axis=0)).T))]
            context = scan_context(sm.points_about(self.points, centre), rc.rings, rc.sectors, rc.max_radius_m)
            self._contexts[sid] = (context, ring_key(context), centre)
        return self._contexts[sid]

    def _add(self, m: Match, kind: str, before: int | None = None) -> None:
        """The match as a constraint from the submap's scan nearest to it
        (of those inserted ``before`` the matched scan, for a local match,
        and placed by a refined match themselves): the submap is rigid, so
        any of its scans can carry the match, and the nearest carries the
        least of the submap's own drift."""
        sm = self.local.submaps[m.submap]
        k = [n for n, scan in enumerate(sm.scans) if (before is None or scan < before) and self._placed(scan)]
        if not k:
            return
        where = np.array([sm.poses[n][:2] for n in k])
        near = k[int(np.argmin(np.hypot(*(where - m.pose[:2]).T)))]
        delta = between(sm.poses[near], m.pose)
        cc = self.cfg.constraints
        if kind != "intra" and cc.refine_near:
            again = refine_near(self.points, self.local.poses, sm.scans[near], m.scan, delta, self.cfg, m.submap, m.score)
            if kind in cc.agree and not _agree(again, delta, cc.agree_m, np.radians(cc.agree_deg)):
                return
            if again is not None:
                m, delta = again, again.pose
        info = self._information(m, kind != "intra")
        self.constraints.append(Constraint(m.submap, sm.scans[near], m.scan, delta, kind, m.score, info, m.weak))

    def _placed(self, scan: int) -> bool:
        """Whether local SLAM placed ``scan`` by a refined match (or it is the first)."""
        m = self.local.matches[scan]
        return scan == 0 or (m is not None and m.refined)

    def _information(self, m: Match, inter: bool) -> np.ndarray:
        """The match's own uncertainty and the configured sigmas, in the
        scan's axes, without the weak directions."""
        sig = self.cfg.constraints if inter else self.cfg.local
        return match_information(m.pose, m.covariance, m.weak, sig.sigma_xy_m, np.radians(sig.sigma_yaw_deg))

    # -- the graph ------------------------------------------------------------------

    def _gnc_outliers(self, est: np.ndarray, n: int) -> set[int]:
        """Indices of the inter constraints that graduated non-convexity
        (Yang et al. 2020; truncated least squares, GTSAM's GncOptimizer)
        gives a weight below one half, every other factor a known inlier."""
        import gtsam

        g, index = self._graph(n, robust_inter=False)
        inter = [pos for pos, k in index if self.constraints[k].kind != "intra"]
        if not inter:
            return set()
        values = self._values(est, n)
        params = gtsam.GncLMParams()
        params.setLossType(gtsam.GncLossType.TLS)
        inter_set = set(inter)
        params.setKnownInliers([f for f in range(g.size()) if f not in inter_set])
        optimizer = gtsam.GncLMOptimizer(g, values, params)
        optimizer.setInlierCostThresholdsAtProbability(self.cfg.constraints.inlier_probability)
        optimizer.optimize()
        weights = np.asarray(optimizer.getWeights())
        by_factor = dict(index)
        return {by_factor[f] for f in inter if weights[f] < 0.5}

    def _graph(self, n: int, robust_inter: bool = True, plain: set[int] = frozenset()):
        """The graph of the first ``n`` nodes; the inter constraints under the
        kernel when ``robust_inter``, except those indexed in ``plain``."""
        import gtsam

        self._extend_chain(n)
        if robust_inter and not plain:
            g = self._walk_graph(n)
            if g is not None:
                m = len(self.constraints)
                return g, list(zip(range(n, n + m), range(m)))
        g = gtsam.NonlinearFactorGraph()
        for i in range(n):
            g.add(self._chain[i])
        index = []  # (factor position, constraint index)
        for k, c in enumerate(self.constraints):
            if c.scan >= n:
                continue
            robust = c.kind != "intra" and robust_inter and k not in plain
            index.append((g.size(), k))
            g.add(self._constraint_factor(c, robust))
        return g, index

    def _extend_chain(self, n: int) -> None:
        """The prior and the chain's factors of the first ``n`` nodes, made once each."""
        import gtsam

        from slam.graph.factors import pose_key

        if not self._chain:
            self._chain.append(gtsam.PriorFactorPose2(pose_key(0), gtsam.Pose2(*self.local.poses[0]),
                                                      _noise([1e-3, 1e-3, 1e-4])))
        for i in range(len(self._chain), n):
            self._chain.append(self._chain_factor(i))

    def _walk_graph(self, n: int):
        """The graph :meth:`_graph` makes with every inter constraint under
        the kernel, made of two graphs that only grow as the walk goes (the
        chain's factors; the constraints' in their order), so the same
        factors in the same order as factor by factor, without a pass over
        all of them in Python; None where that is not the graph (it holds
        more nodes than ``n``, or a constraint reaches past node ``n``)."""
        import gtsam

        if self._chain_graph is None:
            self._chain_graph, self._constraint_graph = gtsam.NonlinearFactorGraph(), gtsam.NonlinearFactorGraph()
        while self._chain_graph.size() < n:
            self._chain_graph.add(self._chain[self._chain_graph.size()])
        if self._chain_graph.size() != n:
            return None
        kept = self._in_graph
        if not self._still_leads(kept):
            # Constraints were taken back (a recognition unconfirmed, the
            # outliers after GNC): start the constraints' graph again.
            self._constraint_graph, self._in_graph, self._last_scan = gtsam.NonlinearFactorGraph(), [], -1
        for c in self.constraints[len(self._in_graph):]:
            self._constraint_graph.add(self._constraint_factor(c, c.kind != "intra"))
            self._in_graph.append(c)
            self._last_scan = max(self._last_scan, c.scan)
        if self._last_scan >= n:
            return None
        g = gtsam.NonlinearFactorGraph()
        g.push_back(self._chain_graph)
        g.push_back(self._constraint_graph)
        return g

    def _still_leads(self, kept: list[Constraint]) -> bool:
        """Whether ``kept``, the constraints a graph was built from, still
        lead :attr:`constraints`. Constraints are only ever appended or taken
        out (a recognition unconfirmed, the outliers after GNC), never moved
        or added twice, so the prefix is intact exactly when the last of
        ``kept`` is still in its place: a check that costs the same however
        many constraints the run has made."""
        n = len(kept)
        return n == 0 or (n <= len(self.constraints) and self.constraints[n - 1] is kept[-1])

    def _chain_factor(self, i: int):
        """The dead-reckoning step into node ``i``."""
        import gtsam

        from slam.graph.factors import pose_key

        cov = self.step_cov[i]
        if cov[0, 0] >= UNKNOWN_VARIANCE:  # no measurement of this step: the local SLAM's
            step, cov = between(self.local.poses[i - 1], self.local.poses[i]), np.diag(UNMATCHED_VARIANCE)
        else:
            step = self.steps[i]
        noise = gtsam.noiseModel.Gaussian.Covariance(cov + 1e-12 * np.eye(3))
        if self.local.matches[i] is not None and self.local.matches[i].refined:
            # Where the scan was matched, dead reckoning is a second
            # opinion: a robust one, as odometry and a scan matcher seeded
            # by it can be wrong together (belgioioso: 15-18 deg at once).
            noise = gtsam.noiseModel.Robust.Create(self.chain_robust, noise)
        return gtsam.BetweenFactorPose2(pose_key(i - 1), pose_key(i), gtsam.Pose2(*step), noise)

    def _constraint_factor(self, c: Constraint, robust: bool):
        """The between factor of constraint ``c``, under the kernel when
        ``robust``; made once per constraint and kind of noise, since the
        graph is rebuilt around it at every optimisation (a factor is not
        changed by optimising it)."""
        import gtsam

        from slam.graph.factors import pose_key

        key = (id(c), robust)
        if key not in self._factors:  # keeps c alive beside it, so its id is not reused
            factor = gtsam.BetweenFactorPose2(pose_key(c.anchor), pose_key(c.scan), gtsam.Pose2(*c.delta),
                                              loop_noise(c.information, self.robust if robust else None))
            self._factors[key] = (c, factor)
        return self._factors[key][1]

    def _optimise(self, est: np.ndarray, n: int, plain: set[int] = frozenset()) -> np.ndarray:
        import gtsam

        self._isam = None
        g, _ = self._graph(n, plain=plain)
        params = gtsam.LevenbergMarquardtParams()
        params.setMaxIterations(50)
        result = gtsam.LevenbergMarquardtOptimizer(g, self._values(est, n), params).optimize()
        out = est.copy()
        out[:n] = gtsam.utilities.extractPose2(result)  # x, y, theta of x0..x(n-1), in key order
        return out

    def _incremental(self, est: np.ndarray, n: int) -> np.ndarray:
        """The walk's estimate of the first ``n`` nodes, updated by iSAM2
        with the chain and constraints added since the last update (the same
        graph as :meth:`_optimise`'s); started again from ``est`` where
        constraints were taken back or a batch optimisation moved it."""
        import gtsam

        from slam.graph.factors import pose_key

        self._extend_chain(n)
        kept = self._isam_constraints
        if self._isam is None or not self._still_leads(kept):
            params = gtsam.ISAM2Params()
            params.setRelinearizeThreshold(0.01)
            params.relinearizeSkip = 1
            self._isam, self._isam_n, self._isam_constraints = gtsam.ISAM2(params), 0, []
            kept = self._isam_constraints
        g, values = gtsam.NonlinearFactorGraph(), gtsam.Values()
        for i in range(self._isam_n, n):
            g.add(self._chain[i])
            values.insert(pose_key(i), gtsam.Pose2(*est[i]))
        for c in self.constraints[len(kept):]:
            g.add(self._constraint_factor(c, c.kind != "intra"))
            kept.append(c)
        try:
            self._isam.update(g, values)
            for _ in range(ISAM2_EXTRA_UPDATES):
                self._isam.update()
        except RuntimeError:
            # An indeterminate system: a node its factors barely pin (a chain
            # step the kernel has all but given up). Levenberg-Marquardt's
            # damping still moves it; iSAM2 starts again after it.
            return self._optimise(est, n)
        self._isam_n = n
        out = est.copy()
        out[:n] = gtsam.utilities.extractPose2(self._isam.calculateEstimate())
        return out

    def _values(self, est: np.ndarray, n: int):
        """The first ``n`` poses of ``est`` as GTSAM values. Done at every
        optimisation of the walk, over the whole graph so far: the keys are
        made once, and the rows handed over as Python floats."""
        import gtsam

        from slam.graph.factors import pose_key

        self._keys.extend(pose_key(i) for i in range(len(self._keys), n))
        values = gtsam.Values()
        insert, pose = values.insert, gtsam.Pose2
        for key, (x, y, yaw) in zip(self._keys, est[:n].tolist()):
            insert(key, pose(x, y, yaw))
        return values


def _agree(again: Match | None, delta: np.ndarray, max_m: float, max_rad: float) -> bool:
    """Whether the carrier's own scans confirm a submap match: their
    refinement ``again`` succeeded and stayed within ``max_m`` and
    ``max_rad`` of the submap's answer ``delta``."""
    if again is None:
        return False
    d = again.pose - delta
    return bool(np.hypot(d[0], d[1]) <= max_m and abs(wrap_angle(d[2])) <= max_rad)


def match_information(pose: np.ndarray, covariance: np.ndarray, weak: np.ndarray, sigma_xy_m: float,
                      sigma_yaw_rad: float) -> np.ndarray:
    """Information (3, 3) of a match at ``pose`` in the frame of the submap,
    in the convention of a Pose2 between factor (the error in the scan's
    axes): the match's ``covariance`` (3, 3, submap axes) plus
    ``sigma_xy_m`` along and across the scan's heading and
    ``sigma_yaw_rad``, with zero information along each ``weak`` direction
    (unit vectors (k, 3) in the submap's axes)."""
    c, s = np.cos(pose[2]), np.sin(pose[2])
    to_scan = np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])
    cov = to_scan @ covariance @ to_scan.T + np.diag([sigma_xy_m**2, sigma_xy_m**2, sigma_yaw_rad**2])
    info = np.linalg.inv(cov)
    if len(weak) == 0:
        return info
    basis = np.linalg.qr((to_scan @ np.asarray(weak).T))[0]
    keep = np.eye(3) - basis @ basis.T
    return keep @ info @ keep
