"""``gslam calibrate``: relation models and observer parameters learnt
from recorded runs instead of typed in by hand.

1. Every run is read, scan-matched and put on the validation steps as
   ``gslam map`` would (:mod:`slam.commands.calibrate.runs`), over a stretch
   declared clean or whole.
2. Each relation of the config gets the gain and offset between its two
   streams' rates and the noise of their residual
   (:mod:`slam.commands.calibrate.fit`), then its boundary, window and threshold
   from that noise and the target false-alarm rate
   (:mod:`slam.commands.calibrate.select`): the run's target share of steps with a
   false alarm, split evenly over the observers. The magnetometer and
   field-gyro checks get their tolerances the same way.
3. Streams of different sensors whose rates correlate and which no
   relation compares yet are proposed as new relations
   (:mod:`slam.commands.calibrate.propose`). Yaw streams stamped early or late
   against the gyro are found (:mod:`slam.commands.calibrate.lags`); ``gslam
   calibrate`` adds the clear offsets to ``input.time_offsets_s``, reads
   the runs again with them and learns steps 2-3 anew, so the relations
   are learnt on streams as the model's config will read them. The
   compass factor's noise is measured against the gyro: the error of one
   heading and how long it stays alike (:mod:`slam.commands.calibrate.noise`).
4. The result is the input config with the learnt observers and the
   measured figures as comments (:mod:`slam.commands.calibrate.write`), for the
   pass (offline or causal) the config names. Learnt on some runs, it is
   used on others.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

from slam.commands.calibrate.heading import HeadingOffset, learn_heading_offset
from slam.commands.calibrate.lags import LagEstimate, learn_lags
from slam.commands.calibrate.noise import CompassNoise, learn_compass_noise
from slam.commands.calibrate.propose import Proposal, propose
from slam.commands.calibrate.distinct import distinct_runs
from slam.commands.calibrate.runs import CalibrationRun, load_run, parse_clean
from slam.commands.calibrate.select import (CheckChoice, Choice, FieldGyroChoice, calibrate_field_gyro, calibrate_magnetometer,
                                   calibrate_relation)
from slam.commands.calibrate.support import Support, judge, uses_fitted_gain
from slam.commands.calibrate.write import calibrated_config
from slam.config import PipelineConfig, check_given_once, config_files, load_config, validation_sections
from slam.errors import GslamError
from slam.results.outdir import check_new_file, file_state, write_result_file

__all__ = ["CalibrationResult", "calibrate", "learn", "load_run", "parse_clean"]

log = logging.getLogger(__name__)

DEFAULT_FALSE_ALARM = 0.005
"""Share of a run's validation steps with a false alarm that calibration aims at."""
MIN_FALSE_ALARM, MAX_FALSE_ALARM = 1e-6, 0.5
"""The shares ``--false-alarm`` may ask for."""


@dataclass
class CalibrationResult:
    """What ``gslam calibrate`` learnt and where it wrote it."""

    out: Path | None
    choices: dict[str, Choice | None]
    magnetometer: CheckChoice | None
    field_gyro: FieldGyroChoice | None
    proposals: list[Proposal]
    target_per_observer: float
    text: str
    lags: list[LagEstimate]
    applied: list[LagEstimate] = field(default_factory=list)
    """The first pass's estimates when their clear offsets were added to the config and the runs learnt again."""
    compass_noise: CompassNoise | None = None
    """The compass factor's noise written to the config (None: kept as configured)."""
    heading_offset: HeadingOffset | None = None
    """The compass heading against the GPS course (None: no GPS course)."""
    applied_heading: HeadingOffset | None = None
    """The first pass's heading offset when it was added to the compass's mounting yaw and the runs learnt again."""
    dropped: dict[str, Support] = field(default_factory=dict)
    """The relations the data do not support, left out of the config (:mod:`slam.commands.calibrate.support`)."""
    support: dict[str, Support] = field(default_factory=dict)
    """The verdict on every relation some learning step observes, kept or not."""


