"""Observers: does each stream agree with the others, and with physics?

- :mod:`~validation.observers.relations`: relation observers, the paper's
  Algorithm 3 (:func:`observe`) over a whole run (:func:`observe_steps`,
  :func:`run_observers`) or step by step (:class:`ObserverBank`), with the
  offline dating of alarms by their evidence (:func:`evidence`).
- :mod:`~validation.observers.quantitative`: residual and offset relations
  (not the paper's), the windowed change of two streams compared
  quantitatively; :mod:`~validation.observers.sequential` a CUSUM on the
  residual.
- :mod:`~validation.observers.checks`: unary plausibility checks, one
  component against physics (magnetometer field, GPS fix quality, scan
  geometry, field against gyro).
- :mod:`~validation.observers.config`: the observers' configuration.
- :mod:`~validation.observers.log`: the per-step log of trends, counters
  and observations.
- :mod:`~validation.observers.coverage`: on how many steps each observer
  could say anything.
"""

from validation.observers.checks import GpsQualityCheck, MagnetometerCheck, UnaryCheck, held, unary_checks
from validation.observers.config import (
    DEFAULT_RELATIONS,
    Component,
    GpsCheckConfig,
    MagnetometerCheckConfig,
    ObserversConfig,
    RelationConfig,
    load_observers_config,
    observers_config,
)
from validation.observers.log import ObserverLog, RelationTrace, UnaryTrace
from validation.observers.relations import (
    MismatchCounter,
    ObserverBank,
    StepObservations,
    evidence,
    excise_spans,
    mask_runs,
    observe,
    observe_steps,
    run_observers,
)

__all__ = [
    "MismatchCounter", "ObserverBank", "StepObservations", "evidence", "excise_spans", "mask_runs", "observe",
    "observe_steps", "run_observers",
    "Component", "DEFAULT_RELATIONS", "GpsCheckConfig", "MagnetometerCheckConfig", "ObserversConfig",
    "RelationConfig", "load_observers_config", "observers_config",
    "ObserverLog", "RelationTrace", "UnaryTrace",
    "GpsQualityCheck", "MagnetometerCheck", "UnaryCheck", "held", "unary_checks",
]
