"""Per-step gating decisions: which measurements enter the graph, and how noisy.

From the diagnosis of a step every component gets an action:

* the empty diagnosis: every component is included;
* one minimal diagnosis: its components are excluded or inflated (``single``);
* several (ambiguity): ``inflate_all`` / ``exclude_all`` components of any
  diagnosis, or treat the ``most_probable`` one (first in the ranking) as the
  single diagnosis;
* no diagnosis at all (the observations contradict SD): the ``no_diagnosis``
  fallback, logged once per episode of such steps.

Each degree of freedom of each factor type depends on components
(``factors``: e.g. scan matching's ``x`` on ``SM_DIST``, its ``yaw`` on
``SM_YAW``) and takes the strongest action among them (EXCLUDE > INFLATE >
INCLUDE): an inflated degree of freedom's sigma is multiplied by
``inflation``, an excluded one's scale is ``inf``.

Offline (:func:`offline_actions`) a step's actions are its diagnosis', no
more: the observers date each alarm by its evidence. Causal (:class:`Gate`)
a suspected component comes back (INCLUDE) only after ``holdoff_s`` seconds
of continuous non-suspicion, so a flickering observer does not toggle a
sensor in and out of the graph, and ``lookback_s`` also gates the factors
of the seconds before a decision.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Mapping, Sequence
from enum import Enum
from typing import TYPE_CHECKING, Annotated, Any

import numpy as np
from pydantic import Field, field_validator

from validation.base import bounds
from validation.diagnosis.model import SystemModel
from validation.base.errors import ValidationError
from validation.base.yamlio import StrictFrozen, validate_mapping

if TYPE_CHECKING:  # the solver behind the diagnosis loads once there is one to make
    from validation.diagnosis.reiter import DiagnosisResult

log = logging.getLogger(__name__)

ALL_DOFS = "*"
"""Key of ``GatingConfig.factors`` entries that apply to every degree of freedom."""


class GatingAction(Enum):
    """What happens to a factor at one step, weakest to strongest."""

    INCLUDE = "include"
    INFLATE = "inflate"
    EXCLUDE = "exclude"


_STRENGTH = {GatingAction.INCLUDE: 0, GatingAction.INFLATE: 1, GatingAction.EXCLUDE: 2}

Actions = dict[str, GatingAction]
"""The actions of one step: component -> action (absent: INCLUDE)."""


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


def _default_factors() -> dict[str, dict[str, list[str]]]:
    return {
        "odometry": {"x": ["ODO_DIST", "ODO"], "y": ["ODO_DIST", "ODO"], "yaw": ["ODO_YAW", "ODO"]},
        "gyro": {"yaw": ["IMU_GYRO"]},
        "compass": {"yaw": ["IMU_YAW"]},
        "scan_matching": {"x": ["SM_DIST", "SM"], "y": ["SM_LAT", "SM"], "yaw": ["SM_YAW", "SM"]},
        "gps": {"x": ["GPS"], "y": ["GPS"]},
    }


class GatingConfig(StrictFrozen):
    """The ``gating`` section of a pipeline config.

    ``factors``: per factor type, the components each degree of freedom
    depends on (``x`` along the keyframe's heading, ``y`` to its left,
    ``yaw``); a plain list applies to every degree of freedom.

    ``ambiguous`` defaults to ``most_probable``: with the shipped model a
    failed scan matcher also admits the unlikely multiple fault of all its
    partners as a second minimal diagnosis, and inflating every sensor would
    throw away the dead reckoning that should take over.

    Causal validation only: ``holdoff_s`` and ``lookback_s``. When a factor is
    gated, its factors of the preceding ``lookback_s`` are gated too: the
    observers need a window and a counter to see a fault, so the factors of
    those seconds were measured while the sensor was already failing (on the
    robot, iSAM2 removes them when the decision is made,
    ``removeFactorIndices``). 0 is the paper's behaviour.

    Offline validation only, the recheck (null ``keep_k_sigma``: none,
    every blamed measurement stays gated). A blamed measurement of the
    ``recheck_factors`` types (absolute ones: compass headings, GPS fixes)
    whose residual against the estimate of the other sensors is within
    ``keep_k_sigma`` sigmas agrees with them and is kept. Relative
    measurements are not taken back one step at a time: a bias well inside
    one step's noise adds up over many steps. Instead, between factors of the
    ``baseline_factors`` types whose degree of freedom is excluded step by
    step are checked again over ``baseline_m`` of path and kept over that
    baseline where they agree: a scan matcher that is wrong step by step but
    right over metres still contributes.

    ``inflate``: components a diagnosis inflates whatever ``single`` says.
    A fault of degree (a slipping wheel still says the robot moved, by too
    much) leaves a measurement worth keeping at a wider sigma, where
    leaving it out would leave the graph to a weaker witness.
    """


    single: SinglePolicy = SinglePolicy.EXCLUDE
    ambiguous: AmbiguousPolicy = AmbiguousPolicy.MOST_PROBABLE
    no_diagnosis: NoDiagnosisPolicy = NoDiagnosisPolicy.KEEP_PREVIOUS
    inflation: Annotated[float, bounds.INFLATION] = Field(10.0, ge=1.0)
    holdoff_s: Annotated[float, bounds.HOLD_S] = Field(2.0, ge=0.0)
    lookback_s: Annotated[float, bounds.SPAN_S] = Field(0.0, ge=0.0)
    keep_k_sigma: Annotated[float | None, bounds.K_SIGMA] = Field(3.0, gt=0.0)
    recheck_factors: tuple[str, ...] = ("compass", "gps")
    recheck_window_s: Annotated[float, bounds.SPAN_S] = Field(5.0, ge=0.0)
    baseline_factors: tuple[str, ...] = ("scan_matching",)
    baseline_m: Annotated[float, bounds.PATH_DELTA_M] = Field(5.0, gt=0.0)
    factors: dict[str, dict[str, list[str]]] = Field(default_factory=_default_factors)
    inflate: tuple[str, ...] = ()

    @field_validator("factors", mode="before")
    @classmethod
    def _per_dof(cls, value: Any) -> Any:
        if not isinstance(value, Mapping):
            return value
        out = {}
        for name, comps in value.items():
            if isinstance(comps, (list, tuple)):
                comps = {ALL_DOFS: list(comps)}
            if isinstance(comps, Mapping):
                for dof, names in comps.items():
                    if not names:
                        raise ValueError(f"{name}.{dof}: needs at least one component")
            out[name] = comps
        return out

    @classmethod
    def from_mapping(cls, data: Mapping[str, Any], source: str = "gating", section: bool = False) -> "GatingConfig":
        """Validate a config section; errors are one-line :class:`ValidationError` s
        (``section``: see :func:`~validation.base.yamlio.validate_mapping`)."""
        return validate_mapping(cls, dict(data), source, section)

    def components_of(self, factor: str, dof: str) -> list[str]:
        """The components one degree of freedom of a factor type depends on."""
        entry = self.factors.get(factor, {})
        return entry.get(dof, entry.get(ALL_DOFS, []))

    def gated_components(self) -> set[str]:
        """Every component some factor depends on."""
        return {c for entry in self.factors.values() for comps in entry.values() for c in comps}


def check_components(config: GatingConfig, model: SystemModel) -> None:
    """Every component named in ``config.factors`` must be the model's, and
    a sensor must gate the factors its modalities gate: a blame of the whole
    sensor that gated nothing would be a validator doing nothing."""
    for factor, entry in config.factors.items():
        for dof, comps in entry.items():
            for c in comps:
                if c not in model.components:
                    where = factor if dof == ALL_DOFS else f"{factor}.{dof}"
                    raise ValidationError(f"gating.factors.{where}: unknown component {c!r}")
    for c in config.inflate:
        if c not in model.components:
            raise ValidationError(f"gating.inflate: unknown component {c!r}")
    gated = config.gated_components()
    for sensor, parts in model.sensors.items():
        used = [p for p in parts if p in gated]
        if used and sensor not in gated:
            raise ValidationError(
                f"gating.factors: the model's sensor {sensor!r} gates no factor, though its modality {used[0]!r} "
                f"does; a blame of {sensor} would change nothing: name it beside {used[0]}"
            )


def action_scale(config: GatingConfig, action: GatingAction) -> float:
    """The sigma multiplier of an action: 1, ``inflation`` or ``inf``."""
    if action is GatingAction.INFLATE:
        return config.inflation
    return math.inf if action is GatingAction.EXCLUDE else 1.0


def strongest(actions: Sequence[GatingAction]) -> GatingAction:
    return max(actions, key=_STRENGTH.__getitem__, default=GatingAction.INCLUDE)


def factor_scales(
    config: GatingConfig, actions: Actions, factor_dofs: Mapping[str, Sequence[str]]
) -> dict[str, np.ndarray]:
    """Sigma multipliers (dofs,) per factor type from the components' actions."""
    out = {}
    for factor, dofs in factor_dofs.items():
        out[factor] = np.array([
            action_scale(config, strongest([actions.get(c, GatingAction.INCLUDE) for c in config.components_of(factor, d)]))
            for d in dofs
        ])
    return out


