"""The logical system model SD of the consistency-based diagnosis, read from YAML.

A model names the diagnosable *components* (a sensor's modalities, as in
the paper's Table 1: ``ODO_DIST``, ``ODO_YAW``, ``IMU_GYRO``, ``IMU_YAW``,
``SM_DIST``, ``SM_LAT``, ``SM_YAW``, ``GPS``), the *relations* whose observers
compare the streams of two components, unary *plausibility checks* of one
component, and optional rules. Its meaning, in Reiter's terms:

* ``¬AB(S) -> ok(S)`` for every component S;
* ``relation(Si, Sj) ∧ ok(Si) ∧ ok(Sj) -> match(Si, Sj)``; an observation
  ``no_match`` is ``¬match``, so ``match ∧ no_match -> ⊥``;
* ``ok(S) -> plausible(S)`` for a unary check; ``implausible ∧ plausible -> ⊥``;
* fault propagation ``ok(S1) <-> ok(S2)``: both are faulty or neither is;
* a sensor with several modalities (``sensors``: e.g. ``SM`` with
  ``SM_DIST``, ``SM_LAT``, ``SM_YAW``) propagates its own fault to all of
  them: ``¬AB(M) ∧ ¬AB(S) -> ok(M)`` for each modality M of sensor S. A
  modality can fail alone (a scan matcher in a corridor loses its distance
  and keeps its heading), or the whole sensor with one fault (a scan
  matcher in an open yard loses everything), which is then one fault, not
  three;
* an observer that may raise a false alarm (``false_alarm``: the
  probability that a relation says no_match, or a unary check implausible,
  of healthy components) is a retractable assumption TRUST:
  ``ok(Si) ∧ ok(Sj) ∧ TRUST(relation) -> match(Si, Sj)`` and
  ``ok(S) ∧ TRUST(check) -> plausible(S)``. Its verdict is then evidence
  the diagnosis weighs rather than a threshold that blames on its own:
  alone, it is explained more cheaply as a false alarm than as a fault
  rarer than that; beside other evidence against the same component it
  makes that component the more probable culprit;
* failure masking on a relation, ``match(S1, S2) ∧ CORR(match(S1, S2)) ->
  ok(S1) ∧ ok(S2)``: a match is taken as evidence that both are healthy. With
  ``corr: false`` the assumption CORR cannot be retracted, so a match always
  implies both ok (which can leave no diagnosis at all); with ``corr: true``
  a diagnosis may retract it, i.e. declare the match coincidental.

Example (``configs/validation/telemax_model.yaml`` is the shipped one)::

    components: [IMU_GYRO, IMU_YAW, SM_YAW, SM_DIST]
    relations:
      yaw_gyro_sm: [IMU_GYRO, SM_YAW]
    unary_checks:
      mag_plausible: IMU_YAW
    fault_propagation: [[SM_YAW, SM_DIST]]
    failure_masking:
      - {relation: yaw_gyro_sm, corr: true, masking_prob: 0.05}
    priors: {SM_YAW: 0.05}
"""

from __future__ import annotations

from enum import Enum
from pathlib import Path

from pydantic import Field, field_validator, model_validator

from validation.base.yamlio import StrictFrozen, load_yaml, validate_mapping

DEFAULT_PRIOR = 0.01
MIN_PROBABILITY = 1e-9
"""The least prior or false-alarm rate a model may give: once in a billion
steps is never, and the products of smaller ones underflow."""
"""Fault probability of a component the model gives no prior for."""


class Observation(Enum):
    """The outcome of an observer comparing the streams of a relation."""

    MATCH = "match"
    NO_MATCH = "no_match"


class Plausibility(Enum):
    """The outcome of a unary plausibility check of one component."""

    PLAUSIBLE = "plausible"
    IMPLAUSIBLE = "implausible"


class MaskingRule(StrictFrozen):
    """No failure masking on ``relation``: its match implies both components ok.

    ``corr``: the implication holds under the retractable assumption
    CORR(match); ``masking_prob`` is the prior probability that a match of
    this relation is coincidental (used only to rank diagnoses).
    """

    relation: str
    corr: bool = True
    masking_prob: float = Field(DEFAULT_PRIOR, gt=0.0, lt=1.0)


