"""One recorded run mapped in memory: scan matching, keyframes,
measurements, gating, submaps, loop closing, graph optimisation,
evaluation. No file is read or written here; :mod:`slam.pipeline.folder`
wraps this core into ``gslam map``'s result folder, and benches and tests
call its steps directly.

:meth:`Mapping.run` reads like the table of contents; each step is a
public method, and what depends on ``validation.mode`` is asked of one
gating policy (:mod:`slam.gating.policy`).
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from slam.config import PipelineConfig
from slam.errors import GslamError
from slam.frontend.kiss import FrontendResult, run_frontend
from slam.gating.policy import Weighing, gating_policy
from slam.graph.measurements import Measurements, RelativeConstraint, build_measurements, select_keyframes
from slam.recording import Recording, Trajectory, interpolate_poses

if TYPE_CHECKING:
    from slam.frontend.worker import BackgroundScanMatching
    from slam.graph.backend import BackendResult

log = logging.getLogger(__name__)


@dataclass
class Timings:
    """Seconds per step; the result folder adds its own (read, write...)."""

    read_s: float = 0.0
    frontend_s: float = 0.0
    validation_s: float = 0.0
    loops_s: float = 0.0
    submaps_s: float = 0.0
    graph_build_s: float = 0.0
    optimise_s: float = 0.0
    write_s: float = 0.0
    grid_s: float = 0.0  # the occupancy grid, map.pgm and map.yaml
    mcap_s: float = 0.0  # run.mcap
    prepare_s: float = 0.0  # beside scan matching: imports, the files that do not need the estimate
    frontend_wait_s: float = 0.0  # waiting for scan matching in the second process
    plots_wait_s: float = 0.0  # waiting for the figures, grid and bag in the second process
    self_check_s: float = 0.0  # the map's self-check (slam/outputs/self_check.py)


class Mapping:
    """Map ``recording`` with ``config``; see :meth:`run`. ``frontend``: the
    scan matching of another variant of the same run, reused; ``source``
    names the input in error messages; ``progress``: progress bars on the
    terminal; ``concurrent``: the submaps' two halves on two cores (see
    :func:`slam.submaps.build.build_submap_constraints`; the same result
    either way). After :meth:`run` the estimate is in :attr:`backend` and
    the metrics in :attr:`metrics`."""

    def __init__(self, recording: Recording, config: PipelineConfig, frontend: FrontendResult | None = None,
                 source: str | Path | None = None, progress: bool = False, concurrent: bool = False):
        self.recording = recording
        self.progress = progress
        self.concurrent = concurrent
        self.config = config
        self.frontend = frontend
        self.source = Path(source) if source is not None else Path(recording.name)
        self.policy = gating_policy(config)
        self.timings = Timings()
        self.measurements: Measurements | None = None
        self.weighing: Weighing | None = None
        self.weights: dict[str, np.ndarray] | None = None
        self.validation = None
        self.constraints: list = []
        self.submaps = None
        self.loop_search = None
        self.loop_observation = None
        self.loop_factors = None
        self.backend: BackendResult | None = None
        self.metrics: dict[str, Any] = {}
        self.extra_metrics: dict[str, Any] = {}
        self.extra_outputs: dict[str, str | Callable[[], str]] = {}
        self._initial_pose: np.ndarray | None = None

    # -- the table of contents ------------------------------------------------

    def run(self, matcher: BackgroundScanMatching | None = None) -> "Mapping":
        """Every step, in order; ``matcher``: scan matching started earlier
        in a second process."""
        self.match_scans(matcher)
        self.build_measurements()
        self.validate()
        self.learn_odometry_scale()
        self.recheck()
        self.map_back_end()
        self.evaluate()
        return self

    # -- steps ----------------------------------------------------------------

    def match_scans(self, matcher: BackgroundScanMatching | None = None) -> None:
        """KISS-ICP over the scans, unless reused or not wanted; then, with
        ground truth, where its output is wrong joins the true faults."""
        rec, cfg = self.recording, self.config
        if rec.scans is None or not matches_scans(cfg):
            self.frontend = None
            return
        if self.frontend is not None:  # reused from another variant
            return
        if matcher is not None:
            self.frontend, self.timings.frontend_wait_s = matcher.result(rec.scans)
        else:
            self.frontend = run_frontend(rec.scans, cfg.frontend, progress=self.progress, odometry=rec.odometry)
        self.timings.frontend_s = self.frontend.time_s
        if self.frontend is not None:
            label_scan_matching_faults(rec, self.frontend, cfg)

    def build_measurements(self) -> None:
        rec, cfg = self.recording, self.config
        candidates, scan_index, stream = keyframe_candidates(rec, self.frontend is not None, self.source)
        chosen = select_keyframes(candidates, rec.odometry, cfg.keyframes)
        if len(chosen) < 2:
            limits = ", ".join(f"{k} {'null' if v is None else f'{v:g}'}" for k, v in cfg.keyframes.model_dump().items())
            raise GslamError(
                f"{self.source}: fewer than 2 keyframes: {len(candidates)} {stream} stamps "
                f"over {rec.duration:.1f} s with keyframes {limits}; the run is too short or the limits too wide"
            )
        t = candidates[chosen]
        scan_idx = scan_index[chosen] if scan_index is not None else None
        sm = self.frontend.poses if self.frontend is not None else None
        self.measurements = build_measurements(rec, t, cfg.backend.factors, scan_idx, sm)

    def validate(self) -> None:
        """The weight of every factor's degrees of freedom per keyframe, as
        the gating policy decides (``validation.mode``)."""
        sm = self.frontend.poses if self.frontend is not None else None
        t = time.perf_counter()
        witnesses = {name: self.witness(name) for name in self.policy.witnesses()}
        witness_s = time.perf_counter() - t
        self.weighing = w = self.policy.weigh(self.recording, sm, self.measurements, self.source, witnesses)
        self.weights, self.validation = w.weights, w.validation
        self.extra_metrics.update(w.metrics)
        if w.validation is not None:
            self.timings.validation_s = w.validation.time_s + witness_s
        if w.csv is not None:
            self.extra_outputs["validation.csv"] = w.csv  # written while the figures are drawn

    def witness(self, name: str) -> Trajectory:
        """A sensor the validator weighs that this run makes: ``sub``, local
        SLAM over the keyframes' scans along the ungated dead-reckoning
        chain (:func:`slam.submaps.build.local_witness`)."""
        if name != "sub":
            raise ValueError(f"unknown witness {name!r}")
        meas = self.measurements
        if self.frontend is None or meas.scan_index is None:
            raise GslamError(f"{self.source}: validation.observers.relations compare stream sub_*, local SLAM's "
                             "submap match, which needs the scans and the front-end (frontend.enabled); "
                             "this run has neither")
        from slam.loops.chain import fuse_steps
        from slam.submaps.build import local_witness

        steps, step_cov = fuse_steps(meas, None)
        return local_witness(self.recording.scans, meas.scan_index, meas.t, steps, step_cov, self.config.frontend,
                             self.config.submaps)

    def learn_odometry_scale(self) -> None:
        """With ``backend.factors.odometry.learn_scale`` and a policy that
        knows where the scan matcher can be trusted, the odometry stands in
        for the scan matcher with the scan matcher's scale: its distance is
        corrected by the scale learnt where both are kept
        (:mod:`slam.gating.odometry_scale`), on the steps where the scan
        matcher's forward motion is gated. Elsewhere the graph fuses the two
        as they are."""
        from slam.gating.odometry_scale import odometry_scale
        from slam.graph.backend import dof_weights

        odo, sm = self.measurements.odometry, self.measurements.scan_matching
        if not self.config.backend.factors.odometry.learn_scale or odo is None or sm is None:
            return
        if not self.policy.learns_scale:
            return
        est = odometry_scale(self.measurements, self.weights)
        stand_in = dof_weights(self.weights["scan_matching"], "scan_matching")[:, 0] > 1.0
        odo.delta[stand_in, :2] *= est.scale
        self.extra_metrics["odometry_scale"] = {
            "scale": round(est.scale, 5), "windows": est.windows, "spread": round(est.spread, 5),
            "steps_corrected": int(stand_in.sum()),
        }

    def recheck(self) -> None:
        """Offline validation's recheck: keep the blamed measurements that
        agree with the other sensors (:mod:`slam.gating.recheck`)."""
        t = time.perf_counter()
        result = self.policy.recheck(self.measurements, self.weights, self.initial_pose())
        if result is None:
            return
        self.weights = result.weights
        self.constraints = result.constraints
        self.extra_metrics.update(result.metrics)
        self.timings.validation_s += time.perf_counter() - t

    def map_back_end(self) -> None:
        """The submaps, the loops and the graph. With ``submaps.blamed_scans:
        choose`` and scans the gating excluded, twice: with those scans left
        out of the submaps and with them kept, and the map whose laser
        returns land in fewer cells is kept
        (:func:`slam.outputs.self_check.return_cells`; a tie keeps them
        out). Leaving a cut laser's scans out hands their stretch to the
        odometry: right where the odometry holds its heading, wrong where it
        turns the rest of the run away. Keeping them lets their weak matches
        bend the run. Either way the map tears into pieces that each hold
        together, and a torn map lays the walls it sees again on other cells
        than before."""
        if self.config.submaps.blamed_scans != "choose" or not self._blames_scans():
            self._back_end_pass()
            return
        before = self._back_end_state()
        cells, in_free = {}, {}
        for mode in ("keep", "leave_out"):
            self._restore_back_end(before)
            self._back_end_pass(mode)
            cells[mode], in_free[mode] = self._map_figures()
        chosen = "keep" if cells["keep"] < cells["leave_out"] else "leave_out"
        if chosen == "keep":  # the last pass made the state (the validator's loop columns too)
            self._restore_back_end(before)
            self._back_end_pass(chosen)
        self.extra_metrics["blamed_scans"] = {"chosen": chosen, "return_cells": cells,
                                              "free_space_returns": {m: round(v, 4) for m, v in in_free.items()}}

    def _back_end_pass(self, blamed_mode: str | None = None) -> None:
        self.build_submaps(blamed_mode=blamed_mode)
        self.judge_loops(self.find_loops())
        self.optimise()

    def _blames_scans(self) -> bool:
        return (self.submaps_possible() and self.weights is not None
                and bool(blamed_scans(self.weights, len(self.measurements)).any()))

    def submaps_possible(self) -> bool:
        cfg, meas = self.config.submaps, self.measurements
        return cfg.enabled and self.frontend is not None and meas.scan_index is not None

    def _back_end_state(self) -> dict[str, Any]:
        """What :meth:`build_submaps`, :meth:`judge_loops` and :meth:`optimise` set."""
        names = ("constraints", "submaps", "loop_search", "loop_observation", "loop_factors", "backend")
        return {**{n: getattr(self, n) for n in names},
                "extra_metrics": dict(self.extra_metrics), "extra_outputs": dict(self.extra_outputs)}

    def _restore_back_end(self, state: dict[str, Any]) -> None:
        for name, value in state.items():
            setattr(self, name, dict(value) if isinstance(value, dict) else value)

    def _map_figures(self) -> tuple[int, float]:
        """The current estimate's :func:`slam.outputs.self_check.map_return_cells`
        and the self-check's ``free_space_returns`` (recorded, not chosen by)."""
        from slam.outputs.pointcloud import beam_limits
        from slam.outputs.self_check import map_free_space_returns, map_return_cells

        rec, limits = self.recording, beam_limits(self.config.frontend, self.recording.scans)
        trajectory, scan_index = self.backend.trajectory, self.measurements.scan_index
        in_free, _ = map_free_space_returns(trajectory, rec.scans, scan_index, limits)
        return (map_return_cells(trajectory, rec.scans, scan_index, limits),
                np.inf if in_free is None else in_free)

    def build_submaps(self, before_judging: Callable[[list], list] | None = None,
                      blamed_mode: str | None = None) -> None:
        """Scan-to-submap constraints (:mod:`slam.submaps`) over the
        keyframes' scans, searched around the dead-reckoning chain (with the
        gating's weights); with ``submaps.blamed_scans: leave_out`` a scan
        the gating excluded is left out of them (:func:`blamed_scans`). The local and near ones join the graph as scan
        matching, gated with it (:func:`submap_factors`); the loops are
        judged in :meth:`judge_loops`. ``before_judging``: given the submap
        graph's constraints before its GNC judges them, returns more to judge
        (a bench's wrong loops)."""
        cfg, meas = self.config.submaps, self.measurements
        if not self.submaps_possible():
            return
        from slam.loops.chain import fuse_steps
        from slam.submaps.build import build_submap_constraints

        t = time.perf_counter()
        steps, step_cov = fuse_steps(meas, self.weights)
        mode = blamed_mode or cfg.blamed_scans
        blamed = blamed_scans(self.weights, len(meas)) if mode == "leave_out" else None
        self.submaps = build_submap_constraints(
            self.recording.scans, meas.scan_index, steps, step_cov, self.config.frontend, cfg, before_judging, blamed,
            self.progress, self.concurrent,
        )
        own = self.weighing.submaps if self.weighing is not None else None
        self.constraints = [*self.constraints, *submap_factors(self.submaps, self.weights, len(meas), blamed, own)]
        self.timings.submaps_s += time.perf_counter() - t

    def find_loops(self):
        """The loops of this run before they are checked (:mod:`slam.loops.search`);
        None with loop closing off."""
        if not self.config.loops.enabled:
            return None
        from slam.loops.search import find_loops

        t = time.perf_counter()
        search = find_loops(self.recording, self.measurements, self.weights, self.config, self.initial_pose(),
                            self.submaps)
        self.timings.loops_s += time.perf_counter() - t
        return search

    def judge_loops(self, search) -> None:
        """Check the loops ``search`` found (loop observer, then the gating
        policy: LOOP in the diagnosis, or ground truth for the oracle) and
        keep the ones that pass; see :mod:`slam.loops` and :mod:`validation.loops`."""
        if search is None:
            return
        from slam.graph.backend import robust_kernel
        from slam.graph.loop_factors import LoopFactors
        from slam.outputs.loops import loops_csv
        from validation.loops.observer import count_reasons, observe_loops

        cfg = self.config.loops
        start = time.perf_counter()
        self.loop_search = search
        obs = observe_loops(search.chain, search.loops, cfg.observer)
        if search.rejected:  # rejected before the observer (the submaps' GNC)
            for v in obs.verdicts:
                if v.loop.id in search.rejected:
                    v.accepted, v.reason = False, search.rejected[v.loop.id]
            obs.counts = count_reasons(obs.verdicts)
        self.policy.gate_loops(obs, self.weighing, self.measurements.t, self.keyframe_truth())
        self.loop_observation = obs
        kernel = cfg.robust_kernel if cfg.robust_kernel is not None else self.config.backend.robust_kernel
        param = cfg.robust_param if cfg.robust_param is not None else self.config.backend.robust_param
        self.loop_factors = LoopFactors(obs.accepted, robust_kernel(kernel, param), cfg.gnc, obs.inflation)
        self.timings.loops_s += time.perf_counter() - start
        self.extra_outputs["loops.csv"] = loops_csv(obs, self.measurements.t)
        if self.validation is not None:  # with the loops' verdicts now; written while the figures are drawn
            self.extra_outputs["validation.csv"] = self.validation.csv_text

    def optimise(self) -> None:
        from slam.graph.backend import optimise

        pose0 = self.initial_pose()
        # Building the batch graph takes milliseconds: a bar would only ever
        # show 0 %. iSAM2 updates per keyframe take long enough to show one.
        progress = self.progress and self.config.backend.optimizer == "isam2"
        start = None
        b = self.config.backend
        judged = b.robust_kernel != "none" or b.optimizer.startswith("gnc")
        # The submaps' estimate already holds their loops, and starts the
        # final optimisation; not under a robust kernel or GNC over the whole
        # graph: where no validator left faulty scans out, the submap graph's
        # estimate is wrong, and a robust kernel started there keeps it (on
        # the simulated hall, DCS 4.7 m from it, 0.18 m from the chain; gated
        # runs converge to the same poses from either).
        if self.submaps is not None and not judged:
            from validation.base.geometry import between, compose

            est = self.submaps.estimate
            start = compose(np.repeat(pose0[None], len(est), axis=0), between(np.repeat(est[:1], len(est), axis=0), est))
        self.backend = optimise(
            self.measurements, pose0, self.config.backend, self.weights, progress=progress,
            constraints=self.constraints, loops=self.loop_factors, initial_poses=start,
        )
        self.timings.graph_build_s += self.backend.build_time_s
        self.timings.optimise_s += self.backend.optimise_time_s

    def evaluate(self) -> None:
        """The metrics: against ground truth where there is one, the graph's
        factors, the loops and submaps, the gating's."""
        from slam.outputs.loops import loop_metrics, submap_metrics

        rec, est = self.recording, self.backend.trajectory
        m: dict[str, Any] = {"input": str(self.source), "n_poses": len(est), "duration_s": round(rec.duration, 3)}
        if rec.groundtruth is not None:
            from slam.outputs.evaluation import evaluate

            ev = self.config.evaluation
            m.update(evaluate(est, rec.groundtruth, ev.rpe_deltas_m, ev.max_time_offset_s))
        m["factor_counts"] = self.backend.factor_counts
        m["fallback_steps"] = self.backend.fallback_steps
        truth = self.keyframe_truth()
        if self.loop_observation is not None:
            m["loops"] = loop_metrics(self.loop_search, self.loop_observation, truth, self.config.evaluation)
        if self.submaps is not None:
            m["submaps"] = submap_metrics(self.submaps, truth, self.config.evaluation)
        if self.validation is not None:
            m.update(self.validation.metrics)
        m.update(self.extra_metrics)
        self.metrics = m

    def self_check_inputs(self) -> dict[str, Any]:
        """What the map's self-check (:func:`slam.outputs.self_check.check_map`)
        reads: the estimate, the keyframes' scans, the kept loops, the odometry."""
        from slam.outputs.pointcloud import beam_limits

        rec, meas = self.recording, self.measurements
        on_scans = rec.scans is not None and meas.scan_index is not None
        return dict(
            trajectory=self.backend.trajectory,
            scans=rec.scans if on_scans else None,
            scan_index=meas.scan_index if on_scans else None,
            beam_limits=beam_limits(self.config.frontend, rec.scans) if on_scans else None,
            loops=self.loop_factors.loops if self.loop_factors is not None else (),
            odometry=meas.odometry,
            stamps_synthesised=rec.stamps_synthesised,
            blame_share=self.metrics.get("alarm_fraction"),
        )

    def check_self(self, check: Any = None) -> None:
        """The map's self-check without ground truth (:mod:`slam.outputs.self_check`)
        into ``metrics['self_check']``; it only reads the estimate. ``check``:
        its result, made elsewhere from :meth:`self_check_inputs` (None: made
        here). Not part of :meth:`run`: the result folder has it made while
        the figures are drawn."""
        if check is None:
            from slam.outputs.self_check import check_map

            check = check_map(**self.self_check_inputs())
        self.timings.self_check_s = check.time_s
        self.metrics["self_check"] = check.as_dict()

    # -- what the steps share -------------------------------------------------

    def initial_pose(self) -> np.ndarray:
        """The first keyframe's pose: ground truth's where the config asks
        for it, else the origin facing the first compass heading. Found
        once (recheck, loops and the optimiser each ask), so that its
        warning is said once."""
        if self._initial_pose is None:
            self._initial_pose = self._find_initial_pose()
        return self._initial_pose.copy()

    def _find_initial_pose(self) -> np.ndarray:
        rec, cfg, t0 = self.recording, self.config.backend, self.measurements.t[:1]
        if cfg.initial_pose == "groundtruth":
            if rec.groundtruth is not None:
                return interpolate_poses(rec.groundtruth, t0)[0]
            log.warning("no ground truth to anchor the first pose; starting at the origin")
        yaw = 0.0
        m = self.measurements.compass
        if m is not None and m.valid[0]:
            yaw = float(m.value[0])
        return np.array([0.0, 0.0, yaw])

    def keyframe_truth(self) -> np.ndarray | None:
        """The true pose (K, 3) of every keyframe, where there is ground truth."""
        rec = self.recording
        return None if rec.groundtruth is None else interpolate_poses(rec.groundtruth, self.measurements.t)


