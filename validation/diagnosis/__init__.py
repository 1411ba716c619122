"""Consistency-based diagnosis (the paper's Section 4, after Reiter 1987).

- :mod:`~validation.diagnosis.model`: the logical system model SD: its
  components (Table 1's modalities), relations, unary checks, fault
  propagation and failure masking (CORR), read from YAML.
- :mod:`~validation.diagnosis.reiter`: every subset-minimal diagnosis of
  one step's observations, by an implicit hitting-set loop over a SAT solver
  (:class:`Diagnoser`).
"""

from validation.diagnosis.model import MaskingRule, Observation, Plausibility, SystemModel, load_model
from validation.diagnosis.reiter import Diagnoser, DiagnosisResult, Explanation, corr_name

__all__ = [
    "Diagnoser", "DiagnosisResult", "Explanation", "MaskingRule", "Observation", "Plausibility", "SystemModel",
    "corr_name", "load_model",
]
