"""Sensor validation of one run, step by step: trends -> observers ->
diagnosis -> gating actions -> per-keyframe weights of every factor's
degrees of freedom.

Validation steps run at ``validation.rate_hz``. A keyframe's factors take
the strongest decision of the validation steps since the previous keyframe
(a between factor spans that interval; a prior sits at its end). Offline,
the steps' trends use centred windows and the observers date each alarm by
its evidence; causal, the decision for keyframe k uses only data up to its
time, as on the robot. With ``interval_oracle`` the actions come from the
true fault intervals.
"""

from __future__ import annotations

import csv
import dataclasses
import io
import logging
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from validation.base.modes import GatingMode
from validation.config import GatingConfig, ValidationConfig
from validation.diagnosis.model import SystemModel
from validation.diagnosis.reiter import Diagnoser, DiagnosisResult
from validation.gating import Actions, Gate, factor_scales, offline_actions, oracle_actions
from validation.metrics import validation_metrics
from validation.observers import ObserverLog, mask_runs, observe_steps, unary_checks
from validation.observers.checks import MagneticReference, ScanGeometrySeries, scan_streams
from validation.observers.config import RelationConfig, field_gyro_stream, gps_course_limits
from validation.observers.coverage import observer_coverage, require_observations, warn_low_coverage
from validation.streams import (
    PoseSeries, SensorSet, fixed_rate_steps, is_integrated, resample_streams, validation_streams,
)

log = logging.getLogger(__name__)

Interval = tuple[float, float]


@dataclass
class ValidationOutcome:
    """Everything validation decided, per validation step, and the weights
    per keyframe, factor type and degree of freedom (sigma multipliers,
    (K, dofs); ``inf`` excludes). ``extra_columns``: more per-step columns
    for the log (the loop observer's, validation.loops). :attr:`metrics`
    and :meth:`csv_text` are computed when first asked for (a map asks
    while its figures are drawn)."""

    step_t: np.ndarray
    observer_log: ObserverLog | None
    results: list[DiagnosisResult] | None
    actions: list[Actions]
    factor_dofs: dict[str, tuple[str, ...]]
    step_scales: dict[str, np.ndarray]
    weights: dict[str, np.ndarray]
    time_s: float
    faults: dict[str, list[Interval]] | None = None
    sensors: dict = field(default_factory=dict)  # the model's whole-sensor components
    coverage: dict | None = None
    sm_poses: PoseSeries | None = None
    extra_columns: dict[str, list] = field(default_factory=dict)

    @cached_property
    def metrics(self) -> dict:
        """Detection, isolation and coverage figures for ``metrics.json``."""
        metrics = validation_metrics(self.step_t, self.results, self.actions, self.faults, self.sensors)
        if self.coverage is not None:
            metrics["observer_coverage"] = {name: round(c.fraction, 4) for name, c in self.coverage.items()}
        metrics["validation_time_s"] = round(self.time_s, 4)
        metrics["keyframes_excluded"] = {f: int(np.sum(np.all(~np.isfinite(w), axis=1))) for f, w in self.weights.items()}
        metrics["keyframes_gated"] = {f: int(np.sum(np.any(w > 1, axis=1))) for f, w in self.weights.items()}
        return metrics

    def csv_text(self) -> str:
        """The per-step log: trends, counters, observations, diagnoses, decisions."""
        cols: dict[str, np.ndarray | list] = {"t": np.round(self.step_t, 4)}
        if self.observer_log is not None:
            for name, values in self.observer_log.columns().items():
                if name != "t":
                    cols[name] = values.astype(int) if values.dtype == bool else values
        if self.results is not None:
            cols["consistent"] = [int(r.consistent) for r in self.results]
            cols["diagnoses"] = [format_diagnoses(r) for r in self.results]
        for factor in sorted(self.step_scales):
            for i, dof in enumerate(self.factor_dofs[factor]):
                cols[f"gate.{factor}.{dof}"] = _action_names(self.step_scales[factor][:, i])
        cols.update(self.extra_columns)
        out = io.StringIO()
        writer = csv.writer(out, lineterminator="\n")
        writer.writerow(cols)
        # Python's numbers print as numpy's do, several times faster.
        writer.writerows(zip(*(c.tolist() if isinstance(c, np.ndarray) else c for c in cols.values())))
        return out.getvalue()


def _action_names(scales: np.ndarray) -> list[str]:
    """Per sigma scale: exclude (infinite), inflate (> 1) or include."""
    return np.where(~np.isfinite(scales), "exclude", np.where(scales > 1.0, "inflate", "include")).tolist()