def matches_scans(config: PipelineConfig) -> bool:
    """Whether the config registers scans (KISS-ICP and its factors)."""
    return config.frontend.enabled and config.backend.factors.scan_matching.enabled


def label_scan_matching_faults(rec: Recording, frontend: FrontendResult, config: PipelineConfig) -> None:
    """Add the times where the front-end's output is wrong (against ground
    truth) to the true fault intervals of each scan-matching modality; see
    :mod:`slam.gating.truth`."""
    ev = config.evaluation
    if rec.groundtruth is None or not ev.sm_output_faults:
        return
    from slam.gating.truth import scan_matching_output_faults
    from slam.recording import union_intervals

    wrong = scan_matching_output_faults(
        frontend.poses, rec.groundtruth, ev.sm_fault_window_s, ev.sm_fault_trans_m, ev.sm_fault_yaw_deg
    )
    for name, intervals in wrong.items():
        rec.faults[name] = union_intervals(rec.faults.get(name, []), intervals)


def keyframe_candidates(rec: Recording, on_scans: bool, source: Path) -> tuple[np.ndarray, np.ndarray | None, str]:
    """The times keyframes are chosen from, the scan of each (or None), and
    the stream's name: scan times when scans are matched, else odometry,
    gyro or compass times (the first stream present)."""
    if on_scans:
        return rec.scans.t, np.arange(len(rec.scans)), "laser scan"
    for name, stream in (("odometry", rec.odometry), ("gyro", rec.gyro), ("compass", rec.compass)):
        if stream is not None:
            return stream.t, None, name
    raise GslamError(f"{source}: no odometry, gyro, compass or laser stream to map with")