class SystemModel(StrictFrozen):
    """The system description SD; see the module docstring for its logic."""

    components: tuple[str, ...] = Field(min_length=1)
    sensors: dict[str, tuple[str, ...]] = Field(default_factory=dict)
    relations: dict[str, tuple[str, str]] = Field(default_factory=dict)
    unary_checks: dict[str, str] = Field(default_factory=dict)
    fault_propagation: tuple[tuple[str, str], ...] = ()
    failure_masking: tuple[MaskingRule, ...] = ()
    false_alarm: dict[str, float] = Field(default_factory=dict)
    priors: dict[str, float] = Field(default_factory=dict)

    @field_validator("components")
    @classmethod
    def _unique_components(cls, value: tuple[str, ...]) -> tuple[str, ...]:
        dupes = sorted({c for c in value if value.count(c) > 1})
        if dupes:
            raise ValueError(f"duplicate component {dupes[0]!r}")
        return value

    @field_validator("priors")
    @classmethod
    def _probabilities(cls, value: dict[str, float]) -> dict[str, float]:
        for name, p in value.items():
            if not MIN_PROBABILITY <= p < 1.0:
                raise ValueError(f"prior of {name!r} must be in [{MIN_PROBABILITY:g}, 1), got {p:g}")
        return value

    @model_validator(mode="after")
    def _references(self) -> "SystemModel":
        known = set(self.components)

        def check(where: str, names: tuple[str, ...]) -> None:
            for n in names:
                if n not in known:
                    raise ValueError(f"{where}: unknown component {n!r}")

        for name, pair in self.relations.items():
            check(f"relations.{name}", pair)
            if pair[0] == pair[1]:
                raise ValueError(f"relations.{name}: a relation needs two different components")
        for name, comp in self.unary_checks.items():
            check(f"unary_checks.{name}", (comp,))
            if name in self.relations:
                raise ValueError(f"unary_checks.{name}: name already used by a relation")
        for i, pair in enumerate(self.fault_propagation):
            check(f"fault_propagation.{i}", pair)
            if pair[0] == pair[1]:
                raise ValueError(f"fault_propagation.{i}: a rule needs two different components, not {pair[0]!r} twice")
        owner: dict[str, str] = {}
        for sensor, parts in self.sensors.items():
            check("sensors", (sensor, *parts))
            for part in parts:
                if part == sensor or part in self.sensors:
                    raise ValueError(f"sensors.{sensor}: {part!r} cannot be a modality of a sensor")
                if part in owner:
                    raise ValueError(f"sensors.{sensor}: {part!r} is already a modality of {owner[part]!r}")
                owner[part] = sensor
        seen: set[str] = set()
        for i, rule in enumerate(self.failure_masking):
            if rule.relation not in self.relations:
                raise ValueError(f"failure_masking.{i}: unknown relation {rule.relation!r}")
            if rule.relation in seen:
                raise ValueError(f"failure_masking.{i}: relation {rule.relation!r} listed twice")
            seen.add(rule.relation)
        check("priors", tuple(self.priors))
        for name, p in self.false_alarm.items():
            if name not in self.relations and name not in self.unary_checks:
                raise ValueError(f"false_alarm: {name!r} is not a relation or unary check")
            if not MIN_PROBABILITY <= p < 1.0:
                raise ValueError(f"false_alarm.{name} must be in [{MIN_PROBABILITY:g}, 1), got {p:g}")
        return self

    def prior(self, component: str) -> float:
        """Prior fault probability of ``component`` (``DEFAULT_PRIOR`` if unset)."""
        return self.priors.get(component, DEFAULT_PRIOR)

    def modalities(self, component: str) -> tuple[str, ...]:
        """What a fault of ``component`` stands for: a sensor's modalities,
        or the component itself."""
        return self.sensors.get(component, (component,))

    def sensor_of(self, component: str) -> str | None:
        """The sensor a modality belongs to, if any."""
        return next((s for s, parts in self.sensors.items() if component in parts), None)

    @property
    def observables(self) -> tuple[str, ...]:
        """Names an observation may refer to: relations, then unary checks."""
        return tuple(self.relations) + tuple(self.unary_checks)


def load_model(path: str | Path) -> SystemModel:
    """Read a :class:`SystemModel` from a YAML file."""
    return validate_mapping(SystemModel, load_yaml(path), str(path))