def format_diagnoses(result: DiagnosisResult) -> str:
    if not result.consistent:
        return "none"
    return " | ".join("{" + ",".join(sorted(d)) + "}" for d in result.diagnoses)


def step_scales(
    step_t: np.ndarray,
    actions: list[Actions],
    gating: GatingConfig,
    factor_dofs: Mapping[str, Sequence[str]],
    lookback_s: float = 0.0,
) -> dict[str, np.ndarray]:
    """Sigma scale per factor type, validation step and degree of freedom
    (m, dofs), with every gating decision also applied to the ``lookback_s``
    before it."""
    # Few distinct actions recur over a run: compute each set's scales once.
    known: dict[tuple, dict[str, np.ndarray]] = {}
    per_step = []
    for a in actions:
        key = tuple(sorted(a.items()))
        if key not in known:
            known[key] = factor_scales(gating, a, factor_dofs)
        per_step.append(known[key])
    scales = {}
    for factor, dofs in factor_dofs.items():
        scale = np.array([s[factor] for s in per_step]).reshape(len(actions), len(dofs))
        if lookback_s > 0:
            back = scale.copy()
            # Closed at the left: steps are sums of floats, so allow for round-off.
            first = np.searchsorted(step_t, step_t - lookback_s - 1e-9, side="left")
            for k in np.flatnonzero(np.any(scale > 1.0, axis=1)):
                seg = back[first[k] : k]
                np.maximum(seg, scale[k], out=seg)
            scale = back
        scales[factor] = scale
    return scales


def keyframe_weights(step_t: np.ndarray, scales: dict[str, np.ndarray], keyframe_t: np.ndarray) -> dict[str, np.ndarray]:
    """Per keyframe, the largest sigma scale of the steps in (t_{k-1}, t_k],
    per degree of freedom; keyframe 0 takes the last step at or before it."""
    end = np.searchsorted(step_t, keyframe_t, side="right")
    start = np.concatenate([[max(end[0] - 1, 0)], end[:-1]])
    weights = {}
    for f, scale in scales.items():
        w = np.ones((len(keyframe_t), scale.shape[1]))
        for k, (a, b) in enumerate(zip(start, end)):
            if b > a:
                w[k] = scale[a:b].max(axis=0)
            elif b > 0:
                w[k] = scale[b - 1]
        weights[f] = w
    return weights


MAX_EXCISE_PASSES = 4
"""Observer passes that re-read offset relations after their integrated
side's faults (:func:`integrated_fault_spans`)."""


def diagnose_log(diagnoser: Diagnoser, observer_log: ObserverLog) -> list[DiagnosisResult]:
    """Each step's diagnosis (each distinct observation pattern diagnosed once)."""
    patterns, index = observer_log.patterns()
    diagnosed = [diagnoser.diagnose(p) for p in patterns]
    return [diagnosed[i] for i in index]


def integrated_fault_spans(
    relations: Sequence[RelationConfig],
    model: SystemModel,
    step_t: np.ndarray,
    results: Sequence[DiagnosisResult],
    lookback_s: float,
) -> dict[str, list[tuple[int, int]]]:
    """Per offset relation with a level, the spans of steps ``(k0, k1)`` over
    which the sensor of one of its integrated streams was blamed: from
    ``lookback_s`` before the first blamed step to the first step after.
    An integrated stream keeps whatever its sensor summed while faulty; the
    relation takes that change out (:func:`validation.observers.relations.excise_spans`),
    as the gate takes out the sensor's factors, so that an offset left behind
    by a past fault of the integrated side is not blamed on its partner."""
    out: dict[str, list[tuple[int, int]]] = {}
    offsets = [r for r in relations if r.kind == "offset" and r.level_window_s is not None]
    if not offsets:
        return out
    # Steps share a result per observation pattern: each pattern's blame once.
    blame_of: dict[int, frozenset[str]] = {}
    for r in results:
        if id(r) not in blame_of:
            top = r.diagnoses[0] if r.consistent else ()
            blame_of[id(r)] = frozenset(c for s in top for c in (s, *model.modalities(s)))
    blamed_sets = [blame_of[id(r)] for r in results]
    for rel in offsets:
        comps = {c for s, c in zip(rel.streams, rel.components) if is_integrated(s)}
        blamed = np.array([bool(comps & b) for b in blamed_sets])
        if not blamed.any():
            continue
        starts, ends = mask_runs(blamed)
        first = np.searchsorted(step_t, step_t[starts] - lookback_s - 1e-9, side="left")
        spans: list[tuple[int, int]] = []
        for a, b in zip(first.tolist(), ends.tolist()):
            if spans and a <= spans[-1][1]:  # the look-back reaches into the span before: one span
                a = spans.pop()[0]
            spans.append((a, b))
        spans = [(a, b) for a, b in spans if b < len(step_t)]
        if spans:
            out[rel.name] = spans
    return out


