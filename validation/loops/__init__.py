"""The loop observer: loop closures checked against the dead-reckoning chain
and against each other, and LOOP as a component of the diagnosis.

- :mod:`~validation.loops.constraint`: a loop constraint between two
  keyframes, and the observer's configuration.
- :mod:`~validation.loops.chain`: the dead-reckoning chain between
  keyframes and its uncertainty.
- :mod:`~validation.loops.observer`: the chain check and pairwise
  consistency (:func:`observe_loops`).
- :mod:`~validation.loops.cliques`: the maximum clique of the pairwise
  consistency graph.
- :mod:`~validation.loops.gating`: LOOP in the diagnosis and the gate, and
  the oracle for loops.

Loop detection and registration are the pipeline's (:mod:`slam.loops`).
"""

from validation.loops.constraint import LoopConstraint, ObserverConfig
from validation.loops.gating import check_model, gate_loops, loop_is_true, oracle_loops
from validation.loops.observer import LoopObservation, LoopVerdict, count_reasons, observe_loops, position_only

__all__ = [
    "LoopConstraint", "LoopObservation", "LoopVerdict", "ObserverConfig", "check_model", "count_reasons",
    "gate_loops", "loop_is_true", "observe_loops", "oracle_loops", "position_only",
]
