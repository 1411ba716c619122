"""Sensor validation after the Telemax paper: qualitative trends, observers,
consistency-based diagnosis (Reiter) and per-step gating of factors.

The paper (Sections 3 and 4, Table 1) and the code that implements it:

====================================  ============================================================
Paper                                 Code
====================================  ============================================================
Algorithm 2, deriveStream             :func:`validation.trends.derive_stream`
Algorithm 1, abstractStream           :func:`validation.trends.abstract_stream` (``rule: paper``;
                                      online :class:`validation.trends.TrendEstimator`)
Algorithm 3, observe                  :func:`validation.observers.relations.observe` (batch:
                                      :func:`~validation.observers.relations.observe_steps`;
                                      online: :class:`~validation.observers.relations.ObserverBank`)
Table 1, the sensors' modalities      the components of :class:`validation.diagnosis.model.SystemModel`
                                      and the streams of :func:`validation.streams.validation_streams`
Section 4, the model SD               :class:`validation.diagnosis.model.SystemModel`
  relation, ok, match / no_match      :class:`validation.diagnosis.model.Observation`
  fault propagation, CORR masking     ``fault_propagation``, ``failure_masking`` of the model
Section 4, Reiter's diagnoses         :class:`validation.diagnosis.reiter.Diagnoser`
Section 2, suppress unreliable data   :mod:`validation.gating` (the gating decision per component)
Section 6, "how models of sensor      :func:`validation.proposal.propose_model`: the components,
relations can be obtained"            relations and checks a set of streams gives, from physics
====================================  ============================================================

Beyond the listings (each says how and why it departs, and the listing's
version stays available): offline dating of alarms by their evidence
(:func:`validation.observers.relations.evidence`), quantitative relations
(:mod:`validation.observers.quantitative`, :mod:`validation.observers.sequential`),
unary plausibility checks (:mod:`validation.observers.checks`) and the loop
observer (:mod:`validation.loops`).

Layout:

- :mod:`validation.trends`: qualitative trends (Algorithms 1 and 2).
- :mod:`validation.streams`: the named streams the observers compare,
  derived from a run's sensors.
- :mod:`validation.observers`: relation observers (Algorithm 3) and unary checks.
- :mod:`validation.diagnosis`: the system model and the diagnosis.
- :mod:`validation.gating`: from diagnoses to the gating decision of every
  factor's degrees of freedom.
- :mod:`validation.loops`: the loop observer, LOOP in the diagnosis.
- :mod:`validation.validator`: one run, step by step: streams, observers,
  diagnosis, gating, weights (:func:`~validation.validator.run_validation`).
- :mod:`validation.metrics`: how well validation did against true faults.
- :mod:`validation.proposal`: the system model a recording's streams suggest.
- :mod:`validation.config`: the ``validation`` and ``gating`` config sections.
"""

from validation.base.errors import ValidationError

__all__ = ["ValidationError"]