def calibrate(
    runs: Sequence[str | Path],
    config_path: str | Path,
    out: str | Path,
    clean: str | None = None,
    false_alarm: float = DEFAULT_FALSE_ALARM,
    force: bool = False,
    progress: bool = False,
    overrides: Sequence[str] = (),
    lag_reference: str = "gyro",
    drop_unsupported: bool = True,
) -> CalibrationResult:
    """Learn the observers of ``config_path`` from ``runs`` (module
    docstring) and write the calibrated config to ``out`` (a new file, an
    earlier calibrate result, or any file with ``force``). ``clean``:
    ``START:END`` seconds of every run declared clean; None learns from
    whole runs with robust statistics. ``lag_reference``: the stream the
    others' time offsets are measured against. ``drop_unsupported``: leave
    out the relations the data do not support (:mod:`slam.commands.calibrate.support`)."""
    if not runs:
        raise GslamError("gslam calibrate: no run given")
    if not MIN_FALSE_ALARM <= false_alarm <= MAX_FALSE_ALARM:
        raise GslamError(f"--false-alarm {false_alarm:g}: expected a share of steps from {MIN_FALSE_ALARM:g} (one "
                         f"false alarm in a million steps; no run tells a smaller share from none) to "
                         f"{MAX_FALSE_ALARM:g} (half the steps alarmed validates nothing), e.g. 0.005")
    out = check_new_file(out, [*runs, *config_files(config_path)], force, command="calibrate")
    checked = file_state(out)
    check_given_once(overrides)
    runs = distinct_runs(runs)
    stretch = parse_clean(clean)
    config = load_config(config_path, list(overrides))
    vcfg, _ = validation_sections(config)
    if vcfg.model is None:
        raise GslamError(f"{config_path}: validation.model: calibration needs the system model the observers belong to; "
                         f"gslam inspect RUN --config {config_path} --config-out NEW.yaml proposes one")
    loaded: list[CalibrationRun] = [load_run(r, config, vcfg, stretch, progress) for r in runs]
    header = [f"Learnt from {len(runs)} run{'s' if len(runs) > 1 else ''} ({', '.join(Path(r).name for r in runs)}) "
              f"{_learnt_from(stretch)}, starting from {Path(config_path).name}."]
    res = learn(loaded, config, false_alarm, header, lag_reference, drop_unsupported)
    moved = {lag.stream: round(getattr(config.input.time_offsets_s, lag.stream) + lag.offset_s, 3)
             for lag in res.lags if lag.proposed}
    heading = res.heading_offset if res.heading_offset is not None and res.heading_offset.proposed else None
    if moved or heading is not None:
        first = res.lags
        overrides = [*overrides, *(f"input.time_offsets_s.{name}={value}" for name, value in moved.items())]
        if moved:
            header.append("Time offsets found in a first pass and added to input.time_offsets_s, the relations "
                          "learnt with them: " + "; ".join(
                              f"{lag.stream} {lag.offset_s:+.3f} s (RMS of its yaw rate's difference to the "
                              f"{lag.reference}'s {-100 * lag.gain:+.0f} %)" for lag in first if lag.proposed) + ".")
        if heading is not None:
            mounting = round(config.input.compass.mounting_yaw_deg + math.degrees(heading.offset_rad), 2)
            overrides.append(f"input.compass.mounting_yaw_deg={mounting}")
            header.append(f"The compass heading stood {math.degrees(heading.offset_rad):+.1f} deg off the GPS course "
                          f"(circular mean over {heading.steps} steps, mean resultant length {heading.steadiness:.2f}): "
                          f"input.compass.mounting_yaw_deg set to {mounting:g}, the relations learnt with it.")
        config = load_config(config_path, overrides)
        loaded = [load_run(r, config, vcfg, stretch, progress) for r in runs]
        res = learn(loaded, config, false_alarm, header, lag_reference, drop_unsupported)
        res.applied = [lag for lag in first if lag.proposed]
        res.applied_heading = heading
    write_result_file(out, res.text, checked)
    res.out = Path(out)
    return res


