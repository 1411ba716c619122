"""A loop constraint: a relative pose between two non-consecutive keyframes
(defined with the loop observer, :mod:`validation.loop_model`)."""

from validation.loop_model import LoopConstraint

__all__ = ["LoopConstraint"]