def suspicion(config: GatingConfig, result: DiagnosisResult) -> Actions:
    """Actions for the suspected components of a consistent diagnosis result."""
    single = GatingAction(config.single.value)
    if not result.diagnoses:
        raise ValueError("suspicion() needs a consistent diagnosis result")
    if len(result.diagnoses) == 1 or config.ambiguous is AmbiguousPolicy.MOST_PROBABLE:
        actions = {c: single for c in result.diagnoses[0]}
    else:
        action = GatingAction.EXCLUDE if config.ambiguous is AmbiguousPolicy.EXCLUDE_ALL else GatingAction.INFLATE
        actions = {c: action for d in result.diagnoses for c in d}
    for c in config.inflate:
        if c in actions:
            actions[c] = GatingAction.INFLATE
    return actions


def offline_actions(config: GatingConfig, results: Sequence[DiagnosisResult]) -> list[Actions]:
    """Offline: each step's actions from its own diagnosis; where no
    diagnosis exists, the ``no_diagnosis`` fallback (``keep_previous`` takes
    the last explained step's)."""
    out: list[Actions] = []
    previous: Actions = {}
    everything = config.gated_components()
    for r in results:
        if r.consistent:
            actions = suspicion(config, r)
        elif config.no_diagnosis is NoDiagnosisPolicy.KEEP_PREVIOUS:
            actions = dict(previous)
        elif config.no_diagnosis is NoDiagnosisPolicy.INFLATE_ALL:
            actions = {c: GatingAction.INFLATE for c in everything}
        else:
            actions = {}
        out.append(actions)
        previous = actions
    return out


