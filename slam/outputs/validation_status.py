"""The validator's decisions at each validation step as diagnostic statuses,
the vocabulary of ROS's ``diagnostic_msgs`` (and of Foxglove's diagnostics
panel): a name, a level (OK, WARN, ERROR, STALE), a message and key-value
pairs. :mod:`slam.outputs.run_mcap` writes them as ``/validation``.

Per step, in this order:

* ``diagnosis``: the minimal diagnoses, as in ``validation.csv``; ERROR when
  they blame a component, WARN when no diagnosis is consistent.
* ``component/NAME`` for every component of the model: ERROR where every
  minimal diagnosis holds it abnormal, WARN where some do, OK where none
  does (WARN "no diagnosis" where none is consistent).
* ``observer/NAME`` for every relation observer (Algorithm 3): OK on
  ``match``, WARN on ``no_match``, STALE where a stream had no data; the
  pair it compares as a value. ``check/NAME`` for every unary check: OK
  plausible, WARN implausible, STALE without data.
* ``gate/FACTOR`` for every factor type: each degree of freedom's gating
  decision (include, inflate, exclude) as a value; the level of the
  strongest (OK, WARN, ERROR).

The steps of a run show a few dozen distinct sets of statuses: each set is
built once (:attr:`StepStatuses.patterns`) and every step points at its own
(:attr:`StepStatuses.index`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from enum import IntEnum
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:  # the statuses' types load without the validator (slam.outputs.result_writer's child)
    from validation.diagnosis.reiter import DiagnosisResult
    from validation.validator import ValidationOutcome


class Level(IntEnum):
    """``diagnostic_msgs/DiagnosticStatus`` levels."""

    OK = 0
    WARN = 1
    ERROR = 2
    STALE = 3


@dataclass(frozen=True)
class Status:
    """One ``diagnostic_msgs/DiagnosticStatus``."""

    name: str
    level: Level
    message: str
    values: tuple[tuple[str, str], ...] = ()


@dataclass(frozen=True)
class StepStatuses:
    """Per validation step ``t`` (s, recording time), the index into the
    distinct sets of statuses ``patterns``."""

    t: np.ndarray
    patterns: list[tuple[Status, ...]]
    index: np.ndarray


_OBSERVATION = ((Level.STALE, "no data"), (Level.OK, "match"), (Level.WARN, "no_match"))
_PLAUSIBILITY = ((Level.STALE, "no data"), (Level.OK, "plausible"), (Level.WARN, "implausible"))
_ACTIONS = ("include", "inflate", "exclude")


def step_statuses(outcome: ValidationOutcome, components: Sequence[str]) -> StepStatuses:
    """The statuses of every step of ``outcome`` (see the module docstring);
    ``components``: the model's, in its order."""
    # 1. One code per step and column: the diagnosis result, each observer's
    #    observation, each factor's decision per degree of freedom.
    n = len(outcome.step_t)
    columns: list[np.ndarray] = []
    results: list = []
    if outcome.results is not None:  # steps of one observation pattern share a result
        ids: dict[int, int] = {}
        columns.append(np.array([ids.setdefault(id(r), len(ids)) for r in outcome.results], dtype=np.int64))
        results = list({id(r): r for r in outcome.results}.values())
    log = outcome.observer_log
    observers = list(log.relations.values()) if log is not None else []
    checks = list(log.unary.values()) if log is not None else []
    columns += [np.where(o.valid, np.where(o.no_match, 2, 1), 0) for o in observers]
    columns += [np.where(c.valid, np.where(c.implausible, 2, 1), 0) for c in checks]
    factors = sorted(outcome.step_scales)
    for f in factors:
        scale = outcome.step_scales[f]
        columns += list(np.where(~np.isfinite(scale), 2, np.where(scale > 1.0, 1, 0)).T)
    if not columns:
        return StepStatuses(outcome.step_t, [()], np.zeros(n, dtype=np.intp))
    table = np.stack(columns, axis=1).astype(np.int64)
    unique, index = np.unique(table, axis=0, return_inverse=True)

    # 2. The statuses of each distinct row.
    patterns = []
    for row in unique.tolist():
        at = 0
        statuses: list[Status] = []
        if outcome.results is not None:
            statuses += _diagnosis(results[row[0]], components)
            at = 1
        for o in observers:
            level, message = _OBSERVATION[row[at]]
            a, b = o.relation.components
            statuses.append(Status(f"observer/{o.relation.name}", level, message, (("relation", f"{a} ~ {b}"),)))
            at += 1
        for c in checks:
            level, message = _PLAUSIBILITY[row[at]]
            statuses.append(Status(f"check/{c.name}", level, message, (("component", c.component),)))
            at += 1
        for f in factors:
            dofs = outcome.factor_dofs[f]
            codes = row[at : at + len(dofs)]
            at += len(dofs)
            values = tuple((d, _ACTIONS[c]) for d, c in zip(dofs, codes))
            message = ", ".join(f"{d} {a}" for d, a in values)
            statuses.append(Status(f"gate/{f}", Level(max(codes)), message, values))
        patterns.append(tuple(statuses))
    return StepStatuses(outcome.step_t, patterns, index.reshape(-1))


def _diagnosis(result: DiagnosisResult, components: Sequence[str]) -> list[Status]:
    """The ``diagnosis`` status and one per component."""
    from validation.validator import format_diagnoses

    text = format_diagnoses(result)
    if not result.consistent:
        return [Status("diagnosis", Level.WARN, "no consistent diagnosis")] + [
            Status(f"component/{c}", Level.WARN, "no diagnosis") for c in components
        ]
    blamed = [d for d in result.diagnoses if d]
    out = [Status("diagnosis", Level.ERROR if blamed else Level.OK, text)]
    for c in components:
        held = sum(c in d for d in result.diagnoses)
        if held and held == len(result.diagnoses):
            out.append(Status(f"component/{c}", Level.ERROR, "abnormal"))
        elif held:
            out.append(Status(f"component/{c}", Level.WARN, f"abnormal in {held} of {len(result.diagnoses)} diagnoses"))
        else:
            out.append(Status(f"component/{c}", Level.OK, "ok"))
    return out
