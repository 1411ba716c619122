"""The submaps step of the pipeline: local SLAM, and the constraint search following it (see the package docstring)."""

from __future__ import annotations

import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from slam.config import FrontendConfig
from slam.recording import Scans, Trajectory
from slam.config.submaps import SubmapsConfig
from slam.processes import background
from slam.processes.background import Inbox
from slam.submaps.graph import Constraint, GlobalResult, GlobalSlam, LocalFeed
from slam.submaps.local import LocalResult, LocalStep, run_local_slam
from slam.submaps.scans import ScanPoints
from validation.loops.chain import integrate
from validation.base.geometry import between, compose

@dataclass
class SubmapResult:
    """What the submaps found, in keyframe indices: the constraints kept and
    dropped, the keyframes that are submap nodes (``nodes``), the local
    SLAM over them, the estimate of every keyframe (K, 3) in the frame of
    the first, and the wall time (s)."""

    local: LocalResult
    nodes: np.ndarray
    constraints: list[Constraint]
    dropped: list[Constraint]
    searches: int
    estimate: np.ndarray
    time_s: float

    def of_kind(self, *kinds: str) -> list[Constraint]:
        return [c for c in self.constraints if c.kind in kinds]

    def dropped_of_kind(self, *kinds: str) -> list[Constraint]:
        return [c for c in self.dropped if c.kind in kinds]

    def submap_keyframes(self, submap: int) -> np.ndarray:
        """The keyframes a submap's scans span (its nodes and those between)."""
        scans = self.local.submaps[submap].scans
        return np.arange(self.nodes[scans[0]], self.nodes[scans[-1]] + 1)


def select_nodes(steps: np.ndarray, spacing_m: float, turn_rad: float) -> np.ndarray:
    """Keyframe indices (sorted, from 0) that become submap nodes: the first,
    then each one that has moved ``spacing_m`` or turned ``turn_rad`` along
    the chain ``steps`` (K, 3) since the last node."""
    poses = integrate(np.zeros(3), steps)
    nodes = [0]
    for k in range(1, len(poses)):
        d = between(poses[nodes[-1]], poses[k])
        if np.hypot(d[0], d[1]) >= spacing_m or abs(d[2]) >= turn_rad:
            nodes.append(k)
    return np.asarray(nodes)


def node_chain(steps: np.ndarray, step_cov: np.ndarray,
               config: SubmapsConfig) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The submap nodes of the keyframe chain ``steps`` (K, 3) with its step
    covariances ``step_cov`` (K, 3, 3): the nodes (:func:`select_nodes`),
    the chain's poses (K, 3), and its steps (N, 3) and their covariances
    (N, 3, 3) from node to node (row 0 unused)."""
    nodes = select_nodes(steps, config.node_spacing_m, np.radians(config.node_turn_deg))
    chain = integrate(np.zeros(3), steps)
    node_steps = np.zeros((len(nodes), 3))
    node_steps[1:] = between(chain[nodes[:-1]], chain[nodes[1:]])
    cum = np.cumsum(step_cov, axis=0)
    node_cov = np.zeros((len(nodes), 3, 3))
    node_cov[1:] = cum[nodes[1:]] - cum[nodes[:-1]]
    return nodes, chain, node_steps, node_cov


def node_points(scans: Scans, scan_index: np.ndarray, nodes: np.ndarray, frontend: FrontendConfig,
                config: SubmapsConfig) -> ScanPoints:
    """The scans of the submap nodes (keyframes ``nodes`` of the keyframes
    whose scans are ``scans[scan_index]``), as the submaps read them."""
    return ScanPoints(scans, frontend.min_range_m, frontend.max_range_m, config.voxel_m, index=scan_index[nodes],
                      search_voxel_m=config.resolution_m)


def hang_off_nodes(node_poses: np.ndarray, nodes: np.ndarray, chain: np.ndarray) -> np.ndarray:
    """Every keyframe's pose (K, 3): each hangs off the node before it
    (``node_poses`` (N, 3) of keyframes ``nodes``) by the chain's poses
    ``chain`` (K, 3)."""
    owner = np.searchsorted(nodes, np.arange(len(chain)), side="right") - 1
    return compose(node_poses[owner], between(chain[nodes[owner]], chain))


def local_witness(scans: Scans, scan_index: np.ndarray, t: np.ndarray, steps: np.ndarray, step_cov: np.ndarray,
                  frontend: FrontendConfig, config: SubmapsConfig) -> Trajectory:
    """Local SLAM alone as a sensor of its own, for the validation (the
    ``sub`` streams, :mod:`validation.streams.names`): the pose of every
    keyframe (times ``t``, (K,)), each submap node where its scan's match
    against the submap being built places it, the keyframes between two
    nodes (less than ``node_spacing_m`` and ``node_turn_deg`` apart) hung
    off the node before them by the chain. The chain ``steps`` only centres
    each search; the search itself spans the chain's uncertainty, at least
    ``local.angular_window_deg`` and ``local.linear_window_m``, so where the
    chain turns or travels wrong (the odometry slipping, the scan matcher
    it seeds following it) the match still finds the scan where the walls
    it saw before put it."""
    nodes, chain, node_steps, node_cov = node_chain(steps, step_cov, config)
    local = run_local_slam(node_points(scans, scan_index, nodes, frontend, config), node_steps, node_cov, config)
    p = hang_off_nodes(local.poses, nodes, chain)
    return Trajectory(np.asarray(t, dtype=float), p[:, 0].copy(), p[:, 1].copy(), p[:, 2].copy())


def _walk(inbox: Inbox, points: ScanPoints, config: SubmapsConfig, steps: np.ndarray, step_cov: np.ndarray,
          before_judging: Callable[[list[Constraint]], list[Constraint]] | None) -> GlobalResult:
    """The global walk over local SLAM's steps as ``inbox`` gives them, a batch at a time."""
    batch: deque[LocalStep | None] = deque()

    def next_step() -> LocalStep | None:
        while not batch:
            batch.extend(inbox())
        return batch.popleft()

    feed = LocalFeed(points, len(points), config.min_points, next_step)
    return GlobalSlam(points, feed, config, steps, step_cov, before_judging).run()