class Gate:
    """Causal per-step gating with hold-off; feed steps in time order."""

    def __init__(self, config: GatingConfig, model: SystemModel | None = None) -> None:
        if model is not None:
            check_components(config, model)
        self.config = config
        self._held: Actions = {}  # components not (yet) back in
        self._clean_since: dict[str, float] = {}  # start of their clean stretch, s
        self._previous: Actions = {}
        self._last_t = -math.inf
        self._in_episode = False

    def step(self, t: float, result: DiagnosisResult) -> Actions:
        """Actions for the step at time ``t`` (s, recording time) from its diagnosis."""
        if t < self._last_t:
            raise ValidationError(f"gating: step time {t} s is before the previous step {self._last_t} s")
        self._last_t = t
        if not result.consistent:
            actions = self._no_diagnosis(t, result)
        else:
            if self._in_episode:
                log.info("t=%.3f s: observations are explainable again", t)
                self._in_episode = False
            actions = self._update(t, suspicion(self.config, result))
        self._previous = actions
        return actions

    def _update(self, t: float, suspected: Actions) -> Actions:
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

    def _no_diagnosis(self, t: float, result: DiagnosisResult) -> Actions:
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
        if policy is NoDiagnosisPolicy.INFLATE_ALL:
            return {c: GatingAction.INFLATE for c in self.config.gated_components()}
        return {}


def oracle_actions(
    config: GatingConfig, times: Sequence[float], faults: Mapping[str, Sequence[tuple[float, float]]]
) -> list[Actions]:
    """Actions of a gate that knows the fault intervals: at each time (s) a
    component inside one of its closed fault intervals ``[start, end]`` (s,
    as in ``Recording.faults``) gets the ``single`` action, all others
    INCLUDE; no hold-off."""
    single = GatingAction(config.single.value)
    return [{c: single for c, spans in faults.items() if any(a <= t <= b for a, b in spans)} for t in times]
