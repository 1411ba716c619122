"""The runs a calibration learns from: each read and scan-matched as
``gslam map`` does, its validation streams resampled onto the validation
steps, and the steps it may learn from.

A run is learnt from over a stretch the user declares clean (``--clean
START:END``, seconds from the run's start; ``END`` may be ``end``), or
whole, with robust statistics (:mod:`slam.commands.calibrate.fit`) that a minority
of faulty steps does not move.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from slam.config import PipelineConfig
from slam.errors import GslamError
from slam.gating.policy import with_witnesses, witness_names
from slam.pipeline.config_fit import check_fit
from slam.pipeline.core import Mapping
from slam.readers.read import read_recording
from validation.config import ValidationConfig
from validation.observers import unary_checks
from validation.observers.checks import UnaryCheck
from validation.observers.config import field_gyro_stream, gps_course_limits
from validation.streams import StepStreams, Stream, fixed_rate_steps, resample_streams, validation_streams

log = logging.getLogger(__name__)

Clean = tuple[float, float]


def parse_clean(text: str | None) -> Clean | None:
    """``START:END`` (s; ``END`` may be ``end``) -> (start, end); None stays None."""
    if text is None:
        return None
    start, colon, end = text.partition(":")
    try:
        a = float(start)
        b = float("inf") if end.strip() == "end" else float(end)
    except ValueError:
        a = b = float("nan")
    if not colon or not (np.isfinite(a) and b > a >= 0.0):
        raise GslamError(f"--clean {text}: expected START:END in seconds from the run's start, END > START >= 0 "
                         "(END may be 'end'), e.g. 0:120")
    return a, b


@dataclass
class CalibrationRun:
    """One run on the validation steps: its streams, the steps resampled,
    the unary checks with its own magnetic reference, and the steps declared
    clean (all of them when nothing was declared: ``declared`` False)."""

    name: str
    streams: dict[str, Stream]
    steps: StepStreams
    checks: list[UnaryCheck]
    clean: np.ndarray
    declared: bool

    @property
    def duration_s(self) -> float:
        return float(self.steps.t[-1] - self.steps.t[0]) if len(self.steps.t) else 0.0


def load_run(path: str | Path, config: PipelineConfig, vcfg: ValidationConfig, clean: Clean | None,
             progress: bool = False) -> CalibrationRun:
    """Read ``path`` as ``gslam map`` would (reader, front-end, keyframes)
    and put its validation streams on the validation steps."""
    rec = read_recording(path, config.input)
    check_fit(rec, config, path)
    pipe = Mapping(rec, config, source=path, progress=progress)
    pipe.match_scans()
    pipe.build_measurements()
    kt = pipe.measurements.t
    obs = vcfg.observers
    sensors = with_witnesses(rec, {name: pipe.witness(name) for name in witness_names(vcfg)})
    streams = validation_streams(sensors, pipe.frontend.poses if pipe.frontend is not None else None,
                                 obs.gps_speed_window_s, vcfg.window, field_gyro_stream(obs),
                                 gps_course_limits(obs))
    step_t = fixed_rate_steps(float(kt[0]), float(kt[-1]), vcfg.rate_hz)
    steps = resample_streams(streams, step_t, obs.max_gap_s, obs.stream_max_gap_s, obs.gap_periods)
    mask = np.ones(len(step_t), dtype=bool)
    if clean is not None:
        mask = (step_t >= clean[0]) & (step_t <= clean[1])
        if not mask.any():
            raise GslamError(f"{path}: --clean {clean[0]:g}:{clean[1]:g} holds no validation step "
                             f"(the run's steps span {step_t[0]:.1f}-{step_t[-1]:.1f} s)")
    checks = unary_checks(obs, rec.magnetic_reference)
    log.info("%s: %d validation steps, %d declared clean", path, len(step_t), int(mask.sum()))
    return CalibrationRun(rec.name, streams, steps, checks, mask, clean is not None)
