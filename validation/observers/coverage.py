"""Coverage: on how many validation steps each observer could say anything.

An observer makes no observation at a step where one of its streams has no
data (absent, a gap longer than the stream may be interpolated across, the
warm-up after a gap, a window that does not fit). Validation that observes
nothing gates nothing, and must not pass for validation that found nothing
wrong. So every run reports each observer's *coverage*, the share of the
steps with a valid observation (``metrics.json``: ``observer_coverage``);
an observer below ``observers.min_coverage`` is named in a warning with the
reason, and a run where no observer observes anything at all is an error
(:func:`require_observations`).
"""

from __future__ import annotations

import logging
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from validation.base.errors import ValidationError
from validation.observers.config import RelationConfig
from validation.observers.log import ObserverLog
from validation.streams import StepStreams, Stream

logger = logging.getLogger(__name__)

_SOURCE = {
    "compass": "the run has no compass",
    "mag": "the run has no magnetometer field (a heading from an orientation estimate has none)",
    "gyro": "the run has no gyro",
    "sm": "the run has no scan matching (no laser, or the front-end is off)",
    "odo": "the run has no odometry",
    "gps": "the run has fewer than two GPS fixes",
    "scan": "the run has no laser scans, or the front-end's scan figures were not computed",
}
_WHOLE = 0.95  # a stream with data on this share of the steps needs no explaining


@dataclass(frozen=True)
class Coverage:
    """One observer's share of steps with a valid observation, and why it is
    short of all steps (None when nothing is missing to speak of)."""

    name: str
    fraction: float
    reason: str | None


def stream_reason(name: str, steps: StepStreams, streams: Mapping[str, Stream]) -> str | None:
    """Why ``name`` has no data on some steps; None if it has data on nearly all."""
    if name not in streams:
        return f"stream {name} is absent: {_SOURCE.get(name.split('_')[0], 'the run does not have it')}"
    share = float(np.mean(steps.valid[name])) if len(steps.t) else 0.0
    if share >= _WHOLE:
        return None
    s = streams[name]
    parts = [f"stream {name} has data on {share:.0%} of the steps"]
    gap = steps.max_gap.get(name)
    if gap is not None and len(s.t) > 1:
        long = int(np.sum(np.diff(s.t) > gap))
        if long:
            parts.append(f"{long} gaps longer than the {gap:.3g} s it may be interpolated across "
                         f"(its samples are {steps.period[name]:.3g} s apart)")
    if len(s.t) and len(steps.t) and (s.t[0] > steps.t[0] + 1.0 or s.t[-1] < steps.t[-1] - 1.0):
        parts.append(f"it spans {s.t[0]:.1f}-{s.t[-1]:.1f} s of the steps' {steps.t[0]:.1f}-{steps.t[-1]:.1f} s")
    return ", ".join(parts)


def _relation_reason(rel: RelationConfig, steps: StepStreams, streams: Mapping[str, Stream]) -> str:
    found = [r for r in (stream_reason(s, steps, streams) for s in rel.streams) if r is not None]
    if found:
        return "; ".join(found)
    if rel.kind == "trend":
        return f"the warm-up of {rel.warmup:g} s after each start or gap of its streams"
    if rel.kind in ("residual", "cusum") and rel.window_travel is not None:
        return (f"its window of {rel.window_travel:g} of {rel.stream_a}'s travel within {rel.window_s:g} s: "
                f"the robot stands or moves slower than {rel.window_travel / rel.window_s:.3g} a second, "
                "or its streams have gaps")
    if rel.kind in ("residual", "cusum"):
        return f"its window of {rel.window_s:g} s rarely fits between the gaps of its streams"
    return "its streams rarely have data at the same steps"


def observer_coverage(
    log: ObserverLog,
    steps: StepStreams,
    streams: Mapping[str, Stream],
    relations: Sequence[RelationConfig],
    unary_streams: Mapping[str, Sequence[str]],
) -> dict[str, Coverage]:
    """Coverage of every relation and unary check in ``log``;
    ``unary_streams`` names each check's streams."""
    m = max(len(log.t), 1)
    out: dict[str, Coverage] = {}
    for rel in relations:
        trace = log.relations[rel.name]
        fraction = float(np.sum(trace.valid)) / m
        reason = None if fraction >= _WHOLE else _relation_reason(rel, steps, streams)
        out[rel.name] = Coverage(rel.name, fraction, reason)
    for name, trace in log.unary.items():
        fraction = float(np.sum(trace.valid)) / m
        reason = None
        if fraction < _WHOLE:
            found = [r for r in (stream_reason(s, steps, streams) for s in unary_streams.get(name, ())) if r]
            reason = "; ".join(found) or "its streams rarely have data at the same steps"
        out[name] = Coverage(name, fraction, reason)
    return out


def warn_low_coverage(coverage: Mapping[str, Coverage], min_coverage: float) -> list[str]:
    """Log a warning for every observer below ``min_coverage``; the messages."""
    messages = [
        f"observer {c.name} has a valid observation on {c.fraction:.1%} of the validation steps "
        f"(below {min_coverage:.0%}): {c.reason}"
        for c in coverage.values()
        if c.fraction < min_coverage
    ]
    for text in messages:
        logger.warning("%s", text)
    return messages


def require_observations(coverage: Mapping[str, Coverage]) -> None:
    """A :class:`ValidationError` naming every observer and its reason when
    no observer has a valid observation at any step: gating would silently
    do nothing."""
    if any(c.fraction > 0.0 for c in coverage.values()):
        return
    if not coverage:
        raise ValidationError("validation.mode on: no observer is configured (validation.observers)")
    why = "; ".join(f"{c.name}: {c.reason}" for c in coverage.values())
    raise ValidationError(f"validation.mode on: no observer has a valid observation at any step, so nothing "
                          f"would be validated: {why}")
