"""One recorded run, end to end: read, scan matching, keyframes,
measurements, validation, loop closing, graph optimisation, evaluation,
results.

:class:`MappingPipeline.run` reads like the table of contents; every step is
a method. The result folder follows :mod:`slam.io.outdir`: ``--out`` is
checked before any work, the result is built in a temporary sibling and
renamed into place at the end, so a killed run leaves a complete folder or
none.

Two steps run beside the others on the second core (``concurrent``, the
default): KISS-ICP registers the scans while the other topics are read and
the next steps prepared (:mod:`slam.scan_matching`), and the figures, the
occupancy grid and ``run.mcap`` are made while the numeric results are
written (:mod:`slam.io.result_writer`). Both
are the same code on the same data as in the plain order
(``concurrent=False``), so the results are the same bytes. gtsam and
validation are imported while the scans are matched, not before.
"""

from __future__ import annotations

import json
import logging
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from slam.config import PipelineConfig, dump_config
from slam.errors import GslamError
from slam.frontend import FrontendResult, ScanProjector, run_frontend
from slam.io.outdir import result_folder
from slam.io.result_writer import FinalEstimate, MapInputs, ResultWriter
from slam.measurements import Measurements, build_measurements, interpolate_poses, select_keyframes
from slam.scan_matching import BackgroundScanMatching, import_next_steps
from slam.recording import Recording, Trajectory

if TYPE_CHECKING:
    from slam.backend import BackendResult, FactorWeights

log = logging.getLogger(__name__)

RESULT_FILES = (
    "config.yaml", "metrics.json", "trajectory.tum", "groundtruth.tum", "validation.csv", "loops.csv", "map.ply",
    "map.pgm", "map.yaml", "run.mcap", "trajectory.png", "map.png",
)
"""Every file a map result may hold (which of them depends on the run)."""


@dataclass
class MapResult:
    """What ``gslam map`` produced: the folder, the metrics and the estimate."""

    out_dir: Path
    metrics: dict[str, Any]
    trajectory: Trajectory
    recording: Recording | None = None
    validation: Any = None


@dataclass
class _Timings:
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