def run_validation(
    sensors: SensorSet,
    sm_poses: PoseSeries | None,
    keyframe_t: np.ndarray,
    config: ValidationConfig,
    gating: GatingConfig,
    factor_dofs: Mapping[str, Sequence[str]],
    faults: Mapping[str, Sequence[Interval]] | None = None,
    magnetic_reference: MagneticReference | None = None,
    scan_geometry: ScanGeometrySeries | None = None,
) -> ValidationOutcome:
    """Validate one run and decide the weight of every factor's degrees of
    freedom per keyframe. ``factor_dofs`` names each factor type's degrees of
    freedom in the order of its noise model; ``faults`` are the true fault
    intervals (for ``interval_oracle`` and the metrics); ``scan_geometry``
    the front-end's figures per scan, for the scan check."""
    start = time.perf_counter()
    faults = dict(faults or {})
    step_t = fixed_rate_steps(float(keyframe_t[0]), float(keyframe_t[-1]), config.rate_hz)
    observer_log, results, coverage = None, None, None
    if config.mode is GatingMode.INTERVAL_ORACLE:
        actions = oracle_actions(gating, step_t, faults)
    else:
        obs = config.observers
        window = config.window
        streams = validation_streams(sensors, sm_poses, obs.gps_speed_window_s, window, field_gyro_stream(obs),
                                     gps_course_limits(obs))
        checks = unary_checks(obs, magnetic_reference)
        streams.update(scan_streams(checks, scan_geometry))
        steps = resample_streams(streams, step_t, obs.max_gap_s, obs.stream_max_gap_s, obs.gap_periods)
        observer_log = observe_steps(steps, obs.relations, checks, window, obs.rule, config.offline)
        coverage = observer_coverage(observer_log, steps, streams, obs.relations, {c.name: c.streams for c in checks})
        warn_low_coverage(coverage, obs.min_coverage)
        require_observations(coverage)
        diagnoser = Diagnoser(config.model)
        results = diagnose_log(diagnoser, observer_log)
        # An offset relation against an integrated stream forgets what that
        # stream summed while its sensor was blamed; that can change later
        # blame, so again until the spans settle.
        lookback = gating.lookback_s if not config.offline else 0.0
        excised: dict[str, list[tuple[int, int]]] = {}
        for _ in range(MAX_EXCISE_PASSES):
            spans = integrated_fault_spans(obs.relations, config.model, step_t, results, lookback)
            if spans == excised:
                break
            changed = [r for r in obs.relations if spans.get(r.name) != excised.get(r.name)]
            excised = spans
            again = observe_steps(steps, changed, (), window, obs.rule, config.offline, excised)
            observer_log = dataclasses.replace(observer_log, relations=observer_log.relations | again.relations)
            results = diagnose_log(diagnoser, observer_log)
        if config.offline:
            actions = offline_actions(gating, results)
        else:
            gate = Gate(gating, config.model)
            actions = [gate.step(float(t), r) for t, r in zip(step_t, results)]
    # The oracle knows each onset exactly and offline alarms are dated by
    # their evidence: the look-back is for causal validation only.
    causal = config.mode is GatingMode.ON and not config.offline
    lookback = gating.lookback_s if causal else 0.0
    dofs = {f: tuple(d) for f, d in factor_dofs.items()}
    scales = step_scales(step_t, actions, gating, dofs, lookback)
    weights = keyframe_weights(step_t, scales, keyframe_t)
    elapsed = time.perf_counter() - start
    sensors = config.model.sensors if config.model is not None else {}
    log.info("validation (%s): %d steps in %.3f s; gated keyframes %s", config.mode, len(step_t), elapsed,
             {f: int(np.sum(np.any(w > 1, axis=1))) for f, w in weights.items()})
    return ValidationOutcome(
        step_t, observer_log, results, actions, dofs, scales, weights, elapsed, faults, sensors, coverage, sm_poses
    )
