"""``gslam map``: one recorded run into a result folder.

The in-memory core (:mod:`slam.pipeline.core`) maps the run; around it this
driver reads the input, writes the result folder and keeps the second core
busy. The folder follows :mod:`slam.results.outdir`: ``--out`` is checked
before any work, the result is built in a temporary sibling and renamed
into place at the end, so a killed run leaves a complete folder or none.

Three steps run beside the others on the second core (``concurrent``, the
default): KISS-ICP registers the scans while the other topics are read and
the next steps prepared (:mod:`slam.frontend.worker`); the submaps' walk
follows their local SLAM scan by scan (:mod:`slam.submaps.build`); and the
figures, the occupancy grid and ``run.mcap`` are made while the numeric
results are written, and the map's self-check beside them, in a process
that imported open3d while the run was mapped (:mod:`slam.outputs.result_writer`). Each is the same
code on the same data as in the plain order (``concurrent=False``), so the
results are the same bytes. gtsam and validation are imported while the scans are
matched, not before.
"""

from __future__ import annotations

import json
import logging
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from slam.config import PipelineConfig, dump_config
from slam.frontend.kiss import FrontendResult
from slam.frontend.worker import BackgroundScanMatching
from slam.outputs.result_writer import FinalEstimate, MapInputs, ResultWriter, SelfChecker
from slam.pipeline.core import Mapping, matches_scans
from slam.recording import Recording, Trajectory
from slam.results.outdir import result_folder

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