def blamed_scans(weights: dict[str, np.ndarray], n: int) -> np.ndarray:
    """Keyframes (n,) bool whose scan the gating excluded in every
    direction: the scan as a whole is wrong (the laser blind or cut off, the
    whole scan matcher blamed), so nothing may be built on it. A scan
    excluded in one direction only (a corridor's distance) still maps what
    it sees."""
    from slam.graph.backend import dof_weights

    sm = weights.get("scan_matching")
    if sm is None:
        return np.zeros(n, dtype=bool)
    return np.isinf(dof_weights(sm, "scan_matching")).all(axis=1)


def submap_factors(submaps, weights: dict[str, np.ndarray], n: int, blamed: np.ndarray | None = None,
                   own: np.ndarray | None = None) -> list[RelativeConstraint]:
    """The local and near submap constraints as between factors. A
    constraint rests on the scans of its submap and on its own: each degree
    of freedom takes the largest weight over those keyframes (an excluded
    one drops that degree of freedom), the constraints' ``own`` weights
    (``gating.factors.submaps``) where given, else scan matching's; a
    ``blamed`` keyframe's scan was left out of the submaps, so the
    constraints do not rest on it."""
    from slam.graph.backend import dof_weights

    sm = own if own is not None else weights.get("scan_matching")
    w = dof_weights(sm, "scan_matching") if sm is not None else np.ones((n, 3))
    out = []
    for c in submaps.of_kind("intra", "near"):
        steps = [c.scan, *submaps.submap_keyframes(c.submap)]
        if blamed is not None:
            steps = [k for k in steps if not blamed[k]] or [c.scan]
        worst = w[steps].max(axis=0)
        if not np.all(np.isfinite(worst)) and not np.any(np.isfinite(worst)):
            continue
        scale = np.where(np.isfinite(worst), 1.0 / worst, 0.0)
        info = c.information * np.outer(scale, scale)
        out.append(RelativeConstraint(c.anchor, c.scan, c.delta, np.full(3, np.inf), "scan_matching", "submap", info))
    return out