class MappingPipeline:
    """Map one run with the given config; see :meth:`run`.

    ``recording`` and ``frontend`` may be given to reuse what another
    variant of the same run already computed (``gslam compare``).
    ``inputs``: other files the run reads (the config), which ``out_dir``
    must not be or hold; ``force``: write into a folder that is not a map
    result (see :mod:`slam.io.outdir`); ``concurrent``: match scans and
    draw figures in a second process (see the module docstring).
    """

    def __init__(
        self,
        input_path: str | Path,
        config: PipelineConfig,
        out_dir: str | Path,
        progress: bool = False,
        recording: Recording | None = None,
        frontend: FrontendResult | None = None,
        inputs: Sequence[str | Path] = (),
        force: bool = False,
        concurrent: bool = True,
    ):
        self.input_path = Path(input_path)
        self.concurrent = concurrent
        self.scan_matching: BackgroundScanMatching | None = None
        self.outputs: ResultWriter | None = None
        self.inputs = [self.input_path, *map(Path, inputs)]
        self.force = force
        self.config = config
        self.out_dir = Path(out_dir)
        self.progress = progress
        self.recording = recording
        self.timings = _Timings()
        self.frontend: FrontendResult | None = frontend
        self.validation = None
        self._start = time.perf_counter()
        self.measurements: Measurements | None = None
        self.weights: FactorWeights | None = None
        self.constraints: list = []
        self.backend: BackendResult | None = None
        self.loop_search = None
        self.submaps = None
        self.loop_observation = None
        self.loop_factors = None
        self.metrics: dict[str, Any] = {}
        self.extra_metrics: dict[str, Any] = {}
        self.extra_outputs: dict[str, str | Callable[[], str]] = {}
        self.points: np.ndarray | None = None

    # -- the table of contents ------------------------------------------------

    def run(self) -> MapResult:
        self._start = time.perf_counter()
        with result_folder(self.out_dir, "map", self.inputs, self.force, RESULT_FILES) as tmp:
            self.start_helpers()
            try:
                self.read()
                self.prepare(tmp)
                self.match_scans()
                self.build_measurements()
                self.validate()
                self.learn_odometry_scale()
                self.recheck()
                self.build_submaps()
                self.close_loops()
                self.optimise()
                self.start_figures(tmp)
                self.evaluate()
                self.write(tmp)
            finally:  # before a failed result's folder is removed
                self.close_helpers()
        return MapResult(self.out_dir, self.metrics, self.backend.trajectory, self.recording, self.validation)

    # -- steps ----------------------------------------------------------------

    def start_helpers(self) -> None:
        """The second process's work: scan matching (unless it is reused)
        and the result files made from the estimate; both wait for their
        data."""
        cfg = self.config
        out = cfg.output
        if out.plots or out.grid or out.mcap:
            self.outputs = ResultWriter(self.concurrent, out.plots, out.mcap)
        if self.recording is None and self.frontend is None and self._matches_scans():
            self.scan_matching = BackgroundScanMatching(cfg.frontend, self.progress, self.concurrent)

    def close_helpers(self) -> None:
        for helper in (self.scan_matching, self.outputs):
            if helper is not None:
                helper.close()

    def read(self) -> None:
        t = time.perf_counter()
        if self.recording is None:
            from slam.io.readers import read_recording

            sm = self.scan_matching
            early = sm.give if sm is not None and not sm.needs_odometry else None
            self.recording = read_recording(self.input_path, self.config.input, on_scans=early)
            if sm is not None:  # without scans, or for odometry guesses: now
                sm.give(self.recording.scans, self.recording.odometry)
        self.timings.read_s = time.perf_counter() - t
        rec = self.recording
        log.info("read %s: %.1f s of data", rec.name, rec.duration)
        self.check_fit()

    def check_fit(self) -> None:
        """Whether the config fits the recording (:mod:`slam.config_fit`),
        before any work on it; a laser that returns nothing within the
        front-end's limits is left out, and its scan matching with it."""
        from slam.config_fit import check_fit

        had_scans = self.recording.scans is not None
        check_fit(self.recording, self.config, self.input_path)
        if had_scans and self.recording.scans is None and self.scan_matching is not None:
            self.scan_matching.close()
            self.scan_matching = None

    def prepare(self, folder: Path) -> None:
        """What needs no estimate, done while the scans are matched: the
        config and the reference into ``folder``, and the imports of the
        next steps."""
        t = time.perf_counter()
        rec = self.recording
        (folder / "config.yaml").write_text(dump_config(self.config))
        if rec.groundtruth is not None:
            from slam.io.tum import write_tum

            write_tum(folder / "groundtruth.tum", rec.groundtruth, rec.t0)
        if self.scan_matching is not None:
            import_next_steps()
        self.timings.prepare_s = time.perf_counter() - t

    def match_scans(self) -> None:
        rec, cfg = self.recording, self.config
        if rec.scans is None or not self._matches_scans():
            self.frontend = None
            return
        if self.frontend is not None:  # reused from another variant
            return
        if self.scan_matching is not None:
            self.frontend, self.timings.frontend_wait_s = self.scan_matching.result(rec.scans)
        else:
            self.frontend = run_frontend(rec.scans, cfg.frontend, progress=self.progress, odometry=rec.odometry)
        self.timings.frontend_s = self.frontend.time_s
        self.label_scan_matching_faults()

    def _matches_scans(self) -> bool:
        cfg = self.config
        return cfg.frontend.enabled and cfg.backend.factors.scan_matching.enabled

    def label_scan_matching_faults(self) -> None:
        """Add the times where the front-end's output is wrong (against
        ground truth) to the true fault intervals of each scan-matching
        modality; see slam.truth."""
        rec, ev = self.recording, self.config.evaluation
        if rec.groundtruth is None or self.frontend is None or not ev.sm_output_faults:
            return
        from slam.truth import scan_matching_output_faults, union_intervals

        wrong = scan_matching_output_faults(
            self.frontend.poses, rec.groundtruth, ev.sm_fault_window_s, ev.sm_fault_trans_m, ev.sm_fault_yaw_deg
        )
        for name, intervals in wrong.items():
            rec.faults[name] = union_intervals(rec.faults.get(name, []), intervals)

    def build_measurements(self) -> None:
        rec, cfg = self.recording, self.config
        candidates, scan_index = self._keyframe_candidates()
        chosen = select_keyframes(candidates, rec.odometry, cfg.keyframes)
        if len(chosen) < 2:
            limits = ", ".join(f"{k} {'null' if v is None else f'{v:g}'}" for k, v in cfg.keyframes.model_dump().items())
            raise GslamError(
                f"{self.input_path}: fewer than 2 keyframes: {len(candidates)} {self._candidate_stream()} stamps "
                f"over {rec.duration:.1f} s with keyframes {limits}; the run is too short or the limits too wide"
            )
        t = candidates[chosen]
        scan_idx = scan_index[chosen] if scan_index is not None else None
        sm = self.frontend.poses if self.frontend is not None else None
        self.measurements = build_measurements(rec, t, cfg.backend.factors, scan_idx, sm)

    def validate(self) -> None:
        """Gate the factors per keyframe and degree of freedom
        (``validation.mode``: on, oracle or interval_oracle)."""
        from slam.config import validation_sections
        from slam.measurements import FACTOR_DOFS

        vcfg, gcfg = validation_sections(self.config)
        n = len(self.measurements)
        if vcfg.mode == "off":
            from slam.backend import unit_weights

            self.weights = unit_weights(n)
            return
        if vcfg.mode == "oracle":
            self.tight_oracle(vcfg.oracle_k_sigma)
            return
        from validation.validator import run_validation

        rec = self.recording
        if vcfg.mode == "interval_oracle" and not any(rec.faults.values()):
            log.info("oracle gating without true fault intervals: nothing will be gated")
        sm = self.frontend.poses if self.frontend is not None else None
        quality = None
        if vcfg.mode == "on" and vcfg.observers.scan.enabled and self.frontend is not None:
            from slam.frontend import scan_quality

            quality = scan_quality(rec.scans, self.config.frontend)
        self.validation = run_validation(
            rec, sm, self.measurements.t, vcfg, gcfg, FACTOR_DOFS, rec.faults, rec.magnetic_reference, quality
        )
        self.weights = self.validation.weights
        self.timings.validation_s = self.validation.time_s
        self.extra_outputs["validation.csv"] = self.validation.csv_text  # written while the figures are drawn

    def learn_odometry_scale(self) -> None:
        """With ``backend.factors.odometry.learn_scale`` and validation on
        (or an oracle), the odometry stands in for the scan matcher with the
        scan matcher's scale: its distance is corrected by the scale learnt
        where validation keeps both (:mod:`slam.odometry_scale`), on the steps where
        the scan matcher's forward motion is gated. Elsewhere the graph fuses
        the two as they are. Without validation nothing says where the scan
        matcher can be trusted, and nothing is learnt."""
        from slam.backend import dof_weights
        from slam.config import validation_sections
        from slam.odometry_scale import odometry_scale

        odo, sm = self.measurements.odometry, self.measurements.scan_matching
        if not self.config.backend.factors.odometry.learn_scale or odo is None or sm is None:
            return
        if validation_sections(self.config)[0].mode == "off":
            return
        est = odometry_scale(self.measurements, self.weights)
        stand_in = dof_weights(self.weights["scan_matching"], "scan_matching")[:, 0] > 1.0
        odo.delta[stand_in, :2] *= est.scale
        self.extra_metrics["odometry_scale"] = {
            "scale": round(est.scale, 5), "windows": est.windows, "spread": round(est.spread, 5),
            "steps_corrected": int(stand_in.sum()),
        }

    def recheck(self) -> None:
        """Offline validation's recheck: keep the blamed measurements
        that agree with the other sensors (:mod:`slam.recheck`)."""
        from slam.config import validation_sections
        from slam.recheck import recheck

        vcfg, gating = validation_sections(self.config)
        if vcfg.mode != "on" or not vcfg.offline:
            return
        t = time.perf_counter()
        result = recheck(self.measurements, self.weights, self._initial_pose(), self.config.backend, gating)
        self.weights = result.weights
        self.constraints = result.constraints
        self.extra_metrics.update(result.metrics)
        self.timings.validation_s += time.perf_counter() - t

    def tight_oracle(self, k_sigma: float) -> None:
        """Exclude exactly the measurements (per degree of freedom) that are
        wrong by more than ``k_sigma`` sigmas against the ground truth."""
        from slam.truth import tight_oracle_weights

        if self.recording.groundtruth is None:
            raise GslamError(f"{self.input_path}: validation.mode oracle needs ground truth; the input has none")
        oracle = tight_oracle_weights(self.measurements, self.recording.groundtruth, k_sigma)
        self.weights = oracle.weights
        self.extra_metrics.update(oracle.metrics())
        self.extra_outputs["validation.csv"] = oracle.csv_text()

    def build_submaps(self) -> None:
        """Scan-to-submap constraints (:mod:`slam.submaps`) over the
        keyframes' scans, searched around the dead-reckoning chain (with the
        validator's weights). The local and near ones join the graph as scan
        matching, gated with it (:meth:`_submap_factors`); the loops are
        judged in :meth:`close_loops`."""
        cfg, meas = self.config.submaps, self.measurements
        if not cfg.enabled or self.frontend is None or meas.scan_index is None:
            return
        from slam.loops.chain import fuse_steps
        from slam.submaps.build import build_submap_constraints

        t = time.perf_counter()
        steps, step_cov = fuse_steps(meas, self.weights)
        self.submaps = build_submap_constraints(
            self.recording.scans, meas.scan_index, steps, step_cov, self.config.frontend, cfg
        )
        self.constraints = [*self.constraints, *self._submap_factors()]
        self.timings.submaps_s = time.perf_counter() - t

    def _submap_factors(self) -> list:
        """The local and near submap constraints as between factors. A
        constraint rests on the scans of its submap and on its own: each
        degree of freedom takes the largest scan-matching weight over those
        keyframes (an excluded one drops that degree of freedom)."""
        from slam.backend import dof_weights
        from slam.measurements import RelativeConstraint

        sm = self.weights.get("scan_matching")
        w = dof_weights(sm, "scan_matching") if sm is not None else np.ones((len(self.measurements), 3))
        out = []
        for c in self.submaps.of_kind("intra", "near"):
            steps = [c.scan, *self.submaps.submap_keyframes(c.submap)]
            worst = w[steps].max(axis=0)
            if not np.all(np.isfinite(worst)) and not np.any(np.isfinite(worst)):
                continue
            scale = np.where(np.isfinite(worst), 1.0 / worst, 0.0)
            info = c.information * np.outer(scale, scale)
            out.append(RelativeConstraint(c.anchor, c.scan, c.delta, np.full(3, np.inf), "scan_matching", "submap", info))
        return out

    def close_loops(self) -> None:
        """Find loop closures, check them (loop observer, LOOP in the
        diagnosis with validation on, ground truth in oracle mode) and keep
        the ones that pass; see slam.loops and validation.loops."""
        cfg = self.config.loops
        if not cfg.enabled:
            return
        from slam.backend import _robust_kernel
        from slam.loops.factors import LoopFactors
        from validation.loops.observer import observe_loops

        start = time.perf_counter()
        self.loop_search = search = self.find_loops()
        obs = observe_loops(search.chain, search.loops, cfg.observer)
        if search.rejected:  # rejected before the observer (the submaps' GNC)
            from validation.loops.observer import count_reasons

            for v in obs.verdicts:
                if v.loop.id in search.rejected:
                    v.accepted, v.reason = False, search.rejected[v.loop.id]
            obs.counts = count_reasons(obs.verdicts)
        self._gate_loops(obs)
        self.loop_observation = obs
        kernel = cfg.robust_kernel if cfg.robust_kernel is not None else self.config.backend.robust_kernel
        param = cfg.robust_param if cfg.robust_param is not None else self.config.backend.robust_param
        self.loop_factors = LoopFactors(obs.accepted, _robust_kernel(kernel, param), cfg.gnc, obs.inflation)
        self.timings.loops_s = time.perf_counter() - start
        self.extra_outputs["loops.csv"] = self._loops_csv()
        if self.validation is not None:
            self.extra_outputs["validation.csv"] = self.validation.csv_text()

    def find_loops(self):
        """The loops of this run before they are checked (slam.loops.search)."""
        from slam.loops.search import find_loops

        return find_loops(self.recording, self.measurements, self.weights, self.config, self._initial_pose(),
                          self.submaps)

    def _gate_loops(self, obs) -> None:
        from slam.config import validation_sections
        from validation.loops.gating import gate_loops, oracle_loops

        vcfg, gcfg = validation_sections(self.config)
        if vcfg.mode == "oracle":
            truth = self._keyframe_truth()
            if truth is None:
                log.info("oracle gating without ground truth: loops are kept as the loop observer decided")
                return
            ev = self.config.evaluation
            oracle_loops(obs, truth, ev.sm_fault_trans_m, np.radians(ev.sm_fault_yaw_deg))
        elif vcfg.mode == "on":
            step_t = self.validation.step_t
            gated = gate_loops(obs, step_t, self.measurements.t, vcfg.model, gcfg, vcfg.offline)
            self.validation.extra_columns.update(gated.columns())

    def _keyframe_truth(self) -> np.ndarray | None:
        rec = self.recording
        return None if rec.groundtruth is None else interpolate_poses(rec.groundtruth, self.measurements.t)

    def _loops_csv(self) -> str:
        """One row per loop: where, what, how well verified, and the decision."""
        import csv
        import io

        t = self.measurements.t
        buf = io.StringIO()
        w = csv.writer(buf, lineterminator="\n")
        w.writerow(["id", "i", "j", "t_i", "t_j", "source", "dx_m", "dy_m", "dyaw_deg", "quality", "chain_chi2", "decision",
                    "reason", "free"])
        for v in self.loop_observation.verdicts:
            lp = v.loop
            quality = " ".join(f"{k}={val}" for k, val in lp.quality.items())
            w.writerow([
                lp.id, lp.i, lp.j, round(float(t[lp.i]), 4), round(float(t[lp.j]), 4), lp.source,
                round(float(lp.delta[0]), 4), round(float(lp.delta[1]), 4), round(float(np.degrees(lp.delta[2])), 3),
                quality, v.chain_chi2, "accepted" if v.accepted else "rejected", v.reason, _free_directions(lp.information),
            ])
        return buf.getvalue()

    def optimise(self) -> None:
        from slam.backend import optimise

        pose0 = self._initial_pose()
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
            from validation.loops.chain import between, compose

            est = self.submaps.estimate
            start = compose(np.repeat(pose0[None], len(est), axis=0), between(np.repeat(est[:1], len(est), axis=0), est))
        self.backend = optimise(
            self.measurements, pose0, self.config.backend, self.weights, progress=progress,
            constraints=self.constraints, loops=self.loop_factors, initial_poses=start,
        )
        self.timings.graph_build_s = self.backend.build_time_s
        self.timings.optimise_s = self.backend.optimise_time_s

    def evaluate(self) -> None:
        rec, est = self.recording, self.backend.trajectory
        m: dict[str, Any] = {"input": str(self.input_path), "n_poses": len(est), "duration_s": round(rec.duration, 3)}
        if rec.groundtruth is not None:
            from slam.evaluation import evaluate

            ev = self.config.evaluation
            m.update(evaluate(est, rec.groundtruth, ev.rpe_deltas_m, ev.max_time_offset_s))
        m["factor_counts"] = self.backend.factor_counts
        m["fallback_steps"] = self.backend.fallback_steps
        if self.loop_observation is not None:
            m["loops"] = self._loop_metrics()
        if self.submaps is not None:
            m["submaps"] = self._submap_metrics()
        if self.validation is not None:
            m.update(self.validation.metrics)
        m.update(self.extra_metrics)
        self.metrics = m

    def _loop_metrics(self) -> dict[str, Any]:
        """Counts of loops by decision, detection's work, and, with ground
        truth, how many kept loops are wrong and rejected ones right."""
        search, obs = self.loop_search, self.loop_observation
        out: dict[str, Any] = {"source": search.source, **obs.counts}
        det = search.detection
        if det is not None:
            out.update(places=len(det.places), candidates=det.candidates, registrations=det.registrations)
            out["verification_rejected"] = dict(sorted(det.rejected.items()))
        out["clique_proven"] = obs.clique_proven
        out["chain_scale"] = round(obs.chain_scale, 3)
        truth = self._keyframe_truth()
        if truth is not None:
            from validation.loops.gating import loop_is_true

            ev = self.config.evaluation
            ok = [loop_is_true(v.loop, truth, ev.sm_fault_trans_m, np.radians(ev.sm_fault_yaw_deg)) for v in obs.verdicts]
            out["true_found"] = int(sum(ok))
            out["wrong_accepted"] = int(sum(1 for v, good in zip(obs.verdicts, ok) if v.accepted and not good))
            out["true_rejected"] = int(sum(1 for v, good in zip(obs.verdicts, ok) if not v.accepted and good))
        return out

    def _submap_metrics(self) -> dict[str, Any]:
        """Submaps, searches and constraints by kind; with ground truth, how
        many kept and dropped constraints are wrong (as for loops)."""
        res = self.submaps
        out: dict[str, Any] = {"submaps": len(res.local.submaps), "nodes": len(res.nodes), "searches": res.searches}
        kinds = ("intra", "near", "loop")
        out["kept"] = {k: len(res.of_kind(k)) for k in kinds}
        out["dropped"] = {k: sum(c.kind == k for c in res.dropped) for k in kinds}
        truth = self._keyframe_truth()
        if truth is not None:
            from validation.loops.gating import pinned_error
            from validation.loops.chain import between

            ev = self.config.evaluation

            def wrong(c) -> bool:
                e = pinned_error(c.information, between(between(truth[c.anchor], truth[c.scan]), c.delta))
                return bool(np.hypot(e[0], e[1]) > ev.sm_fault_trans_m or abs(e[2]) > np.radians(ev.sm_fault_yaw_deg))

            out["wrong_kept"] = {k: sum(wrong(c) for c in res.of_kind(k)) for k in kinds}
            out["wrong_dropped"] = {k: sum(wrong(c) for c in res.dropped if c.kind == k) for k in kinds}
        return out

    def start_figures(self, folder: Path) -> None:
        """Hand the estimate to the result writer as soon as it is final,
        then the map's points (kept for ``map.ply``), the keyframes' scans
        for the occupancy grid, and the rest of ``run.mcap``."""
        t = time.perf_counter()
        if self.outputs is not None:
            rec = self.recording
            self.outputs.submit(FinalEstimate(folder, rec.name, self.backend.trajectory, rec.groundtruth, rec.faults))
        self.points = self.map_points()
        if self.outputs is not None:
            self.outputs.submit_map(self.map_inputs())
        self.timings.write_s += time.perf_counter() - t

    def map_inputs(self) -> MapInputs:
        """What the grid, ``map.png`` and ``run.mcap`` are made from
        (``output.grid``, ``output.mcap``): the keyframes' scans and the
        validator's statuses per step (:mod:`slam.validation_status`)."""
        rec, meas, out = self.recording, self.measurements, self.config.output
        inputs = MapInputs(points=self.points)
        if rec.scans is not None and meas.scan_index is not None and (out.grid or out.mcap):
            inputs.ranges, inputs.angles = rec.scans.ranges[meas.scan_index], rec.scans.angles
            inputs.beam_limits = self._beam_limits()
        if out.grid:
            from slam.occupancy import GridModel

            inputs.grid = GridModel(out.grid_resolution_m, out.grid_hit_probability, out.grid_miss_probability,
                                    out.grid_no_return_m)
        if out.mcap:
            from slam.io.run_mcap import RunContent

            est = self.backend.trajectory
            inputs.mcap = content = RunContent(rec.t0, est)
            truth = self._keyframe_truth()
            if truth is not None:
                content.reference = Trajectory(est.t, truth[:, 0], truth[:, 1], truth[:, 2])
            if self.validation is not None:
                from slam.config import validation_sections
                from slam.validation_status import step_statuses

                model = validation_sections(self.config)[0].model
                content.statuses = step_statuses(self.validation, model.components if model is not None else ())
        return inputs

    def write(self, folder: Path) -> None:
        """Write the numeric results into ``folder`` (the temporary folder
        that is renamed into place afterwards) while the figures, grid and
        bag are made, then wait for them; metrics.json last."""
        t = time.perf_counter()
        self._write_into(folder, self.points)
        self.timings.write_s += time.perf_counter() - t
        if self.outputs is not None:
            t = time.perf_counter()
            made = self.outputs.wait()
            self.timings.plots_wait_s = time.perf_counter() - t
            self.timings.grid_s, self.timings.mcap_s = made.grid_s, made.mcap_s
            if made.grid is not None:
                self.metrics["grid"] = made.grid
            if made.mcap_messages is not None:
                self.metrics["mcap_messages"] = made.mcap_messages
        # Everything but renaming the folder into place and writing this file.
        self.metrics["runtime_s"] = round(time.perf_counter() - self._start, 4)
        self._add_timings()
        (folder / "metrics.json").write_text(json.dumps(self.metrics, indent=2) + "\n")

    # -- details --------------------------------------------------------------

    def _keyframe_candidates(self) -> tuple[np.ndarray, np.ndarray | None]:
        """Keyframes sit on scan times when scan matching runs, else on
        odometry, gyro or compass times (the first stream present)."""
        rec = self.recording
        if self.frontend is not None:
            return rec.scans.t, np.arange(len(rec.scans))
        for stream in (rec.odometry, rec.gyro, rec.compass):
            if stream is not None:
                return stream.t, None
        raise GslamError(f"{self.input_path}: no odometry, gyro, compass or laser stream to map with")

    def _candidate_stream(self) -> str:
        rec = self.recording
        if self.frontend is not None:
            return "laser scan"
        return next(name for name, s in (("odometry", rec.odometry), ("gyro", rec.gyro), ("compass", rec.compass))
                    if s is not None)

    def _initial_pose(self) -> np.ndarray:
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

    def _add_timings(self) -> None:
        tm = self.timings
        self.metrics["timings_s"] = {
            "read": round(tm.read_s, 4),
            "frontend": round(tm.frontend_s, 4),
            "validation": round(tm.validation_s, 4),
            "loops": round(tm.loops_s, 4),
            "submaps": round(tm.submaps_s, 4),
            "graph_build": round(tm.graph_build_s, 4),
            "optimise": round(tm.optimise_s, 4),
            "write": round(tm.write_s, 4),
            "grid": round(tm.grid_s, 4),
            "mcap": round(tm.mcap_s, 4),
            "prepare": round(tm.prepare_s, 4),
            "frontend_wait": round(tm.frontend_wait_s, 4),
            "plots_wait": round(tm.plots_wait_s, 4),
        }
        total = self.metrics.get("runtime_s") or 0.0
        if total:
            self.metrics["realtime_factor"] = round(self.recording.duration / total, 2)

    def _write_into(self, d: Path, points: np.ndarray | None) -> None:
        """The numeric results (config.yaml and groundtruth.tum are written
        by :meth:`prepare`, the figures by the plot writer)."""
        from slam.io.tum import write_tum

        rec, est = self.recording, self.backend.trajectory
        write_tum(d / "trajectory.tum", est, rec.t0)
        for name, text in self.extra_outputs.items():
            (d / name).write_text(text() if callable(text) else text)
        if points is not None:
            from slam.io.pointcloud import write_ply

            write_ply(d / "map.ply", points)

    def map_points(self, chunk: int = 2048) -> np.ndarray | None:
        """Laser points of every keyframe in its optimised pose, voxel-thinned
        (world frame, m, (n, 2)).

        Keyframes are projected ``chunk`` at a time and each chunk thinned on
        its own: the first point of a voxel over all chunks is the first of
        the chunks' firsts, so the map does not depend on ``chunk``.
        """
        from slam.io.pointcloud import voxel_downsample

        rec, meas = self.recording, self.measurements
        if rec.scans is None or meas.scan_index is None:
            return None
        est, voxel = self.backend.trajectory, self.config.output.map_voxel_m
        project = ScanProjector(rec.scans.angles, *self._beam_limits())
        chunks = []
        for lo in range(0, len(meas.scan_index), chunk):
            k = slice(lo, lo + chunk)
            poses = Trajectory(est.t[k], est.x[k], est.y[k], est.yaw[k])
            chunks.append(voxel_downsample(project.world_points(rec.scans.ranges[meas.scan_index[k]], poses)[0], voxel))
        points = np.concatenate(chunks) if chunks else np.zeros((0, 2))
        return voxel_downsample(points, voxel)

    def _beam_limits(self) -> tuple[float, float]:
        """The ranges (m) a beam must lie within to be a return: the
        front-end's, and the scanner's own maximum."""
        fe = self.config.frontend
        return fe.min_range_m, min(fe.max_range_m, self.recording.scans.range_max)


def _free_directions(information: np.ndarray) -> str:
    """The directions (x y yaw, unit vectors in the frame of the loop's later
    keyframe, ``;``-separated) a loop's information leaves free; empty when
    it pins all three."""
    values, vectors = np.linalg.eigh(0.5 * (information + information.T))
    free = vectors[:, values <= 1e-9 * max(values.max(), 1e-300)]
    return ";".join(" ".join(f"{c:.4f}" for c in v) for v in free.T)


def run_map(
    input_path: str | Path,
    config: PipelineConfig,
    out_dir: str | Path,
    progress: bool = False,
    inputs: Sequence[str | Path] = (),
    force: bool = False,
    concurrent: bool = True,
) -> MapResult:
    """Map one run (the library form of ``gslam map``); ``inputs``,
    ``force`` and ``concurrent`` as for :class:`MappingPipeline`."""
    pipe = MappingPipeline(input_path, config, out_dir, progress=progress, inputs=inputs, force=force, concurrent=concurrent)
    return pipe.run()