class MappingPipeline:
    """Map one run with the given config into ``out_dir``; see :meth:`run`.

    ``recording`` and ``frontend`` may be given to reuse what another
    variant of the same run already computed (``gslam compare``).
    ``inputs``: other files the run reads (the config), which ``out_dir``
    must not be or hold; ``force``: write into a folder that is not a map
    result (see :mod:`slam.results.outdir`); ``concurrent``: match scans and
    draw figures in a second process (see the module docstring);
    ``shared_s``: the seconds another variant took to read and match what
    this one reuses, which ``metrics.json`` adds to this run's
    ``runtime_s`` as ``runtime_with_shared_s`` (None: no such figure). After
    :meth:`run`, :attr:`core` holds the run in memory.
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
        shared_s: float | None = None,
    ):
        self.input_path = Path(input_path)
        self.config = config
        self.out_dir = Path(out_dir)
        self.progress = progress
        self.recording = recording
        self.frontend = frontend
        self.inputs = [self.input_path, *map(Path, inputs)]
        self.force = force
        self.concurrent = concurrent
        self.shared_s = shared_s
        self.scan_matching: BackgroundScanMatching | None = None
        self.outputs: ResultWriter | None = None
        self.checker: SelfChecker | None = None
        self.core: Mapping | None = None
        self.points = None  # the map's points, for map.ply
        self._start = time.perf_counter()

    @property
    def metrics(self) -> dict[str, Any]:
        return self.core.metrics

    def run(self) -> MapResult:
        self._start = time.perf_counter()
        with result_folder(self.out_dir, "map", self.inputs, self.force, RESULT_FILES) as tmp:
            self.start_helpers()
            try:
                self.read()
                self.prepare(tmp)
                core = self.core
                core.run(self.scan_matching)
                self.frontend = core.frontend
                self.start_figures(tmp)
                self.checker.submit(core.self_check_inputs())
                self.write(tmp)
            finally:  # before a failed result's folder is removed
                self.close_helpers()
        return MapResult(self.out_dir, core.metrics, core.backend.trajectory, self.recording, core.validation)

    # -- around the core ------------------------------------------------------

    def start_helpers(self) -> None:
        """The second process's work: scan matching (unless it is reused),
        the result files made from the estimate and the map's self-check;
        each waits for its data."""
        cfg = self.config
        out = cfg.output
        self.checker = SelfChecker(self.concurrent)
        if out.plots or out.grid or out.mcap:
            self.outputs = ResultWriter(self.concurrent, out.plots, out.mcap)
        if self.recording is None and self.frontend is None and matches_scans(cfg):
            self.scan_matching = BackgroundScanMatching(cfg.frontend, self.progress, self.concurrent)

    def close_helpers(self) -> None:
        for helper in (self.scan_matching, self.outputs, self.checker):
            if helper is not None:
                helper.close()

    def read(self) -> None:
        """Read the input (unless it is reused), check that the config fits
        it, and make the core that maps it."""
        from slam.pipeline.config_fit import check_fit

        t = time.perf_counter()
        if self.recording is None:
            from slam.readers.read import read_recording

            sm = self.scan_matching
            early = sm.give if sm is not None and not sm.needs_odometry else None
            self.recording = read_recording(self.input_path, self.config.input, on_scans=early)
            if sm is not None:  # without scans, or for odometry guesses: now
                sm.give(self.recording.scans, self.recording.odometry)
        read_s = time.perf_counter() - t
        rec = self.recording
        log.info("read %s: %.1f s of data", rec.name, rec.duration)
        # Whether the config fits the recording, before any work on it; a
        # laser that returns nothing within the front-end's limits is left
        # out, and its scan matching with it.
        had_scans = rec.scans is not None
        check_fit(rec, self.config, self.input_path)
        if had_scans and rec.scans is None and self.scan_matching is not None:
            self.scan_matching.close()
            self.scan_matching = None
        self.core = Mapping(rec, self.config, self.frontend, self.input_path, self.progress, self.concurrent)
        self.core.timings.read_s = read_s

    def prepare(self, folder: Path) -> None:
        """What needs no estimate, done while the scans are matched: the
        config and the reference into ``folder``, and the imports of the
        next steps."""
        t = time.perf_counter()
        rec = self.recording
        (folder / "config.yaml").write_text(dump_config(self.config))
        if rec.groundtruth is not None:
            from slam.outputs.tum import write_tum

            write_tum(folder / "groundtruth.tum", rec.groundtruth, rec.t0)
        if self.scan_matching is not None:
            import_next_steps(self.config.submaps.enabled)
        self.core.timings.prepare_s = time.perf_counter() - t

    def start_figures(self, folder: Path) -> None:
        """Hand the estimate to the result writer as soon as it is final,
        then the map's points (kept for ``map.ply``), the keyframes' scans
        for the occupancy grid, and the rest of ``run.mcap``."""
        from slam.outputs.pointcloud import map_points

        core = self.core
        t = time.perf_counter()
        if self.outputs is not None:
            rec = self.recording
            self.outputs.submit(FinalEstimate(folder, rec.name, core.backend.trajectory, rec.groundtruth,
                                              rec.fault_truth or {}))
        self.points = map_points(core.recording, core.measurements.scan_index, core.backend.trajectory,
                                 self.config.frontend, self.config.output.map_voxel_m)
        if self.outputs is not None:
            self.outputs.submit_map(self.map_inputs())
        core.timings.write_s += time.perf_counter() - t

    def map_inputs(self) -> MapInputs:
        """What the grid, ``map.png`` and ``run.mcap`` are made from
        (``output.grid``, ``output.mcap``): the keyframes' scans and the
        validator's statuses per step (:mod:`slam.outputs.validation_status`)."""
        from slam.outputs.pointcloud import beam_limits

        core, rec, out = self.core, self.recording, self.config.output
        meas = core.measurements
        inputs = MapInputs(points=self.points)
        if rec.scans is not None and meas.scan_index is not None and (out.grid or out.mcap):
            inputs.ranges, inputs.angles = rec.scans.ranges[meas.scan_index], rec.scans.angles
            inputs.beam_limits = beam_limits(self.config.frontend, rec.scans)
        if out.grid:
            from slam.outputs.occupancy import GridModel

            inputs.grid = GridModel(out.grid_resolution_m, out.grid_hit_probability, out.grid_miss_probability,
                                    out.grid_no_return_m)
        if out.mcap:
            from slam.outputs.run_mcap import RunContent

            est = core.backend.trajectory
            inputs.mcap = content = RunContent(rec.t0, est)
            truth = core.keyframe_truth()
            if truth is not None:
                content.reference = Trajectory(est.t, truth[:, 0], truth[:, 1], truth[:, 2])
            if core.validation is not None:
                from slam.outputs.validation_status import step_statuses

                model = core.policy.validation.model
                content.statuses = step_statuses(core.validation, model.components if model is not None else ())
        return inputs

    def write(self, folder: Path) -> None:
        """Write the numeric results into ``folder`` (the temporary folder
        that is renamed into place afterwards) while the figures, grid and
        bag are made, then wait for them; metrics.json last."""
        from slam.outputs.pointcloud import write_ply
        from slam.outputs.tum import write_tum

        core = self.core
        tm, metrics = core.timings, core.metrics
        t = time.perf_counter()
        write_tum(folder / "trajectory.tum", core.backend.trajectory, self.recording.t0)
        for name, text in core.extra_outputs.items():
            (folder / name).write_text(text() if callable(text) else text)
        if self.points is not None:
            write_ply(folder / "map.ply", self.points)
        tm.write_s += time.perf_counter() - t
        core.check_self(self.checker.wait())
        if self.outputs is not None:
            t = time.perf_counter()
            made = self.outputs.wait()
            tm.plots_wait_s = time.perf_counter() - t
            tm.grid_s, tm.mcap_s = made.grid_s, made.mcap_s
            if made.grid is not None:
                metrics["grid"] = made.grid
            if made.mcap_messages is not None:
                metrics["mcap_messages"] = made.mcap_messages
        # Everything but renaming the folder into place and writing this file.
        metrics["runtime_s"] = round(time.perf_counter() - self._start, 4)
        if self.shared_s is not None:
            metrics["runtime_with_shared_s"] = round(metrics["runtime_s"] + self.shared_s, 4)
        metrics["timings_s"] = {name.removesuffix("_s"): round(value, 4) for name, value in vars(tm).items()}
        metrics.update(realtime_factor(self.recording, metrics.get("runtime_with_shared_s", metrics["runtime_s"])))
        (folder / "metrics.json").write_text(json.dumps(metrics, indent=2) + "\n")