class _WalkBeside:
    """Local SLAM's steps, told as they come, to the walk (:func:`_walk`):
    in a second process when ``concurrent``, else in this one when its
    result is asked for. The second process starts once local SLAM has
    completed its first submap: before that the walk has nothing to
    search, and by then this process has loaded the search's compiled
    kernels, which the second one inherits instead of loading them again.
    The steps go over ``BATCH`` at a time."""

    BATCH = 16

    def __init__(self, concurrent: bool, *args):
        self.concurrent, self.args = concurrent, args
        self.walk = None
        self.waiting: list[LocalStep | None] = []

    def tell(self, step: LocalStep | None) -> None:
        self.waiting.append(step)
        if self.walk is None and (step is None or step.finished):
            self.walk = background.start("the submaps' walk", _walk, *self.args, concurrent=self.concurrent)
        if self.walk is not None and (step is None or len(self.waiting) >= self.BATCH):
            self.walk.send(self.waiting)
            self.waiting = []

    def result(self) -> GlobalResult:
        return self.walk.result()

    def close(self) -> None:
        if self.walk is not None:
            self.walk.close()


def build_submap_constraints(
    scans: Scans,
    scan_index: np.ndarray,
    steps: np.ndarray,
    step_cov: np.ndarray,
    frontend: FrontendConfig,
    config: SubmapsConfig,
    before_judging: Callable[[list[Constraint]], list[Constraint]] | None = None,
    blamed: np.ndarray | None = None,
    progress: bool = False,
    concurrent: bool = False,
) -> SubmapResult:
    """Scan-to-submap constraints over the keyframes whose scans are
    ``scans[scan_index]`` (K,); ``steps`` (K, 3) and ``step_cov`` (K, 3, 3):
    the dead-reckoning chain between them (row 0 unused). Submaps are built
    over the keyframes :func:`select_nodes` keeps; the others keep their
    chain steps. ``before_judging``: see :class:`slam.submaps.graph.GlobalSlam`.
    ``blamed`` (K,) bool: keyframes whose scan the gating excluded; such a
    scan leaves no trace here: it is neither matched nor inserted into a
    submap (its node keeps the chain's pose), so no constraint, submap or
    loop rests on it. ``progress``: a bar on a terminal. ``concurrent``:
    the walk follows local SLAM scan by scan in a second process (else it
    runs after it here); the same code on the same data either way, so the
    same result to the last bit."""
    start = time.perf_counter()
    nodes, chain, node_steps, node_cov = node_chain(steps, step_cov, config)
    points = node_points(scans, scan_index, nodes, frontend, config)
    if blamed is not None:
        points.leave_out(np.flatnonzero(np.asarray(blamed)[nodes]))
    walk = _WalkBeside(concurrent, points, config, node_steps, node_cov, before_judging)
    try:
        local = run_local_slam(points, node_steps, node_cov, config, progress, tell=walk.tell)
        found: GlobalResult = walk.result()
    finally:
        walk.close()
    # Back to keyframes: every keyframe hangs off the node before it by the chain.
    estimate = hang_off_nodes(found.poses, nodes, chain)

    def to_keyframes(c: Constraint) -> Constraint:
        return replace(c, anchor=int(nodes[c.anchor]), scan=int(nodes[c.scan]))

    return SubmapResult(local, nodes, [to_keyframes(c) for c in found.constraints],
                        [to_keyframes(c) for c in found.rejected], found.searches, estimate,
                        time.perf_counter() - start)
