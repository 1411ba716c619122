"""Finding the loops of one run: the pipeline step's entry point, :func:`find_loops`."""


from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field

import numpy as np

from slam.config import PipelineConfig
from slam.errors import GslamError
from slam.loops.chain import Chain, build_chain
from validation.loops.constraint import LoopConstraint
from slam.loops.detector import Detection, LoopDetector
from slam.loops.file_loops import file_loops
from slam.loops.local_maps import KeyframePoints
from slam.graph.measurements import Measurements
from slam.recording import Recording

log = logging.getLogger(__name__)


@dataclass
class LoopSearch:
    """Loops found in one run, before the loop observer.

    ``chain``: the dead-reckoning chain they are judged against;
    ``detection``: detection's counts (None for listed loops); ``source``:
    ``submaps``, ``scans``, ``file`` or ``none``; ``time_s``: wall time;
    ``rejected``: loops (by id) the search itself rejected, and why (the
    submaps' GNC: ``gnc``), which the observer reports as rejected.
    """

    chain: Chain
    loops: list[LoopConstraint]
    detection: Detection | None
    source: str
    time_s: float
    rejected: dict[int, str] = field(default_factory=dict)


def find_loops(
    recording: Recording,
    meas: Measurements,
    weights: dict[str, np.ndarray] | None,
    config: PipelineConfig,
    initial_pose: np.ndarray,
    submaps=None,
) -> LoopSearch:
    """Loops of one run from its keyframe measurements (``weights``: the
    validator's, so the chain leaves out what validation excluded);
    ``submaps``: the run's :class:`slam.submaps.build.SubmapResult`, if any."""
    cfg = config.loops
    start = time.perf_counter()
    chain = build_chain(meas, weights, initial_pose)
    source = cfg.source
    if source == "auto":
        source = "file" if recording.place_matches is not None else "submaps" if submaps is not None else "scans"
    if source == "submaps":
        if submaps is None:  # no scans: the reader said why; scans without scan matching: said here
            (log.info if recording.scans is None else log.warning)(
                "%s: no submaps to close loops in (%s): no loop closing", recording.name,
                "no laser scans" if recording.scans is None else "scan matching is off")
            return LoopSearch(chain, [], None, "none", time.perf_counter() - start)
        kept, dropped = submap_loops(submaps.of_kind("loop")), submap_loops(submaps.dropped_of_kind("loop"))
        for k, lp in enumerate(dropped, start=len(kept)):
            lp.id = k
        rejected = {lp.id: "gnc" for lp in dropped}
        return LoopSearch(chain, kept + dropped, None, source, time.perf_counter() - start, rejected)
    if source == "file":
        if recording.place_matches is None:
            raise GslamError(f"loops.source is file, but {recording.name} lists no loop closures")
        max_gap = float(np.median(np.diff(meas.t))) if len(meas) > 1 else 0.0
        loops = file_loops(recording.place_matches, meas.t, cfg.file, max_gap)
        return LoopSearch(chain, loops, None, source, time.perf_counter() - start)
    if recording.scans is None or meas.scan_index is None:
        if cfg.source == "scans":
            raise GslamError(f"loops.source is scans, but {recording.name} has no laser scans (or scan matching is off)")
        log.info("no laser scans and no listed loops: no loop closing")
        return LoopSearch(chain, [], None, "none", time.perf_counter() - start)
    fe = config.frontend
    points = KeyframePoints(
        recording.scans, meas.scan_index, fe.min_range_m, fe.max_range_m, cfg.voxel_m, cfg.registration
    )
    det = LoopDetector(points, chain, cfg).run()
    return LoopSearch(chain, det.loops, det, source, time.perf_counter() - start)


def submap_loops(constraints) -> list[LoopConstraint]:
    """Loop constraints of the submaps' search (:class:`slam.submaps.graph.Constraint`)
    as loops: the carrier scan's keyframe to the matched scan's."""
    return [
        LoopConstraint(k, c.anchor, c.scan, np.asarray(c.delta, dtype=float), c.information, "submaps",
                       {"score": round(float(c.score), 4), "submap": c.submap})
        for k, c in enumerate(constraints)
    ]