def realtime_factor(rec: Recording, runtime_s: float) -> dict[str, Any]:
    """``realtime_factor``: the recording's duration over ``runtime_s``;
    where the reader synthesised the times (they are not seconds), null and
    ``realtime_factor_unavailable`` says why; nothing for a zero runtime."""
    if rec.stamps_synthesised is not None:
        return {"realtime_factor": None,
                "realtime_factor_unavailable": f"the recording's stamps are unusable: {rec.stamps_synthesised}"}
    return {"realtime_factor": round(rec.duration / runtime_s, 2)} if runtime_s else {}


def import_next_steps(submaps: bool) -> None:
    """Import what the steps after scan matching need while it runs in the
    second process (gtsam and the validator take a second to load; numba,
    for the ``submaps``' search, half a second, and once here rather than
    in each of the submaps' two processes). The search's compiled kernels
    are loaded from numba's cache here too: the first search would
    otherwise spend a third of a second on it after scan matching."""
    import numpy.ma  # noqa: F401 - numpy's median loads it on first use

    if submaps:
        from slam.matching import kernels

        kernels.load()

    import slam.gating.odometry_scale  # noqa: F401
    import slam.gating.recheck  # noqa: F401
    import slam.gating.truth  # noqa: F401
    import slam.graph.backend  # noqa: F401
    import slam.outputs.evaluation  # noqa: F401
    import slam.outputs.self_check  # noqa: F401
    import slam.outputs.tum  # noqa: F401
    import slam.outputs.validation_status  # noqa: F401
    import validation.validator  # noqa: F401


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
