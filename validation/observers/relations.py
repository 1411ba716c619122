"""Relation observers: the paper's Algorithm 3, over a whole run or online.

A *relation* observer compares the qualitative trends (Algorithms 1 and 2,
:mod:`validation.trends`) of two streams that should move together, e.g. the
compass yaw and the integrated gyro yaw, at every validation step.
:func:`observe` is Algorithm 3 (observe): a mismatch counter rises by one on
a step where the two symbols differ and falls by one (not below zero) where
they agree; the observation is ``NO_MATCH`` while the counter exceeds the
relation's threshold ``th`` and ``MATCH`` otherwise. (The listing's
``count = counter + 1`` is read as the counter's own increment.) The
comparison is strict: ``+`` against ``0`` is a mismatch, unless the
relation sets a ``mismatch_margin`` (not the paper's): then only where the
two slopes also part by more than it (:meth:`RelationConfig.compared`). A step where either
stream has no data makes no observation and leaves the counter unchanged;
trends are computed over the steps where the stream has data, so a gap
shortens the next windows as at the start; the relation observes nothing
until both streams have had data for a warm-up time
(``RelationConfig.warmup_s``), since trends from truncated windows are noise.

Online, the counter's threshold is what makes an alarm reliable, at the
price of a delay of ``th`` steps, and its drain keeps the alarm on after
the streams agree again. Offline (:func:`evidence`), each alarm is dated
by its evidence instead. Run forward, an alarm's evidence starts at the
first mismatch of the climb that raised it (the step after the counter was
last 0); run backward over the same steps, the counter climbs from the
alarm's last mismatch. ``NO_MATCH`` holds where both runs' evidence does:
from where the mismatches begin to where they end, without the ``th``
steps of delay or the drain. Unary checks are dated the same way: a
deviation that lasted ``hold_s`` is implausible over its whole run.

:func:`run_observers` runs every observer over a whole run;
:class:`ObserverBank` does the same one step at a time (trailing windows),
with the same results as the batch run with trailing windows. The unary
plausibility checks live in :mod:`validation.observers.checks`, the configuration in
:mod:`validation.observers.config` and the per-step log in
:mod:`validation.observers.log`; :mod:`validation.observers` exports them all.
"""

from __future__ import annotations

import logging
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from validation.diagnosis.model import Observation, Plausibility
from validation.observers.checks import (
    _HOLD_EPS_S,
    UnaryCheck,
    held,
)
from validation.observers.config import (
    RelationConfig,
)
from validation.observers.log import ObserverLog, RelationTrace, UnaryTrace
from validation.observers.quantitative import (
    RunningLevel,
    TravelChange,
    WindowChange,
    offset_test,
    residual_test,
    running_level,
    travel_changes,
    window_changes,
)
from validation.base.geometry import wrap_angle
from validation.observers.sequential import Cusum, cusum
from validation.streams import StepStreams, Stream, is_angular, resample_streams
from validation.trends import Rule, Trend, TrendEstimator, TrendSample, Window, abstract_stream

__all__ = ["MismatchCounter", "ObserverBank", "StepObservations", "evidence", "excise_spans", "mask_runs",
           "observe", "observe_steps", "run_observers"]

logger = logging.getLogger(__name__)
_NO_TREND = TrendSample(0.0, 0.0, 0.0, Trend.ZERO)
"""A stream without a trend at this step (its relation makes no observation)."""


# --- Algorithm 3 ------------------------------------------------------------


