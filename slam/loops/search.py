"""Finding the loops of one run: the pipeline step's entry point, :func:`find_loops`."""


from __future__ import annotations

import logging
import time
from dataclasses import dataclass

import numpy as np

from slam.config import PipelineConfig
from slam.errors import GslamError
from slam.loops.chain import Chain, build_chain
from slam.loops.constraints import LoopConstraint
from slam.loops.detector import Detection, LoopDetector
from slam.loops.file_loops import file_loops
from slam.loops.local_maps import KeyframePoints
from slam.measurements import Measurements
from slam.recording import Recording

log = logging.getLogger(__name__)


@dataclass
class LoopSearch:
    """Loops found in one run, before the loop observer.

    ``chain``: the dead-reckoning chain they are judged against;
    ``detection``: detection's counts (None for listed loops); ``source``:
    ``scans``, ``file`` or ``none``; ``time_s``: wall time.
    """

    chain: Chain
    loops: list[LoopConstraint]
    detection: Detection | None
    source: str
    time_s: float


def find_loops(
    recording: Recording,
    meas: Measurements,
    weights: dict[str, np.ndarray] | None,
    config: PipelineConfig,
    initial_pose: np.ndarray,
) -> LoopSearch:
    """Loops of one run from its keyframe measurements (``weights``: the
    validator's, so the chain leaves out what validation excluded)."""
    cfg = config.loops
    start = time.perf_counter()
    chain = build_chain(meas, weights, initial_pose)
    source = cfg.source
    if source == "auto":
        source = "file" if recording.place_matches is not None else "scans"
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
