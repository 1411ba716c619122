"""LOOP as a component of the diagnosis, and the oracle for loops.

**LOOP in the diagnosis.** With validation on, each validation step gets a
unary observation ``loop_consistency`` of component LOOP: implausible when a
loop found in the step was rejected by the observer, plausible when its
loops were kept. The model's diagnosis and the gate (hold-off included) turn
that into a decision for the ``loop`` factors of each step: loops of a step
where LOOP is excluded are rejected as ``gated``. LOOP has no relation to
another component, so its diagnosis composes with the sensors' (a product of
independent parts) and is run on its own. In oracle mode a loop is kept when
it agrees with ground truth.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from validation.loops.constraint import LoopConstraint
from validation.loops.observer import LoopObservation, LoopVerdict, count_reasons, position_only

LOOP_COMPONENT = "LOOP"
LOOP_CHECK = "loop_consistency"


@dataclass
class LoopGating:
    """Per validation step: the LOOP observation, its diagnosis and the
    ``loop`` factors' decision, and the loops found in the step (for the
    log)."""

    observations: list[str]
    diagnoses: list[str]
    decisions: list[str]
    step_loops: list[str]

    def columns(self) -> dict[str, list]:
        return {
            LOOP_CHECK: self.observations,
            "loop_diagnosis": self.diagnoses,
            "gate.loop": self.decisions,
            "loops": self.step_loops,
        }


def check_model(model) -> None:
    """Loops under validation need LOOP and its check in the model."""
    from validation.base.errors import ValidationError

    if model is None or LOOP_COMPONENT not in model.components or model.unary_checks.get(LOOP_CHECK) != LOOP_COMPONENT:
        raise ValidationError(
            f"validation.model: loop closing with validation on needs a component {LOOP_COMPONENT} "
            f"and a unary check '{LOOP_CHECK}: {LOOP_COMPONENT}'"
        )
    for name, pair in model.relations.items():
        if LOOP_COMPONENT in pair:
            raise ValidationError(f"validation.model: relation '{name}': {LOOP_COMPONENT} takes no relations, only its check")


def _step_of(step_t: np.ndarray, t: np.ndarray) -> np.ndarray:
    """The validation step (t_{k-1}, t_k] each time falls in."""
    return np.clip(np.searchsorted(step_t, t, side="left"), 0, len(step_t) - 1)


def gate_loops(
    obs: LoopObservation, step_t: np.ndarray, keyframe_t: np.ndarray, model, gating, offline: bool = False
) -> LoopGating:
    """Diagnose LOOP per validation step from the observer's verdicts and
    gate the loops (see the module docstring); updates ``obs`` in place.
    ``offline``: each step's own diagnosis decides, without hold-off."""
    from validation.diagnosis.reiter import Diagnoser
    from validation.gating import Gate, GatingAction, GatingConfig, action_scale, suspicion
    from validation.diagnosis.model import Plausibility

    check_model(model)
    steps = _step_of(step_t, keyframe_t[[v.loop.j for v in obs.verdicts]]) if obs.verdicts else np.zeros(0, int)
    by_step: dict[int, list[LoopVerdict]] = {}
    for k, v in zip(steps, obs.verdicts):
        by_step.setdefault(int(k), []).append(v)
    loop_gating = GatingConfig.model_validate(
        {**gating.model_dump(mode="json"), "factors": {"loop": [LOOP_COMPONENT]}}
    )
    gate = Gate(loop_gating, model)
    diagnoser = Diagnoser(model)
    out = LoopGating([], [], [], [])
    for k, t in enumerate(step_t):
        here = by_step.get(k, [])
        value = None
        if here:
            value = Plausibility.IMPLAUSIBLE if any(not v.accepted for v in here) else Plausibility.PLAUSIBLE
        result = diagnoser.diagnose({LOOP_CHECK: value})
        if offline:
            actions = suspicion(loop_gating, result) if result.consistent else {}
        else:
            actions = gate.step(float(t), result)
        action = actions.get(LOOP_COMPONENT, GatingAction.INCLUDE)
        for v in here:
            if v.accepted and action is GatingAction.EXCLUDE:
                v.accepted, v.reason = False, "gated"
            elif v.accepted and action is GatingAction.INFLATE:
                obs.inflation[v.loop.id] = action_scale(loop_gating, action)
        out.observations.append("" if value is None else value.value)
        out.diagnoses.append(" | ".join("{" + ",".join(sorted(d)) + "}" for d in result.diagnoses) if result.consistent else "none")
        out.decisions.append(action.value)
        out.step_loops.append(" ".join(f"{v.loop.id}:{'accepted' if v.accepted else 'rejected(' + v.reason + ')'}" for v in here))
    diagnoser.close()
    obs.counts = count_reasons(obs.verdicts)
    return out


def oracle_loops(obs: LoopObservation, truth: np.ndarray, max_trans_m: float, max_yaw_rad: float) -> None:
    """Keep exactly the loops that agree with ground truth (``truth``: the
    true keyframe poses (K, 3)), within ``max_trans_m`` and ``max_yaw_rad``
    (position only for a position-only loop); updates ``obs`` in place."""
    for v in obs.verdicts:
        v.accepted, v.reason = loop_is_true(v.loop, truth, max_trans_m, max_yaw_rad), ""
        if not v.accepted:
            v.reason = "oracle"
    obs.counts = count_reasons(obs.verdicts)


def loop_is_true(loop: LoopConstraint, truth: np.ndarray, max_trans_m: float, max_yaw_rad: float) -> bool:
    """Whether ``loop`` agrees with the true keyframe poses (K, 3): within
    ``max_trans_m`` and ``max_yaw_rad`` in the directions it pins
    (:func:`pinned_error`); a position-only loop, whose stated
    sigma is usually larger, within three of its sigmas (at least
    ``max_trans_m``)."""
    from validation.base.geometry import between

    if position_only(loop):
        sigma = 1.0 / np.sqrt(max(loop.information[0, 0], 1e-12))
        limit = max(max_trans_m, 3.0 * sigma)
        return bool(np.hypot(*(truth[loop.i, :2] - truth[loop.j, :2])) <= limit)
    err = pinned_error(loop.information, between(between(truth[loop.i], truth[loop.j]), loop.delta))
    return bool(np.hypot(err[0], err[1]) <= max_trans_m and abs(err[2]) <= max_yaw_rad)


def pinned_error(information: np.ndarray, error: np.ndarray) -> np.ndarray:
    """``error`` (3,) without its components along the directions
    ``information`` (3, 3) gives no weight (a corridor's axis that a scan
    match leaves free): a loop claims nothing there."""
    values, vectors = np.linalg.eigh(0.5 * (information + information.T))
    free = vectors[:, values <= 1e-9 * max(values.max(), 1e-300)]
    return error - free @ (free.T @ error)
