"""Per-step gating decisions: which factors enter the graph, and how noisy.

Each factor type depends on components (``factors``: e.g. ``scan_matching ->
[SM]``). From the diagnosis of a step every component gets an action:

* the empty diagnosis: every component is included;
* one minimal diagnosis: its components are excluded or inflated (``single``);
* several (ambiguity): ``inflate_all`` / ``exclude_all`` components of any
  diagnosis, or treat the ``most_probable`` one (first in the ranking) as the
  single diagnosis;
* no diagnosis at all (the observations contradict SD): the ``no_diagnosis``
  fallback, logged once per episode of such steps.

A suspected component comes back (INCLUDE) only after ``holdoff_s`` seconds
of continuous non-suspicion, so a flickering observer does not toggle a
sensor in and out of the graph. A factor takes the strongest action among its
components (EXCLUDE > INFLATE > INCLUDE). An inflated factor's noise sigmas
are multiplied by ``inflation``; an excluded factor's scale is ``inf``.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Mapping, Sequence
from enum import Enum
from typing import Any, NamedTuple

from pydantic import BaseModel, ConfigDict, Field, model_validator

from validation.diagnosis import DiagnosisResult
from validation.errors import ValidationError
from validation.model import SystemModel, validate_mapping

log = logging.getLogger(__name__)


class GatingAction(Enum):
    """What happens to a factor at one step, weakest to strongest."""

    INCLUDE = "include"
    INFLATE = "inflate"
    EXCLUDE = "exclude"


_STRENGTH = {GatingAction.INCLUDE: 0, GatingAction.INFLATE: 1, GatingAction.EXCLUDE: 2}


class SinglePolicy(Enum):
    EXCLUDE = "exclude"
    INFLATE = "inflate"


class AmbiguousPolicy(Enum):
    INFLATE_ALL = "inflate_all"
    EXCLUDE_ALL = "exclude_all"
    MOST_PROBABLE = "most_probable"


class NoDiagnosisPolicy(Enum):
    KEEP_PREVIOUS = "keep_previous"
    INCLUDE_ALL = "include_all"
    INFLATE_ALL = "inflate_all"


def _default_factors() -> dict[str, list[str]]:
    return {
        "odometry": ["ODO"],
        "gyro": ["IMU_GYRO"],
        "compass": ["IMU_YAW"],
        "scan_matching": ["SM"],
        "gps": ["GPS"],
    }


class GatingConfig(BaseModel):
    """The ``gating`` section of a pipeline config.

    ``ambiguous`` defaults to ``most_probable``: with the shipped model a
    failed scan matcher also admits the unlikely triple fault of all its
    partners as a second minimal diagnosis, and inflating every sensor would
    throw away the dead reckoning that should take over.

    ``lookback_s``: when a factor is gated, its factors of the preceding
    ``lookback_s`` are gated too. The observers need a window and a counter
    to see a fault, so the factors of those seconds were measured while the
    sensor was already failing; on the robot, iSAM2 removes them when the
    decision is made (``removeFactorIndices``). 0 is the paper's behaviour:
    decisions act from their step on.
    """

    model_config = ConfigDict(extra="forbid", frozen=True)

    single: SinglePolicy = SinglePolicy.EXCLUDE
    ambiguous: AmbiguousPolicy = AmbiguousPolicy.MOST_PROBABLE
    no_diagnosis: NoDiagnosisPolicy = NoDiagnosisPolicy.KEEP_PREVIOUS
    inflation: float = Field(10.0, ge=1.0)
    holdoff_s: float = Field(2.0, ge=0.0)
    lookback_s: float = Field(0.0, ge=0.0)
    factors: dict[str, list[str]] = Field(default_factory=_default_factors)

    @model_validator(mode="after")
    def _factors_have_components(self) -> "GatingConfig":
        for name, comps in self.factors.items():
            if not comps:
                raise ValueError(f"factors.{name}: needs at least one component")
        return self

    @classmethod
    def from_mapping(cls, data: Mapping[str, Any], source: str = "gating") -> "GatingConfig":
        """Validate a config section; errors are one-line :class:`ValidationError` s."""
        return validate_mapping(cls, dict(data), source)


class FactorGate(NamedTuple):
    """The decision for one factor: ``sigma_scale`` multiplies its noise sigmas
    (1 when included, ``inflation`` when inflated, ``inf`` when excluded)."""

    action: GatingAction
    sigma_scale: float


def factor_decisions(config: GatingConfig, actions: Mapping[str, GatingAction]) -> dict[str, FactorGate]:
    """Per-factor decisions from per-component actions (missing = INCLUDE)."""
    out = {}
    for factor, comps in config.factors.items():
        action = max((actions.get(c, GatingAction.INCLUDE) for c in comps), key=_STRENGTH.__getitem__)
        out[factor] = FactorGate(action, _scale(config, action))
    return out


def _scale(config: GatingConfig, action: GatingAction) -> float:
    if action is GatingAction.INFLATE:
        return config.inflation
    return math.inf if action is GatingAction.EXCLUDE else 1.0


def suspicion(config: GatingConfig, result: DiagnosisResult) -> dict[str, GatingAction]:
    """Actions for the suspected components of a consistent diagnosis result."""
    single = GatingAction(config.single.value)
    if not result.diagnoses:
        raise ValueError("suspicion() needs a consistent diagnosis result")
    if len(result.diagnoses) == 1 or config.ambiguous is AmbiguousPolicy.MOST_PROBABLE:
        return {c: single for c in result.diagnoses[0]}
    action = GatingAction.EXCLUDE if config.ambiguous is AmbiguousPolicy.EXCLUDE_ALL else GatingAction.INFLATE
    return {c: action for d in result.diagnoses for c in d}


class Gate:
    """Causal per-step gating with hold-off; feed steps in time order."""

    def __init__(self, config: GatingConfig, model: SystemModel | None = None) -> None:
        if model is not None:
            for factor, comps in config.factors.items():
                for c in comps:
                    if c not in model.components:
                        raise ValidationError(f"gating.factors.{factor}: unknown component {c!r}")
        self.config = config
        self._held: dict[str, GatingAction] = {}  # components not (yet) back in
        self._clean_since: dict[str, float] = {}  # start of their clean stretch, s
        self._previous = factor_decisions(config, {})
        self._last_t = -math.inf
        self._in_episode = False

    def step(self, t: float, result: DiagnosisResult) -> dict[str, FactorGate]:
        """Decisions for the step at time ``t`` (s, recording time) from its diagnosis."""
        if t < self._last_t:
            raise ValidationError(f"gating: step time {t} s is before the previous step {self._last_t} s")
        self._last_t = t
        if not result.consistent:
            decisions = self._no_diagnosis(t, result)
        else:
            if self._in_episode:
                log.info("t=%.3f s: observations are explainable again", t)
                self._in_episode = False
            decisions = factor_decisions(self.config, self._update(t, suspicion(self.config, result)))
        self._previous = decisions
        return decisions

    def _update(self, t: float, suspected: dict[str, GatingAction]) -> dict[str, GatingAction]:
        """Apply the hold-off: suspected components are gated now; a held one
        returns once it has been clean for ``holdoff_s``."""
        for c, action in suspected.items():
            self._held[c] = action
            self._clean_since.pop(c, None)
        for c in list(self._held):
            if c in suspected:
                continue
            since = self._clean_since.setdefault(c, t)
            if t - since >= self.config.holdoff_s:
                del self._held[c], self._clean_since[c]
        return dict(self._held)

    def _no_diagnosis(self, t: float, result: DiagnosisResult) -> dict[str, FactorGate]:
        policy = self.config.no_diagnosis
        if not self._in_episode:
            log.warning(
                "t=%.3f s: no diagnosis explains the observations (in conflict: %s); fallback %s",
                t,
                ", ".join(sorted(result.conflicting_observations)) or "?",
                policy.value,
            )
            self._in_episode = True
        # Such a step is no evidence of health: it interrupts every hold-off.
        self._clean_since.clear()
        if policy is NoDiagnosisPolicy.KEEP_PREVIOUS:
            return dict(self._previous)
        action = GatingAction.INFLATE if policy is NoDiagnosisPolicy.INFLATE_ALL else GatingAction.INCLUDE
        return factor_decisions(self.config, {c: action for comps in self.config.factors.values() for c in comps})


def oracle_decisions(
    config: GatingConfig, times: Sequence[float], faults: Mapping[str, Sequence[tuple[float, float]]]
) -> list[dict[str, FactorGate]]:
    """Decisions of a gate that knows the truth: at each time (s) a component
    inside one of its closed fault intervals ``[start, end]`` (s, as in
    ``Recording.faults``) gets the ``single`` action, all others INCLUDE; no
    hold-off."""
    single = GatingAction(config.single.value)
    out = []
    for t in times:
        faulty = {c: single for c, spans in faults.items() if any(a <= t <= b for a, b in spans)}
        out.append(factor_decisions(config, faulty))
    return out
