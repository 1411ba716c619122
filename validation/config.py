"""The ``validation`` and ``gating`` sections of a pipeline config.

``validation.mode`` decides how factors are gated:

* ``off``: no validation; every factor enters with its configured noise.
* ``on``: sensor validation gates the factors, offline or causal as
  ``validation.pass`` says (below; offline by default).
* ``oracle``: the tight oracle, from ground truth: every degree of freedom
  of every measurement whose error exceeds ``oracle_k_sigma`` times its
  sigma is excluded, all others kept. The bound validation aims at.
* ``interval_oracle``: gating from the true fault intervals of each
  component (the simulator's labels): a component's factors are gated over
  its whole fault interval, right or wrong.

``validation.pass`` decides how ``on`` runs:

* ``offline`` (a recorded run): trend windows centred on each step, every
  alarm dated by its evidence, and a recheck that keeps the blamed
  measurements that agree with the other sensors (``gating.keep_k_sigma``);
* ``causal``: as it would run on the robot, from past data only: trailing
  windows, the counters' delay, hold-off and look-back.

``validation.model`` is the logical system model (a mapping, or a path to
a YAML file relative to the config file that names it; the loader inlines
it, so the ``config.yaml`` written beside a result is self-contained).
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any, Literal, Mapping

from pydantic import ConfigDict, Field, field_validator

from validation.diagnosis.model import SystemModel
from validation.gating import GatingConfig, check_components
from validation.observers.config import ObserversConfig, observers_config
from validation.trends import Window
from validation.base import bounds
from validation.base.modes import GatingMode
from validation.base.yamlio import StrictFrozen, load_yaml, validate_mapping, yaml_kind

Pass = Literal["offline", "causal"]


class ValidationConfig(StrictFrozen):
    """``rate_hz``: validation steps per second; observers' thresholds are
    counted in these steps."""

    model_config = ConfigDict(populate_by_name=True)

    mode: GatingMode = GatingMode.OFF
    pass_: Pass = Field("offline", alias="pass")
    rate_hz: bounds.Rate_hz = Field(10.0, gt=0.0)
    oracle_k_sigma: Annotated[float, bounds.ORACLE_K_SIGMA] = Field(3.0, gt=0.0)
    model: SystemModel | None = None
    observers: ObserversConfig = ObserversConfig()

    @field_validator("mode", mode="before")
    @classmethod
    def _yaml_booleans(cls, value: Any) -> Any:
        # YAML 1.1 reads a bare on/off as a boolean.
        return {True: "on", False: "off"}.get(value, value) if isinstance(value, bool) else value

    @property
    def offline(self) -> bool:
        return self.pass_ == "offline"

    @property
    def window(self) -> Window:
        """The trend window: the observers' own, else the pass's."""
        if self.observers.window is not None:
            return self.observers.window
        return "centred" if self.offline else "trailing"


def inline_model(section: dict[str, Any], base_dir: Path) -> Path | None:
    """Replace a ``model: path`` entry by the YAML it names (in place);
    the file read, or None if the model was no path."""
    model = section.get("model")
    if not isinstance(model, str):
        return None
    path = Path(model)
    if not path.is_absolute():
        path = base_dir / path
    section["model"] = load_yaml(path)
    return path


def parse_sections(validation: Mapping[str, Any], gating: Mapping[str, Any]) -> tuple[ValidationConfig, GatingConfig]:
    """Validate both sections; one-line ValidationError naming the key."""
    data = dict(validation)
    observers = data.pop("observers", {})
    if not isinstance(observers, Mapping):  # null too: it is not "every default"
        from validation.base.errors import ValidationError

        raise ValidationError(f"validation.observers: expected a mapping of the observers' settings, got "
                              f"{yaml_kind(observers)}")
    observers = observers_config(observers, "validation.observers", section=True)
    cfg = validate_mapping(ValidationConfig, data, "validation", section=True)
    cfg = cfg.model_copy(update={"observers": observers})
    gate = GatingConfig.from_mapping(dict(gating), "gating", section=True)
    from validation.base.errors import ValidationError

    if cfg.mode.needs_model and cfg.model is None:
        raise ValidationError("validation.model: a system model is needed when validation.mode is on or interval_oracle")
    if not cfg.offline and cfg.observers.window == "centred":
        raise ValidationError(
            "validation.observers.window: centred windows need the samples after each step; "
            "validation.pass causal needs trailing (or null)"
        )
    _check_names(cfg, gate)
    return cfg, gate


def _check_names(cfg: ValidationConfig, gate: GatingConfig) -> None:
    """Every observer must be a relation or check of the model, and every
    gated component one of its components."""
    from validation.base.errors import ValidationError

    if cfg.model is None:
        return
    model = cfg.model
    for rel in cfg.observers.relations:
        if rel.name not in model.relations:
            raise ValidationError(f"validation.observers: relation '{rel.name}' is not in the model's relations")
        if set(rel.components) != set(model.relations[rel.name]):
            raise ValidationError(
                f"validation.observers: relation '{rel.name}' relates {sorted(rel.components)}, "
                f"the model says {sorted(model.relations[rel.name])}"
            )
    obs = cfg.observers
    for check in (obs.magnetometer, obs.field_gyro, obs.gps, obs.scan_ceiling):
        if check.enabled and check.name not in model.unary_checks:
            raise ValidationError(f"validation.observers: check '{check.name}' is not in the model's unary_checks")
        if check.enabled and model.unary_checks[check.name] != check.component:
            raise ValidationError(f"validation.observers: check '{check.name}' tests {check.component}, "
                                  f"the model says {model.unary_checks[check.name]}")
    check_components(gate, model)
