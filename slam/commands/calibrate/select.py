"""Each observer's parameters from the measured noise and a target
false-alarm rate.

For a relation, the noise it must stand above is measured first
(:mod:`slam.commands.calibrate.fit`): the spread of the two slopes' difference for
a trend relation, of the windowed residual for a residual relation, of
the difference about its running level for an offset relation. The
boundary is then a multiple of that noise (``b = c * noise`` for a trend,
``k_sigma`` for the others) and Algorithm 3's threshold ``th`` a number of
steps; the observer itself (:func:`validation.observers.relations.observe_steps`,
with the pass the config names) runs on the learning steps for each
candidate, smallest multiple first and, for each, smallest ``th`` first.
Each run is judged held out (:func:`held_out`): with the gain, offset and
noise learnt from the other runs (a single run: each half of its learning
steps with those of the other half), so that what is chosen is what holds
on a run it was not learnt from, a gyro's bias of another day included.
The first candidate whose ``NO_MATCH`` steps are at most the target share
of the judged steps, on every run, is taken, with the parameters learnt
from all runs: the smallest error, then the shortest one, the observer can
see at that false-alarm rate. The
unary magnetometer and field-gyro checks get their tolerances from
quantiles of their deviations.

A trend or residual relation tries windows of half, once and twice the
configured ``window_s`` (none shorter than four samples of its sparser
stream, each a whole number of step pairs) and keeps the one whose smallest visible change over a window is
least (``b * w`` for a trend, ``k_sigma * sigma_floor`` for a residual).
An offset relation keeps its window, ``level_window_s`` and
``level_max_rate``: how long a standing offset may last and still be seen,
and how fast the reference may drift, are the user's choice. One with
a level of 0 (``level_window_s`` null: two absolute streams) also keeps
its gain, and its noise is the spread of the difference itself.
``th`` is first sought no longer than the configured one (how long an
error must last to count is the user's choice, and a short one is missed
with a long ``th``), then longer. ``max_counter`` is ``th + 20``.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace

import numpy as np

from slam.commands.calibrate.fit import RateFit, fit_offset, fit_rates, fit_slopes, motion_scale, robust_sd
from slam.commands.calibrate.runs import CalibrationRun
from validation.base.bounds import MAX_SIGMA_REL
from validation.config import ValidationConfig
from validation.observers import evidence, observe, observe_steps
from validation.observers.config import FieldGyroCheckConfig, MagnetometerCheckConfig, RelationConfig
from validation.streams.names import source_stream, split_source_stream

log = logging.getLogger(__name__)

THRESHOLDS = (1, 2, 3, 5, 8, 12, 20, 30)
"""Candidate ``th``, steps."""
MULTIPLES = (3.0, 4.0, 5.0, 6.0, 8.0, 12.0)
"""Candidate boundaries in units of the measured noise."""
CUSUM_LIMITS = (5.0, 10.0, 20.0, 40.0, 80.0, 160.0)
"""Candidate decision limits of a cusum relation, in sds (its sums add up
overlapping windows' residuals, which move together)."""
COUNTER_HEADROOM = 20
TIE = 1.05
"""Windows whose smallest visible change is within this factor count as equal (the shorter wins)."""
RESOLUTION = 0.1
"""The smallest noise a relation is calibrated to, as a share of how far its
stream a moves over the window when it moves (:func:`slam.commands.calibrate.fit.motion_scale`;
a sideways travel: the forward travel): below it, a noise measured on a
quiet recording (a simulated odometry indoors, a gyro whose bias held still)
would give a band that the next run's bias or terrain crosses. Chosen on
telemax_lab, telemax_compass and telemax_lab_clean seeds 1-6 and the Husky
faults of ``python -m scripts.bench proposal --choice`` (0.05 gave
telemax_lab 1.2 x the shipped model's false alarms; 0.1 the same)."""


def sig(x: float, digits: int = 4) -> float:
    """``x`` to ``digits`` significant digits: what the config shows is what ran."""
    return float(f"{x:.{digits}g}")


@dataclass
class Choice:
    """A calibrated relation and what it was chosen from."""

    relation: RelationConfig
    fit: RateFit
    noise: float
    multiple: float
    alarm: float
    visible: float
    met: bool
    offset: tuple[float, float] | None = None
    """An offset relation's ``(median difference, steps)`` its noise was measured over."""
    slope_offset: float = 0.0
    """A trend relation's median slope difference, which its boundary stands above."""
    resolution: bool = False
    """The noise was raised to :data:`RESOLUTION` of the motion."""


@dataclass(frozen=True)
class Fold:
    """One held-out evaluation: the relation's parameters learnt without
    ``run``, judged on its ``judged`` steps."""

    run: CalibrationRun
    make: Callable[[float, int], RelationConfig]
    judged: np.ndarray


def _first_threshold(folds: Sequence[Fold], multiple: float, vcfg: ValidationConfig, target: float,
                     longest: int) -> tuple[int, float] | None:
    """The smallest th up to ``longest`` whose NO_MATCH share of the judged
    steps is at most ``target`` on every fold, and the worst share; None if
    none is."""
    traces = []
    for fold in folds:
        rel = fold.make(multiple, THRESHOLDS[0])
        trace = observe_steps(fold.run.steps, [rel], (), vcfg.window, vcfg.observers.rule, False).relations[rel.name]
        traces.append((*trace.compared(), trace.valid, fold.judged))
    for th in (t for t in THRESHOLDS if t <= longest):
        worst = 0.0
        for a, b, valid, good in traces:
            cap = th + COUNTER_HEADROOM
            no_match = evidence(a, b, th, valid, cap) if vcfg.offline else observe(a, b, th, valid, cap)[1]
            judged = valid & good
            if judged.any():
                worst = max(worst, float(no_match[judged].mean()))
        if worst <= target:
            return th, worst
    return None


def _search(folds: Sequence[Fold], make: Callable[[float, int], RelationConfig], vcfg, target, longest: int,
            multiples: Sequence[float] = MULTIPLES) -> tuple[RelationConfig, float, float, bool]:
    """``(relation, multiple, alarm, met)``: the first multiple and th (no
    longer than ``longest`` steps, then any) that meet ``target`` on every
    fold, with ``make``'s parameters (learnt from every run); the last
    candidate (largest both) if none does."""
    for limit in (longest, THRESHOLDS[-1]):
        for multiple in multiples:
            found = _first_threshold(folds, multiple, vcfg, target, limit)
            if found is not None:
                th, alarm = found
                return make(multiple, th), multiple, alarm, True
    rel = make(multiples[-1], THRESHOLDS[-1])
    return rel, multiples[-1], float("nan"), False


def _updated(rel: RelationConfig, **changes) -> RelationConfig:
    """``rel`` with ``changes``, checked as a config is."""
    return RelationConfig.model_validate({**rel.model_dump(), **changes})


def candidate_windows(runs: Sequence[CalibrationRun], rel: RelationConfig, rate_hz: float) -> list[float]:
    """Half, once and twice ``rel.window_s``, none shorter than four samples
    of the sparser stream, each a whole number of step pairs (a centred
    window reaches the same whole number of steps either side)."""
    if rel.window_travel is not None:  # lengths of travel: no sample period bounds them
        return sorted({round(f * rel.window_travel, 6) for f in (0.5, 1.0, 2.0)})
    period = max((run.steps.period.get(s, 0.0) for run in runs for s in rel.streams if s in run.streams), default=0.0)
    shortest = 4.0 * period if np.isfinite(period) else rel.window_s
    pair = 2.0 / rate_hz
    return sorted({round(max(pair, np.ceil(max(w, shortest) / pair - 1e-9) * pair), 6)
                   for w in (0.5 * rel.window_s, rel.window_s, 2.0 * rel.window_s)})


@dataclass
class _Learnt:
    """A relation's fit on some runs, and the relation it gives for a
    multiple and a th."""

    fit: RateFit
    noise: float
    make: Callable[[float, int], RelationConfig]
    bias: tuple[float, float] | None = None
    slope_offset: float = 0.0
    resolution: bool = False


def _learn(runs: Sequence[CalibrationRun], rel: RelationConfig, vcfg: ValidationConfig, w: float) -> _Learnt | None:
    """The fit of ``rel`` over windows of ``w`` on ``runs``; None when no
    step has both its streams."""
    a, b = rel.streams
    travel = rel.window_travel is not None
    fit = fit_rates(runs, a, b, rel.window_s if travel else w, vcfg.window, vcfg.rate_hz, rel.gain,
                    travel=w if travel else None)
    if fit is None:
        return None
    base = dict(window_travel=w, warmup_s=rel.warmup_s) if travel else dict(window_s=w, warmup_s=None)
    scale_stream = _moving_stream(a)
    if rel.kind == "trend":
        sd, median = fit_slopes(runs, a, b, w, vcfg.window, fit.inliers)
        floor = RESOLUTION * motion_scale(runs, scale_stream, w, vcfg.window, fit.inliers, slope=True)
        noise = max(sd, floor) if sd > 0.0 else 0.0

        def make(m: float, th: int) -> RelationConfig:
            return _updated(rel, **base, boundary=sig(abs(median) + m * noise), boundary_a=None, boundary_b=None,
                            threshold=th, max_counter=th + COUNTER_HEADROOM)

        return _Learnt(fit, noise, make, slope_offset=median, resolution=floor > sd)
    if rel.kind in ("residual", "cusum"):
        moved = w if travel else motion_scale(runs, scale_stream, w, vcfg.window, fit.inliers)
        floor = RESOLUTION * abs(fit.gain) * moved
        noise = max(fit.noise, floor)
        # Streams that do not move together fit a relative sigma of up to
        # 1e9: any change passes at MAX_SIGMA_REL already, so the config
        # holds the bound (the support test then drops the relation).

        def make(m: float, th: int) -> RelationConfig:
            return _updated(rel, **base, gain=sig(fit.gain), rate_offset=0.0 if travel else sig(fit.rate_offset),
                            sigma_floor=sig(noise), sigma_rel=sig(min(fit.sigma_rel, MAX_SIGMA_REL)), k_sigma=m,
                            threshold=th, max_counter=th + COUNTER_HEADROOM)

        return _Learnt(fit, noise, make, resolution=floor > fit.noise)
    # Two absolute streams (a level of 0) keep their gain: a gain fitted to
    # their changes would scale a heading by it.
    gain = rel.gain if rel.level_window_s is None else sig(fit.gain)
    noise, median, count = fit_offset(runs, a, b, gain, rel.level_window_s, vcfg.window, fit.inliers,
                                      rel.level_max_rate)

    def make(m: float, th: int) -> RelationConfig:
        return _updated(rel, gain=gain, sigma_floor=sig(max(noise, 1e-12)), k_sigma=m,
                        threshold=th, max_counter=th + COUNTER_HEADROOM)

    return _Learnt(fit, noise, make, (median, count))


def _moving_stream(name: str) -> str:
    """The stream whose motion sets a relation's resolution: its own, or
    for a sideways travel (none on wheels or tracks) the forward travel of
    the same source."""
    split = split_source_stream(name)
    return source_stream(split[0], "forward") if split is not None and split[1] == "lateral" else name


def held_out(runs: Sequence[CalibrationRun]) -> list[tuple[list[CalibrationRun], int, np.ndarray]]:
    """The folds of the module docstring: ``(learning runs, judged run,
    its judged steps)``. Each run of several is judged by what the others
    teach; a single run's halves (in time) by each other."""
    if len(runs) > 1:
        return [([r for j, r in enumerate(runs) if j != i], i, runs[i].clean) for i in range(len(runs))]
    run = runs[0]
    learning = np.flatnonzero(run.clean)
    if len(learning) < 2:
        return [([run], 0, run.clean)]
    mid = run.steps.t[learning[len(learning) // 2]]
    first = run.clean & (run.steps.t < mid)
    second = run.clean & (run.steps.t >= mid)
    return [([replace(run, clean=second)], 0, first), ([replace(run, clean=first)], 0, second)]


def calibrate_relation(runs: Sequence[CalibrationRun], rel: RelationConfig, vcfg: ValidationConfig,
                       target: float) -> Choice | None:
    """``rel`` with its parameters learnt from ``runs`` (module docstring);
    None when no run has both its streams."""
    best: Choice | None = None
    windows = candidate_windows(runs, rel, vcfg.rate_hz) if rel.kind != "offset" else [rel.window_s]
    folds_of = held_out(runs)
    for w in windows:
        pooled = _learn(runs, rel, vcfg, w)
        if pooled is None:
            return None
        if not pooled.noise > 0.0:  # no step to learn from in this window
            continue
        folds = []
        for learning, judged_run, steps in folds_of:
            own = _learn(learning, rel, vcfg, w)
            make = own.make if own is not None and own.noise > 0.0 else pooled.make
            # A step the pooled fit takes for a fault is not judged.
            folds.append(Fold(runs[judged_run], make, steps & pooled.fit.inliers[judged_run]))
        multiples = CUSUM_LIMITS if rel.kind == "cusum" else MULTIPLES
        chosen, multiple, alarm, met = _search(folds, pooled.make, vcfg, target, max(rel.threshold, 1), multiples)
        # The smallest error seen: over a trend's window, in the stream's own
        # units, or as a share of a window of travel.
        visible = multiple * pooled.noise * (w if rel.kind == "trend" else 1.0 / w if rel.window_travel else 1.0)
        choice = Choice(chosen, pooled.fit, pooled.noise, multiple, alarm, visible, met, pooled.bias,
                        pooled.slope_offset, pooled.resolution)
        if best is None or (met and not best.met) or (met == best.met and visible < best.visible / TIE):
            best = choice
    if best is not None:
        log.info("%s: %s", rel.name, best.relation.model_dump(exclude_none=True))
    return best


@dataclass
class CheckChoice:
    """The magnetometer check's tolerances and the deviations they came from."""

    config: MagnetometerCheckConfig
    strength_T: float
    dip_rad: float
    steps: int
    learnt_reference: bool = False
    """The reference field was learnt from the runs (none was given)."""


def _tolerance(deviation: np.ndarray, share: float, declared: bool) -> float:
    """The ``1 - share`` quantile of one run's ``deviation``; over a whole
    run (not ``declared`` clean), no further than 6 robust sds above its
    median, so faults do not widen it."""
    tol = float(np.percentile(deviation, 100.0 * (1.0 - share)))
    if not declared:
        tol = min(tol, float(np.median(deviation)) + 6.0 * robust_sd(deviation))
    return tol


def _field_reference(runs: Sequence[CalibrationRun]) -> tuple[float, float] | None:
    """``(strength_T, dip_rad)``: the medians of the field's strength and dip
    over the learning steps of every run: the local Earth field where the
    recording gives none (a real bag; a disturbance of a minority of the
    steps does not move a median)."""
    strength, dip = [], []
    for run in runs:
        s = run.steps
        if "mag_strength" not in s.valid or "mag_dip" not in s.valid:
            continue
        ok = s.valid["mag_strength"] & s.valid["mag_dip"] & run.clean
        strength.append(s.values["mag_strength"][ok])
        dip.append(s.values["mag_dip"][ok])
    if not strength or not sum(len(x) for x in strength):
        return None
    return float(np.median(np.concatenate(strength))), float(np.median(np.concatenate(dip)))


def calibrate_magnetometer(runs: Sequence[CalibrationRun], cfg: MagnetometerCheckConfig, target: float) -> CheckChoice | None:
    """Tolerances of field strength and dip at the ``1 - target / 2``
    quantile of their deviations on the learning steps of the worst run
    (:func:`_tolerance`); no hold. The reference field is the config's, else
    the run's (a simulated run's sidecar), else learnt from the runs
    (:func:`_field_reference`, written to the config). None without
    magnetometer data."""
    if not cfg.enabled:
        return None
    learnt = None
    if cfg.strength_T is None and cfg.dip_deg is None and not any(
            c.name == cfg.name for run in runs for c in run.checks):
        learnt = _field_reference(runs)
    worst_b = worst_d = 0.0
    steps = 0
    for run in runs:
        check = next((c for c in run.checks if c.name == cfg.name), None)
        reference = (check.strength_T, check.dip_rad) if check is not None else learnt
        if reference is None or not all(s in run.streams for s in ("mag_strength", "mag_dip")):
            continue
        s = run.steps
        ok = s.valid["mag_strength"] & s.valid["mag_dip"] & run.clean
        if not ok.any():
            continue
        db = np.abs(s.values["mag_strength"][ok] - reference[0])
        dd = np.abs(s.values["mag_dip"][ok] - reference[1])
        tb, td = _tolerance(db, 0.5 * target, run.declared), _tolerance(dd, 0.5 * target, run.declared)
        worst_b, worst_d, steps = max(worst_b, tb), max(worst_d, td), steps + int(ok.sum())
    if not steps:
        return None
    update = {"tolerance_T": sig(max(worst_b, 1e-9), 3), "tolerance_dip_deg": sig(max(np.degrees(worst_d), 1e-3), 3),
              "hold_s": 0.0}
    if learnt is not None:
        update.update(strength_T=sig(learnt[0], 4), dip_deg=sig(float(np.degrees(learnt[1])), 4))
    return CheckChoice(cfg.model_copy(update=update), worst_b, worst_d, steps,
                       learnt_reference=learnt is not None)


@dataclass
class FieldGyroChoice:
    """The field-gyro check's tolerance and the learning steps it came from."""

    config: FieldGyroCheckConfig
    steps: int


def calibrate_field_gyro(runs: Sequence[CalibrationRun], cfg: FieldGyroCheckConfig, target: float) -> FieldGyroChoice | None:
    """The field-gyro check's tolerance at the ``1 - target`` quantile of
    ``mag_field_change`` on the learning steps of the worst run
    (:func:`_tolerance`); its window and smoothing stay as configured (how
    long a disturbance may take to build and still be seen is the user's
    choice); no hold. None when no run has the stream."""
    if not cfg.enabled:
        return None
    worst, steps = 0.0, 0
    for run in runs:
        if "mag_field_change" not in run.steps.values:
            continue
        ok = run.steps.valid["mag_field_change"] & run.clean
        if ok.any():
            worst = max(worst, _tolerance(run.steps.values["mag_field_change"][ok], target, run.declared))
            steps += int(ok.sum())
    if not steps:
        return None
    return FieldGyroChoice(cfg.model_copy(update={"tolerance_T": sig(max(worst, 1e-9), 3), "hold_s": 0.0}), steps)


__all__ = ["Choice", "CheckChoice", "FieldGyroChoice", "calibrate_field_gyro", "calibrate_magnetometer",
           "calibrate_relation", "fit_rates"]
