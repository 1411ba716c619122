"""Whether the data support a relation: do its two streams move together?

A relation proposed from physics (:mod:`validation.proposal`) may not hold
on a given robot: streams that never move together (an odometry that is not
the robot's, a heading that is not the robot's), a quantity the run never
exercises (a robot that hardly turns while learning), too little time with
both streams, or a pair turning opposite ways (frames to fix). Such a
relation observes nothing useful and costs false alarms, so calibration
drops it and writes why (:func:`judge`). A relation is kept when:

1. both streams have data together on at least ``MIN_OVERLAP`` of the
   learning steps;
2. they are associated, by the measure that fits the pair:

   - two streams that sum increments (headings, travel; one of them may be
     an absolute heading): the correlation of their changes over the
     relation's window, which must be at least ``MIN_ASSOCIATION``, with
     the largest tenth of stream a's changes at least ``MIN_MOTION`` times
     the residual's noise (there is motion to compare);
   - two instantaneous streams (speeds): the correlation of their values,
     or, where they hardly vary (a robot at a steady speed), the median of
     their difference against the median of their size, at most
     ``MAX_LEVEL_DIFFERENCE``;
   - two absolute headings (a compass and the GPS course): the mean
     resultant length of their difference, ``|mean(exp(i (b - a)))|``
     (1: a steady offset, 0: unrelated);
   - two sideways travels (none on wheels or tracks: both stay flat): the
     smallest sideways change the observer sees must stay below
     ``LATERAL_SHARE`` of the forward travel over the window, or it sees
     no slide short of the whole motion;

   a negative association (the pair turns opposite ways) is dropped too,
   with a pointer to ``input.frames``;
3. wherever stream a moves enough for the gain to be fitted (more than
   ``MIN_MOTION`` times the residual's noise, :mod:`slam.commands.calibrate.fit`)
   and the observer uses that gain (not an offset observer of two
   absolute streams, which keeps its configured gain and is judged by the
   mean resultant length above), the changes themselves carry evidence: the gain at least ``MIN_GAIN``
   and the correlation of the changes at least ``MIN_ASSOCIATION``. Both
   streams of a relation measure one physical quantity (a turn, a travel,
   a speed), so the gain is 1 up to the sensors' scale errors; the largest
   of a working pair is a skid-steer robot's wheel odometry against its
   gyro, up to about twice (or half: which stream is a) the true turn
   (a Husky's wheel-separation multiplier is 1.875). A gain below a
   quarter is no scale error but a stream that does not follow the other:
   a GPS speed or course whose changes over the window are noise the
   other never sees. A correlation below 0.5 explains less than a quarter
   of b's changes (r^2 < 0.25): an observer on them would compare noise;
4. a boundary and ``th`` meet the false-alarm target
   (:func:`slam.commands.calibrate.select.calibrate_relation`).

The thresholds were set on the calibration runs of the shipped data
(the Husky bag's first 180 s, the CARMEN tuning logs, simulated
``telemax_lab_clean`` seeds 1-3), where every physical relation passes
with a margin and streams of different robots do not.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from slam.commands.calibrate.fit import MIN_MOTION, RateFit, changes
from slam.commands.calibrate.runs import CalibrationRun
from slam.commands.calibrate.select import Choice
from validation.config import ValidationConfig
from validation.observers.config import RelationConfig
from validation.streams import is_angular, is_integrated
from validation.streams.names import split_source_stream

MIN_OVERLAP = 0.1
MIN_ASSOCIATION = 0.5
MIN_GAIN = 0.25
MAX_LEVEL_DIFFERENCE = 0.25
LATERAL_SHARE = 0.5


@dataclass(frozen=True)
class Support:
    """The verdict on one relation: ``kept``, the measure and its value,
    and the reason in words when it is dropped."""

    kept: bool
    measure: str
    value: float
    reason: str = ""


def _overlap(runs: Sequence[CalibrationRun], a: str, b: str) -> float:
    both = total = 0
    for run in runs:
        total += int(run.clean.sum())
        if a in run.steps.valid and b in run.steps.valid:
            both += int((run.steps.valid[a] & run.steps.valid[b] & run.clean).sum())
    return both / total if total else 0.0


def _pairs(runs: Sequence[CalibrationRun], a: str, b: str, inliers: Sequence[np.ndarray]):
    xs, ys = [], []
    for run, good in zip(runs, inliers):
        if a not in run.streams or b not in run.streams:
            continue
        s = run.steps
        keep = s.valid[a] & s.valid[b] & good
        xs.append(s.values[a][keep])
        ys.append(s.values[b][keep])
    return (np.concatenate(xs), np.concatenate(ys)) if xs else (np.zeros(0), np.zeros(0))


def _correlation(x: np.ndarray, y: np.ndarray) -> float:
    if len(x) < 3 or np.std(x) == 0 or np.std(y) == 0:
        return 0.0
    return float(np.corrcoef(x, y)[0, 1])


def _motion(runs: Sequence[CalibrationRun], name: str, window_s: float, vcfg: ValidationConfig,
            inliers: Sequence[np.ndarray]) -> float:
    """The 90th percentile of |change| of ``name`` over the window on the
    inlier steps: how far it moves when it moves (a robot that mostly
    drives straight still turns)."""
    out = []
    for run, good in zip(runs, inliers):
        if name in run.streams:
            d, ok = changes(run, name, window_s, vcfg.window)
            out.append(np.abs(d[ok & good]))
    moved = np.concatenate(out) if out else np.zeros(0)
    return float(np.percentile(moved, 90)) if len(moved) else 0.0


def _forward_travel(runs: Sequence[CalibrationRun], lateral: str, window_s: float, vcfg: ValidationConfig,
                    inliers: Sequence[np.ndarray]) -> float:
    """The median forward travel (m) over the window of the source of
    ``lateral``, over the steps where it moves."""
    split = split_source_stream(lateral)
    forward = f"{split[0]}_forward" if split is not None else ""
    out = []
    for run, good in zip(runs, inliers):
        if forward not in run.streams:
            continue
        d, ok = changes(run, forward, window_s, vcfg.window)
        moving = ok & good & (np.abs(d) > 0.0)
        out.append(np.abs(d[moving]))
    travel = np.concatenate(out) if out else np.zeros(0)
    return float(np.median(travel)) if len(travel) else 0.0


def judge(runs: Sequence[CalibrationRun], choice: Choice, vcfg: ValidationConfig) -> Support:
    """The verdict of the module docstring on a calibrated relation."""
    rel, fit = choice.relation, choice.fit
    a, b = rel.streams
    overlap = _overlap(runs, a, b)
    if overlap < MIN_OVERLAP:
        return Support(False, "overlap", overlap, f"{a} and {b} have data together on {100 * overlap:.0f} % of the "
                       f"learning steps (at least {100 * MIN_OVERLAP:.0f} % needed)")
    lateral = all((split_source_stream(s) or ("", ""))[1] == "lateral" for s in (a, b))
    if lateral:
        travel = _forward_travel(runs, a, rel.window_s, vcfg, fit.inliers)
        share = choice.visible / travel if travel > 0 else np.inf
        if not share < LATERAL_SHARE:
            return Support(False, "sideways band / forward travel", share,
                           f"the smallest sideways change it sees ({choice.visible:.3g} m over {rel.window_s:g} s) is "
                           f"{share:.2g} of the forward travel over that time: it sees no slide short of the motion")
        support = Support(True, "sideways band / forward travel", share)
    elif is_angular(a) and is_angular(b) and not (is_integrated(a) or is_integrated(b)):
        x, y = _pairs(runs, a, b, fit.inliers)
        r = float(np.abs(np.mean(np.exp(1j * (y - x))))) if len(x) else 0.0
        if r < MIN_ASSOCIATION:
            return Support(False, "mean resultant length", r, f"{b} minus {a} keeps no steady offset (mean resultant "
                           f"length {r:.2f}, at least {MIN_ASSOCIATION:g} needed): the headings do not move together")
        support = Support(True, "mean resultant length", r)
    elif is_integrated(a) or is_integrated(b):
        motion = _motion(runs, a, rel.window_s, vcfg, fit.inliers) / fit.noise
        if motion < MIN_MOTION:
            return Support(False, "motion / noise", motion,
                           f"{a} hardly moves on the learning steps (the largest tenth of its changes over "
                           f"{rel.window_s:g} s reach {motion:.2g} x the residual's noise, at least {MIN_MOTION:g} "
                           "needed): nothing to compare")
        support = _associated(fit.corr, "correlation of the changes", a, b, rel.window_s)
    else:
        x, y = _pairs(runs, a, b, fit.inliers)
        level = float(np.median(np.abs(y - x)) / max(np.median(np.maximum(np.abs(x), np.abs(y))), 1e-12)) \
            if len(x) else np.inf
        support = _associated(_correlation(x, y), "correlation of the values", a, b, None)
        if not support.kept and support.value > -MIN_ASSOCIATION and level <= MAX_LEVEL_DIFFERENCE:
            support = Support(True, "level difference", level)
        elif not support.kept:
            support = Support(False, support.measure, support.value,
                              f"{support.reason}, and their levels differ by {level:.2g} of their size (at most "
                              f"{MAX_LEVEL_DIFFERENCE:g} where they do not vary together)")
    if support.kept and fit.gain_fitted and uses_fitted_gain(rel):
        support = changes_evidence(fit, rel.window_s) or support
    if support.kept and not choice.met:
        return Support(False, support.measure, support.value,
                       "no boundary and th keep its false alarms below the target on the learning steps")
    return support


def uses_fitted_gain(rel: RelationConfig) -> bool:
    """Whether the calibrated observer of ``rel`` rests on the gain fitted
    to the changes: every one but an offset observer of two absolute
    streams (a level of 0), whose gain stays as configured
    (:func:`slam.commands.calibrate.select.calibrate_relation`)."""
    return not (rel.kind == "offset" and rel.level_window_s is None)


def changes_evidence(fit: RateFit, window_s: float) -> Support | None:
    """Step 3 of the module docstring: the verdict where the changes carry
    no evidence, else None."""
    a, b, over = fit.a, fit.b, f"over {window_s:g} s"
    if fit.gain <= -MIN_GAIN:
        return Support(False, "gain", fit.gain, f"{b} turns against {a} (gain {fit.gain:.2f} {over}): check "
                       "input.frames (yaw_sign) of one of them")
    if fit.gain < MIN_GAIN:
        return Support(False, "gain", fit.gain, f"{b} does not follow {a}'s changes {over} (gain {fit.gain:.2g}, at "
                       f"least {MIN_GAIN:g} needed: two measures of one motion differ by a scale factor, not by "
                       "nothing)")
    if fit.corr < MIN_ASSOCIATION:
        return Support(False, "correlation of the changes", fit.corr,
                       f"the changes of {a} and {b} {over} hardly correlate ({fit.corr:.2f}, at least "
                       f"{MIN_ASSOCIATION:g} needed): {a} explains {100 * max(fit.corr, 0) ** 2:.0f} % of {b}'s")
    return None


def _associated(r: float, measure: str, a: str, b: str, window_s: float | None) -> Support:
    over = f" over {window_s:g} s" if window_s is not None else ""
    if r <= -MIN_ASSOCIATION:
        return Support(False, measure, r, f"{a} and {b} move opposite ways (correlation {r:.2f}{over}): check "
                       "input.frames (yaw_sign) of one of them")
    if r < MIN_ASSOCIATION:
        return Support(False, measure, r, f"{a} and {b} do not move together (correlation {r:.2f}{over}, at least "
                       f"{MIN_ASSOCIATION:g} needed)")
    return Support(True, measure, r)