def observe(
    symbol_a: np.ndarray,
    symbol_b: np.ndarray,
    threshold: int,
    valid: np.ndarray | None = None,
    max_counter: int | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Algorithm 3 (observe) over whole sequences: ``(counter, no_match)`` per step.

    ``counter_k = counter_{k-1} + 1`` on a mismatch (symbols differ),
    ``max(0, counter_{k-1} - 1)`` on a match, unchanged where ``valid`` is
    false; ``no_match = valid and counter > threshold``. Without a cap the
    recursion is Lindley's, whose closed form ``S_k - min(0, min_{j<=k} S_j)``
    over the running sum ``S`` of the +-1 steps needs no loop.
    """
    a = np.asarray(symbol_a)
    b = np.asarray(symbol_b)
    valid = np.ones(len(a), dtype=bool) if valid is None else np.asarray(valid, dtype=bool)
    step = np.where(valid, np.where(a != b, 1, -1), 0).astype(np.int64)
    if max_counter is None:
        s = np.cumsum(step)
        counter = s - np.minimum.accumulate(np.minimum(s, 0)) if len(s) else s
    else:
        # Reflected at both ends: no simple closed form, and one pass is cheap.
        counts = []
        c = 0
        for x in step.tolist():
            c += x
            if c < 0:
                c = 0
            elif c > max_counter:
                c = max_counter
            counts.append(c)
        counter = np.array(counts, dtype=np.int64)
    return counter, valid & (counter > threshold)


class MismatchCounter:
    """Algorithm 3 (observe) one step at a time."""

    def __init__(self, threshold: int, max_counter: int | None = None) -> None:
        self.threshold = threshold
        self.max_counter = max_counter
        self.counter = 0

    def update(self, symbol_a: int, symbol_b: int, valid: bool = True) -> Observation | None:
        """Count one step; the observation, or None where there is no data."""
        if not valid:
            return None
        self.counter = self.counter + 1 if symbol_a != symbol_b else max(0, self.counter - 1)
        if self.max_counter is not None:
            self.counter = min(self.counter, self.max_counter)
        return Observation.NO_MATCH if self.counter > self.threshold else Observation.MATCH


def evidence(
    symbol_a: np.ndarray,
    symbol_b: np.ndarray,
    threshold: int,
    valid: np.ndarray,
    max_counter: int | None = None,
) -> np.ndarray:
    """Offline ``NO_MATCH`` mask: every alarm of Algorithm 3 dated by its
    evidence, run forward and backward (module docstring). Steps without
    data stay False."""
    a, b, v = np.asarray(symbol_a), np.asarray(symbol_b), np.asarray(valid, dtype=bool)
    forward = _climbs(a, b, v, *observe(a, b, threshold, v, max_counter))
    ra, rb, rv = a[::-1], b[::-1], v[::-1]
    backward = _climbs(ra, rb, rv, *observe(ra, rb, threshold, rv, max_counter))[::-1]
    return forward & backward


def _climbs(symbol_a: np.ndarray, symbol_b: np.ndarray, valid: np.ndarray, counter: np.ndarray, no_match: np.ndarray) -> np.ndarray:
    """Each alarm from the first mismatch of the climb that raised it to the
    last mismatch before the counter returns to 0."""
    m = len(counter)
    mismatch = valid & (np.asarray(symbol_a) != np.asarray(symbol_b))
    out = np.zeros(m, dtype=bool)
    # Zero-counter steps (valid, counter 0) bound each climb.
    zero = valid & (counter == 0)
    zeros = np.flatnonzero(zero)
    k = 0
    alarm = np.flatnonzero(no_match)
    while k < len(alarm):
        first = alarm[k]
        i = np.searchsorted(zeros, first)  # zeros before the alarm: zeros[:i]
        start = zeros[i - 1] + 1 if i > 0 else 0
        end_zero = zeros[i] if i < len(zeros) else m
        hits = np.flatnonzero(mismatch[start:end_zero])
        if len(hits):
            out[start + hits[0] : start + hits[-1] + 1] = True
        k = np.searchsorted(alarm, end_zero)
    return out & valid


# --- batch ----------------------------------------------------------------------


def _trend_key(relation: RelationConfig, side: int) -> tuple[str, float, float]:
    stream = relation.streams[side]
    return stream, relation.window_s, relation.boundaries[side]


def observe_steps(
    steps: StepStreams,
    relations: Sequence[RelationConfig],
    unary: Sequence[UnaryCheck] = (),
    window: Window = "trailing",
    rule: Rule = "paper",
    offline: bool = False,
    excised: Mapping[str, Sequence[tuple[int, int]]] | None = None,
) -> ObserverLog:
    """Run every observer over streams already resampled onto the steps.

    ``window`` and ``rule`` choose Algorithms 1-2's window and rule;
    ``offline`` dates every alarm by its evidence (:func:`evidence`).
    ``excised`` gives offset relations spans of steps ``(k0, k1)`` whose
    change of the difference is taken out from ``k1`` on
    (:func:`excise_spans`)."""
    m = len(steps.t)
    missing = np.zeros(m, dtype=bool)
    cache: dict[tuple[str, float, float], tuple[np.ndarray, np.ndarray]] = {}

    def symbols(key: tuple[str, float, float]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """A stream's symbols, its slopes (r1) and where it has data."""
        name, window_s, boundary = key
        if name not in steps.values:
            return np.zeros(m, dtype=np.int8), np.zeros(m), missing
        valid = steps.valid[name]
        if key not in cache:
            sym, slope = np.zeros(m, dtype=np.int8), np.zeros(m)
            trend = abstract_stream(
                steps.t[valid], steps.values[name][valid], boundary, window_s, window, rule, steps.angular[name]
            )
            sym[valid], slope[valid] = trend.symbol, trend.r1
            cache[key] = sym, slope
        return *cache[key], valid

    def residual(rel: RelationConfig) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        a, b = rel.streams
        if a not in steps.values or b not in steps.values:
            return np.zeros(m), np.zeros(m, dtype=bool), missing
        if rel.window_travel is not None:
            da, db, ok = travel_changes(steps.t, steps.values[a], steps.values[b], steps.valid[a], steps.valid[b],
                                        rel.window_travel, rel.window_s, window)
            return *residual_test(rel, da, db), ok
        da, ok_a = window_changes(steps.t, steps.values[a], steps.valid[a], rel.window_s, window)
        db, ok_b = window_changes(steps.t, steps.values[b], steps.valid[b], rel.window_s, window)
        z, mismatch = residual_test(rel, da, db)
        return z, mismatch, ok_a & ok_b

    def offset(rel: RelationConfig) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        a, b = rel.streams
        if a not in steps.values or b not in steps.values:
            return np.zeros(m), np.zeros(m, dtype=bool), missing
        valid = steps.valid[a] & steps.valid[b]
        d = np.where(valid, steps.values[b] - rel.gain * steps.values[a], 0.0)
        if excised and rel.name in excised:
            d = excise_spans(d, valid, excised[rel.name])
        if rel.level_window_s is None:  # two absolute streams: the level is 0
            if steps.angular[a] or steps.angular[b]:
                d = wrap_angle(d)
            level = np.zeros(m)
        else:
            level = running_level(steps.t, d, valid, rel.level_window_s, window, rel.k_sigma * rel.sigma_floor,
                                  rel.level_max_rate)
        z, mismatch = offset_test(rel, d, np.where(valid, level, d))
        return np.where(valid, z, 0.0), mismatch & valid, valid

    rel_traces: dict[str, RelationTrace] = {}
    for rel in relations:
        if rel.kind != "trend":
            z, mismatch, valid = offset(rel) if rel.kind == "offset" else residual(rel)
            if rel.kind == "cusum":
                z, mismatch = cusum(z, valid, rel.cusum_drift, rel.k_sigma)
            sym_a, sym_b = mismatch.astype(np.int8), np.zeros(m, dtype=np.int8)
            slope_a = slope_b = None
        else:
            z = None
            sym_a, slope_a, valid_a = symbols(_trend_key(rel, 0))
            sym_b, slope_b, valid_b = symbols(_trend_key(rel, 1))
            valid = held(steps.t, valid_a, rel.warmup) & held(steps.t, valid_b, rel.warmup)
        compared_b = sym_b if slope_a is None else rel.compared(sym_a, sym_b, slope_a, slope_b)
        counter, no_match = observe(sym_a, compared_b, rel.threshold, valid, rel.max_counter)
        if offline:
            no_match = evidence(sym_a, compared_b, rel.threshold, valid, rel.max_counter)
        rel_traces[rel.name] = RelationTrace(rel, sym_a, sym_b, valid, counter, no_match, z, slope_a, slope_b)
        logger.debug("%s: no_match on %d of %d valid steps", rel.name, int(no_match.sum()), int(valid.sum()))

    unary_traces: dict[str, UnaryTrace] = {}
    for check in unary:
        if not all(s in steps.values for s in check.streams):
            valid = missing
            deviant = np.zeros(m, dtype=bool)
        else:
            valid = np.logical_and.reduce([steps.valid[s] for s in check.streams])
            with np.errstate(invalid="ignore"):
                deviant = valid & check.deviant({s: steps.values[s] for s in check.streams})
        implausible = held(steps.t, deviant, check.hold_s)
        if offline:
            implausible = _whole_runs(deviant, implausible)
        unary_traces[check.name] = UnaryTrace(check.name, check.component, valid, deviant, implausible)
    return ObserverLog(steps.t, rel_traces, unary_traces)


def excise_spans(d: np.ndarray, valid: np.ndarray, spans: Sequence[tuple[int, int]]) -> np.ndarray:
    """``d`` with the change over each span ``(k0, k1)`` (step indices, in
    time order) taken out of every step from ``k1`` on: what an integrated
    stream summed while its sensor was faulty. Spans whose ends have no data
    are left alone."""
    d = d.copy()
    for k0, k1 in spans:
        if k1 < len(d) and valid[k0] and valid[k1]:
            d[k1:] = np.where(valid[k1:], d[k1:] - (d[k1] - d[k0]), d[k1:])
    return d


def mask_runs(mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(starts, ends)``: the first step of every run of True in ``mask``
    and the step after its last."""
    d = np.concatenate(([False], np.asarray(mask, dtype=bool), [False]))
    return np.flatnonzero(~d[:-1] & d[1:]), np.flatnonzero(d[:-1] & ~d[1:])


def _whole_runs(deviant: np.ndarray, held_mask: np.ndarray) -> np.ndarray:
    """Every run of ``deviant`` that reaches ``held_mask`` anywhere, whole."""
    out = np.zeros(len(deviant), dtype=bool)
    for a, b in zip(*mask_runs(deviant)):
        if held_mask[a:b].any():
            out[a:b] = True
    return out


def run_observers(
    streams: Mapping[str, Stream],
    relations: Sequence[RelationConfig],
    step_times: np.ndarray,
    unary: Sequence[UnaryCheck] = (),
    max_gap_s: float = 0.5,
    stream_max_gap_s: Mapping[str, float] | None = None,
    window: Window = "trailing",
    rule: Rule = "paper",
    offline: bool = False,
    gap_periods: float | None = None,
) -> ObserverLog:
    """Resample ``streams`` onto ``step_times`` (s) and run every observer;
    the gaps as :func:`validation.streams.resample_streams` judges them."""
    steps = resample_streams(streams, step_times, max_gap_s, stream_max_gap_s, gap_periods)
    return observe_steps(steps, relations, unary, window, rule, offline)


# --- online -----------------------------------------------------------------------


@dataclass(frozen=True)
class StepObservations:
    """What the observers say at one step."""

    t: float
    symbols: dict[str, tuple[Trend, Trend]]
    counters: dict[str, int]
    observations: dict[str, Observation | Plausibility | None]


class ObserverBank:
    """Every observer, one validation step at a time (causal).

    Streams with equal (name, window, boundary) share one trend estimator,
    as in :func:`observe_steps`, whose results this reproduces (without
    ``excised`` spans: those come from the diagnosis of earlier steps, which
    :func:`validation.validator.run_validation` feeds back).
    """

    def __init__(
        self,
        relations: Sequence[RelationConfig],
        unary: Sequence[UnaryCheck] = (),
        angular: Mapping[str, bool] | None = None,
        rule: Rule = "paper",
    ) -> None:
        """``angular`` says which streams are angles (default: the yaw streams)."""
        self.rule = rule
        self.relations = tuple(relations)
        names = {s for r in self.relations for s in r.streams}
        self.angular = dict(angular) if angular is not None else {n: is_angular(n) for n in names}
        self.unary = tuple(unary)
        self._estimators: dict[tuple[str, float, float], TrendEstimator] = {}
        self._counters = {r.name: MismatchCounter(r.threshold, r.max_counter) for r in self.relations}
        self._run_start: dict[str, float | None] = {c.name: None for c in self.unary}
        self._present_since: dict[str, float | None] = {s: None for r in self.relations for s in r.streams}
        self._changes: dict[tuple[str, float], WindowChange] = {}
        self._travels: dict[str, TravelChange] = {}
        self._levels: dict[str, RunningLevel] = {}
        self._last_offset: dict[str, float] = {}
        self._cusums: dict[str, Cusum] = {}

    def _unwrap_offset(self, name: str, d: float) -> float:
        """An angular difference made continuous from step to step."""
        last = self._last_offset.get(name)
        if last is not None:
            d = last + float(np.angle(np.exp(1j * (d - last))))
        self._last_offset[name] = d
        return d

    def update(self, t: float, values: Mapping[str, float | None]) -> StepObservations:
        """Process step ``t`` (s). ``values`` maps a stream to its value at the
        step; a missing, None or NaN value means no data at this step."""

        def present(name: str) -> bool:
            v = values.get(name)
            return v is not None and bool(np.isfinite(v))

        # 1. Trends of every stream with data at this step, and the windowed
        #    changes of the residual relations' streams.
        current: dict[tuple[str, float, float], TrendSample] = {}
        changes: dict[tuple[str, float], float | None] = {}
        for rel in self.relations:
            if rel.kind == "offset":
                continue
            if rel.kind in ("residual", "cusum") and rel.window_travel is not None:
                a, b = rel.streams
                tracker = self._travels.setdefault(rel.name, TravelChange(
                    rel.window_travel, rel.window_s, (self.angular.get(a, False), self.angular.get(b, False))))
                changes[(rel.name, None)] = tracker.update(
                    t, float(values[a]) if present(a) else None, float(values[b]) if present(b) else None)
                continue
            if rel.kind in ("residual", "cusum"):
                for name in rel.streams:
                    key = (name, rel.window_s)
                    if key not in changes:
                        tracker = self._changes.setdefault(
                            key, WindowChange(rel.window_s, self.angular.get(name, False))
                        )
                        changes[key] = tracker.update(t, float(values[name]) if present(name) else None)
                continue
            for side in (0, 1):
                key = _trend_key(rel, side)
                if key in current or not present(key[0]):
                    continue
                est = self._estimators.get(key)
                if est is None:
                    est = self._estimators[key] = TrendEstimator(
                        key[1], key[2], self.angular.get(key[0], False), self.rule
                    )
                current[key] = est.update(t, float(values[key[0]]))

        # 2. Relations (Algorithm 3), once both streams are warm.
        for name, since in self._present_since.items():
            self._present_since[name] = (t if since is None else since) if present(name) else None

        def warm(name: str, warmup_s: float) -> bool:
            since = self._present_since[name]
            return since is not None and t - since >= warmup_s - _HOLD_EPS_S

        symbols, counters, observations = {}, {}, {}
        for rel in self.relations:
            if rel.kind in ("residual", "cusum"):
                if rel.window_travel is not None:
                    da, db = changes[(rel.name, None)] or (None, None)
                else:
                    da, db = (changes[(name, rel.window_s)] for name in rel.streams)
                valid = da is not None and db is not None
                z, mismatch = residual_test(rel, np.array(da), np.array(db)) if valid else (None, False)
                if rel.kind == "cusum":
                    test = self._cusums.setdefault(rel.name, Cusum(rel.cusum_drift, rel.k_sigma))
                    mismatch = test.update(None if z is None else float(z))[1]
                mismatch = bool(mismatch)
                sym = (Trend.PLUS if mismatch else Trend.ZERO, Trend.ZERO)
            elif rel.kind == "offset":
                a, b = rel.streams
                valid = present(a) and present(b)
                angular = self.angular.get(a, False) or self.angular.get(b, False)
                mismatch = False
                if rel.level_window_s is None:  # two absolute streams: the level is 0
                    if valid:
                        d = float(values[b]) - rel.gain * float(values[a])
                        d = float(wrap_angle(d)) if angular else d
                        mismatch = bool(offset_test(rel, np.array(d), np.array(0.0))[1])
                else:
                    tracker = self._levels.setdefault(
                        rel.name, RunningLevel(rel.level_window_s, rel.k_sigma * rel.sigma_floor, rel.level_max_rate)
                    )
                    if valid:
                        d = float(values[b]) - rel.gain * float(values[a])
                        if angular:
                            d = self._unwrap_offset(rel.name, d)
                        mismatch = bool(offset_test(rel, np.array(d), np.array(tracker.update(t, d)))[1])
                    else:
                        tracker.reset()
                        self._last_offset.pop(rel.name, None)
                sym = (Trend.PLUS if mismatch else Trend.ZERO, Trend.ZERO)
            else:
                ka, kb = _trend_key(rel, 0), _trend_key(rel, 1)
                valid = warm(ka[0], rel.warmup) and warm(kb[0], rel.warmup)
                sa, sb = current.get(ka, _NO_TREND), current.get(kb, _NO_TREND)
                sym = (sa.symbol, sb.symbol)
            counter = self._counters[rel.name]
            compared = sym[1] if rel.kind != "trend" else rel.compared(sa.symbol, sb.symbol, sa.r1, sb.r1)
            observations[rel.name] = counter.update(int(sym[0]), int(compared), valid)
            symbols[rel.name] = sym
            counters[rel.name] = counter.counter

        # 3. Unary checks with their hold time.
        for check in self.unary:
            if not all(present(s) for s in check.streams):
                self._run_start[check.name] = None
                observations[check.name] = None
                continue
            if bool(check.deviant({s: float(values[s]) for s in check.streams})):
                start = self._run_start[check.name]
                if start is None:
                    start = self._run_start[check.name] = t
                bad = t - start >= check.hold_s - _HOLD_EPS_S
            else:
                self._run_start[check.name] = None
                bad = False
            observations[check.name] = Plausibility.IMPLAUSIBLE if bad else Plausibility.PLAUSIBLE
        return StepObservations(t, symbols, counters, observations)
