"""Sensor validation of one run, step by step: trends -> observers ->
diagnosis -> gating decisions -> per-keyframe factor weights.

Validation steps run at ``validation.rate_hz``. A keyframe's factors take
the strongest decision of the validation steps since the previous keyframe
(a between factor spans that interval; a prior sits at its end), so the
decision for keyframe k uses only data up to its time: causal, as on the
robot. In oracle mode the decisions come from the true fault intervals.
"""

from __future__ import annotations

import csv
import io
import logging
import time
from dataclasses import dataclass, field

import numpy as np

from slam.recording import Recording, Trajectory
from validation.config import GatingConfig, ValidationConfig
from validation.diagnosis import Diagnoser, DiagnosisResult
from validation.gating import FactorGate, Gate, oracle_decisions
from validation.metrics import validation_metrics
from validation.observers import ObserverLog, observe, unary_checks
from validation.streams import fixed_rate_steps, validation_streams

log = logging.getLogger(__name__)


@dataclass
class ValidationOutcome:
    """Everything validation decided, per validation step, and the weights
    per keyframe and factor type (sigma multipliers; ``inf`` excludes).
    ``extra_columns``: more per-step columns for the log (the loop
    observer's, validation.loops)."""

    step_t: np.ndarray
    observer_log: ObserverLog | None
    results: list[DiagnosisResult] | None
    decisions: list[dict[str, FactorGate]]
    weights: dict[str, np.ndarray]
    metrics: dict
    time_s: float
    sm_poses: Trajectory | None = None
    extra_columns: dict[str, list] = field(default_factory=dict)

    def csv_text(self) -> str:
        """The per-step log: trends, counters, observations, diagnoses, decisions."""
        cols: dict[str, np.ndarray | list] = {"t": np.round(self.step_t, 4)}
        if self.observer_log is not None:
            for name, values in self.observer_log.columns().items():
                if name != "t":
                    cols[name] = values.astype(int) if values.dtype == bool else values
        if self.results is not None:
            cols["consistent"] = [int(r.consistent) for r in self.results]
            cols["diagnoses"] = [_format_diagnoses(r) for r in self.results]
        factors = sorted(self.decisions[0]) if self.decisions else []
        for f in factors:
            cols[f"gate.{f}"] = [d[f].action.value for d in self.decisions]
        cols.update(self.extra_columns)
        out = io.StringIO()
        writer = csv.writer(out, lineterminator="\n")
        writer.writerow(cols)
        writer.writerows(zip(*cols.values()))
        return out.getvalue()


def _format_diagnoses(result: DiagnosisResult) -> str:
    if not result.consistent:
        return "none"
    return " | ".join("{" + ",".join(sorted(d)) + "}" for d in result.diagnoses)


def _step_times(keyframe_t: np.ndarray, rate_hz: float) -> np.ndarray:
    return fixed_rate_steps(float(keyframe_t[0]), float(keyframe_t[-1]), rate_hz)


def step_scales(step_t: np.ndarray, decisions: list[dict[str, FactorGate]], lookback_s: float) -> dict[str, np.ndarray]:
    """Sigma scale per factor type and validation step, with every gating
    decision also applied to the ``lookback_s`` before it."""
    factors = sorted(decisions[0]) if decisions else []
    scales = {}
    for f in factors:
        scale = np.array([d[f].sigma_scale for d in decisions])
        if lookback_s > 0:
            back = scale.copy()
            # Closed at the left: steps are sums of floats, so allow for round-off.
            first = np.searchsorted(step_t, step_t - lookback_s - 1e-9, side="left")
            for k in np.flatnonzero(scale > 1.0):
                seg = back[first[k] : k]
                np.maximum(seg, scale[k], out=seg)
            scale = back
        scales[f] = scale
    return scales


def keyframe_weights(step_t: np.ndarray, scales: dict[str, np.ndarray], keyframe_t: np.ndarray) -> dict[str, np.ndarray]:
    """Per keyframe, the largest sigma scale of the steps in (t_{k-1}, t_k];
    keyframe 0 takes the last step at or before it."""
    end = np.searchsorted(step_t, keyframe_t, side="right")
    start = np.concatenate([[max(end[0] - 1, 0)], end[:-1]])
    weights = {}
    for f, scale in scales.items():
        w = np.ones(len(keyframe_t))
        for k, (a, b) in enumerate(zip(start, end)):
            if b > a:
                w[k] = scale[a:b].max()
            elif b > 0:
                w[k] = scale[b - 1]
        weights[f] = w
    return weights


def run_validation(
    recording: Recording,
    sm_poses: Trajectory | None,
    keyframe_t: np.ndarray,
    config: ValidationConfig,
    gating: GatingConfig,
) -> ValidationOutcome:
    """Validate one run and decide the weight of every factor per keyframe."""
    start = time.perf_counter()
    step_t = _step_times(keyframe_t, config.rate_hz)
    observer_log, results = None, None
    if config.mode == "oracle":
        decisions = oracle_decisions(gating, step_t, recording.faults)
    else:
        obs_cfg = config.observers
        streams = validation_streams(recording, sm_poses, obs_cfg.gps_speed_window_s)
        checks = unary_checks(obs_cfg, recording.magnetic_reference)
        observer_log = observe(
            streams, obs_cfg.relations, step_t, checks, obs_cfg.max_gap_s, obs_cfg.stream_max_gap_s
        )
        diagnoser = Diagnoser(config.model)
        gate = Gate(gating, config.model)
        results, decisions = [], []
        for k, t in enumerate(step_t):
            result = diagnoser.diagnose(observer_log.observations(k))
            results.append(result)
            decisions.append(gate.step(float(t), result))
    # The oracle knows each onset exactly: no look-back.
    lookback = 0.0 if config.mode == "oracle" else gating.lookback_s
    weights = keyframe_weights(step_t, step_scales(step_t, decisions, lookback), keyframe_t)
    elapsed = time.perf_counter() - start
    metrics = validation_metrics(step_t, results, decisions, gating, recording.faults)
    metrics["validation_time_s"] = round(elapsed, 4)
    excluded = {f: int(np.sum(~np.isfinite(w))) for f, w in weights.items()}
    inflated = {f: int(np.sum(np.isfinite(w) & (w > 1))) for f, w in weights.items()}
    metrics["keyframes_excluded"] = excluded
    metrics["keyframes_inflated"] = inflated
    log.info("validation (%s): %d steps in %.3f s; excluded keyframes %s", config.mode, len(step_t), elapsed, excluded)
    return ValidationOutcome(step_t, observer_log, results, decisions, weights, metrics, elapsed, sm_poses)