def learn(loaded: Sequence[CalibrationRun], config: PipelineConfig, false_alarm: float = DEFAULT_FALSE_ALARM,
          header: Sequence[str] = (), lag_reference: str = "gyro", drop_unsupported: bool = True) -> CalibrationResult:
    """Steps 2-4 of the module docstring on runs already loaded
    (:func:`slam.commands.calibrate.runs.load_run`); the text is not written
    (``out`` is None). ``drop_unsupported``: leave out the relations the
    data do not support (else they are kept, with a warning)."""
    vcfg, _ = validation_sections(config)
    relations = vcfg.observers.relations
    has_mag = vcfg.observers.magnetometer.enabled and any("mag_strength" in r.streams for r in loaded)
    has_field = vcfg.observers.field_gyro.enabled and any("mag_field_change" in r.streams for r in loaded)
    observers = len(relations) + int(has_mag) + int(has_field)
    if observers == 0:
        raise GslamError("nothing can be validated: validation.observers has no relation between two streams and no "
                         "check to learn (gslam inspect RUN --config-out FILE proposes the relations its streams allow, "
                         "or says why there are none)")
    target = false_alarm / observers
    choices = {rel.name: calibrate_relation(loaded, rel, vcfg, target) for rel in relations}
    # A relation no learning step observes is neither supported nor refuted: kept as configured.
    support = {name: judge(loaded, choice, vcfg) for name, choice in choices.items() if choice is not None}
    dropped = {name: s for name, s in support.items() if not s.kept} if drop_unsupported else {}
    for name, verdict in support.items():
        if not verdict.kept:
            log.info("relation %s: %s; %s", name, verdict.reason,
                        "dropped" if name in dropped else "kept (--keep-unsupported)")
    if dropped and len(dropped) == len(relations) and not (has_mag or has_field):
        raise GslamError("nothing can be validated: the data support none of the relations ("
                         + "; ".join(f"{name}: {s.reason}" for name, s in dropped.items()) + ")")
    for name, choice in choices.items():
        if name in dropped:
            continue
        if choice is None:
            log.warning("relation %s: no run has both its streams; kept as configured", name)
        elif not choice.met:
            log.warning("relation %s: no candidate keeps its alarms below %.3f %% of the learning steps",
                        name, 100 * target)
        elif choice.fit.gain < 0 and uses_fitted_gain(choice.relation):
            log.warning("relation %s: %s turns against %s (gain %.2f): check input.frames", name,
                        choice.relation.stream_b, choice.relation.stream_a, choice.fit.gain)
    mag = calibrate_magnetometer(loaded, vcfg.observers.magnetometer, target) if has_mag else None
    field = calibrate_field_gyro(loaded, vcfg.observers.field_gyro, target) if has_field else None
    proposals = propose(loaded, relations, vcfg.model, vcfg, target)
    lags = learn_lags(loaded, lag_reference)
    heading = learn_heading_offset(loaded) if "compass_yaw" in {n for r in loaded for n in r.streams} else None
    for lag in lags:
        log.info("time offset of %s against %s: %+.3f s (RMS of the rate difference %.3g -> %.3g rad/s, "
                 "correlation %.2f, halves %+.3f / %+.3f s)%s", lag.stream, lag.reference, lag.offset_s,
                 lag.rms_before, lag.rms_after, lag.correlation, *lag.halves_s,
                 ": proposed" if lag.proposed else f": not proposed, {lag.why_not()}")
    noise = learn_compass_noise(loaded, vcfg.rate_hz) if config.backend.factors.compass.enabled else None
    header = [*header, *_header(false_alarm, target, observers, vcfg.offline)]
    text = calibrated_config(config, choices, mag, field, proposals, header, target, len(loaded), lags, noise,
                             dropped)
    return CalibrationResult(None, choices, mag, field, proposals, target, text, lags, compass_noise=noise,
                             heading_offset=heading, dropped=dropped, support=support)


def _learnt_from(stretch) -> str:
    if stretch is None:
        return "over whole runs, with robust statistics"
    span = f"{stretch[0]:g}-{stretch[1]:g} s" if stretch[1] != float("inf") else f"{stretch[0]:g} s to the end"
    return f"over {span} of each run, declared clean"


def _header(false_alarm: float, target: float, observers: int, offline: bool) -> list[str]:
    return [
        f"Target: at most {100 * false_alarm:.2f} % of a run's validation steps with a false alarm, "
        f"{100 * target:.3f} % for each of the {observers} observers.",
        "Chosen for the " + ("offline pass (centred windows, alarms dated by their evidence): map with pass offline."
                             if offline else "causal pass (trailing windows): map with pass causal."),
        "Use it on other runs: gslam map RUN --config THIS_FILE --out DIR --gating on",
    ]
